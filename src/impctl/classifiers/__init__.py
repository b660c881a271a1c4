"""Range classifiers: random forests that put a house into parameter ranges from its IMP nights.

Pipeline position: population → **classifiers** → fit. Nothing here imports torch; scikit-learn
is loaded only when a classifier is trained, loaded or used: the names below are resolved lazily,
so ``import impctl.classifiers`` stays light (the CLI imports it).

* :func:`classify_nights`, :class:`ClassResult`, :func:`default_model_dir`, :func:`load_models`,
  :func:`save_models` (:mod:`.saved`)
* :func:`train_classifiers`, :class:`TrainConfig` (:mod:`.training`), :func:`format_report`
  (:mod:`.report`)
* :class:`RangeClassifier` (:mod:`.estimator`)
* :func:`campaign_features` (:mod:`.campaign`): a household's nights combined into one row
* :data:`DEFAULT_RANGES`: the ranges (:mod:`impctl.population.ranges`)
"""

from __future__ import annotations

import lazy_loader

from ..population.ranges import DEFAULT_RANGES

# Resolved on first use (lazy_loader), so that importing the package stays light.
__getattr__, __dir__, _LAZY_NAMES = lazy_loader.attach(__name__, submod_attrs={
    "result": ["ClassResult"],
    "files.saved": ["classify_nights", "default_model_dir", "load_models", "save_models"],
    "training": ["TrainConfig", "train_classifiers"],
    "report": ["format_report"],
    "estimator": ["RangeClassifier"],
    "campaign": ["campaign_features"],
})
__all__ = ["DEFAULT_RANGES", *_LAZY_NAMES]
