"""The virtual population: households, their simulated IMP nights, and the training dataset.

Pipeline position: model → plant → imp → **population** → classifiers → fit. Nothing here imports
torch or scikit-learn; the names below are resolved lazily, so ``import impctl.population`` loads
only numpy (pandas comes with the first household, night or dataset asked for).

* :func:`sample_households`, :func:`sample_population`, :class:`PopulationConfig`
  (:mod:`.households`)
* :func:`simulate_imp`, :class:`ImpSimConfig`, :class:`ImpResult` (:mod:`.virtual_imp`)
* :func:`simulate_imp_plant` (:mod:`.virtual_imp_plant`): the same nights on the realistic plant
  (:mod:`impctl.plant`); :func:`sample_params` (:mod:`.realism`): every household's realism
  options drawn over their documented ranges
* :func:`generate_dataset`, :class:`Dataset` (:mod:`.dataset`)
* :func:`synth_nights` (:mod:`.synth_nights`): fine-step simulated nights for the fit's tests
  and benches
* :data:`DEFAULT_RANGES` (:mod:`.ranges`): the parameter ranges (the paper's Table III) the
  population is drawn over and the classifiers put a house into
"""

from __future__ import annotations

import importlib
from typing import Any

from .ranges import DEFAULT_RANGES

_LAZY = {
    "PopulationConfig": "households",
    "sample_households": "households",
    "sample_population": "households",
    "ImpResult": "virtual_imp",
    "ImpSimConfig": "virtual_imp",
    "simulate_imp": "virtual_imp",
    "simulate_imp_plant": "virtual_imp_plant",
    "sample_params": "realism",
    "Dataset": "dataset",
    "generate_dataset": "dataset",
    "synth_nights": "synth_nights",
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
