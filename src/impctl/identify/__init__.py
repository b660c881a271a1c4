"""Identification: virtual population, parameter-range classifiers, Neural-ODE fit.

Nothing here imports torch at package import time; the fit lives in ``impctl.identify.fit``.
scikit-learn is loaded only when a classifier is trained, loaded or used: the names below are
resolved lazily, so ``import impctl.identify`` stays light (the daemon imports it).

* :func:`classify_nights`, :class:`ClassResult`, :func:`default_model_dir`, :func:`load_models`
  (:mod:`.classifiers`)
* :data:`DEFAULT_RANGES` (:mod:`.ranges`)
* :func:`sample_households`, :func:`sample_population`, :class:`PopulationConfig`
  (:mod:`.population`)
* :func:`simulate_imp`, :class:`ImpSimConfig`, :class:`ImpResult` (:mod:`.virtual_imp`)
* :func:`generate_dataset`, :class:`Dataset` (:mod:`.dataset`)
* :func:`train_classifiers`, :class:`TrainConfig` (:mod:`.training`), :class:`RangeClassifier`
  (:mod:`.estimator`)
"""

from __future__ import annotations

import importlib
from typing import Any

from .ranges import DEFAULT_RANGES

_LAZY = {
    "ClassResult": "classifiers",
    "classify_nights": "classifiers",
    "default_model_dir": "classifiers",
    "load_models": "classifiers",
    "save_models": "classifiers",
    "PopulationConfig": "population",
    "sample_households": "population",
    "sample_population": "population",
    "ImpResult": "virtual_imp",
    "ImpSimConfig": "virtual_imp",
    "simulate_imp": "virtual_imp",
    "Dataset": "dataset",
    "generate_dataset": "dataset",
    "TrainConfig": "training",
    "train_classifiers": "training",
    "RangeClassifier": "estimator",
    "campaign_features": "campaign",
    "NightFit": "fit",
}

__all__ = ["DEFAULT_RANGES", *_LAZY]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'impctl.identify' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
