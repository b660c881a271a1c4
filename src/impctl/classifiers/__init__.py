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

import importlib
from typing import Any

from ..population.ranges import DEFAULT_RANGES

_LAZY = {
    "ClassResult": "saved",
    "classify_nights": "saved",
    "default_model_dir": "saved",
    "load_models": "saved",
    "save_models": "saved",
    "TrainConfig": "training",
    "train_classifiers": "training",
    "format_report": "report",
    "RangeClassifier": "estimator",
    "campaign_features": "campaign",
}

__all__ = ["DEFAULT_RANGES", *_LAZY]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
