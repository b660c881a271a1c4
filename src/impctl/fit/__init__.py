"""The night fit: the 5R1C parameters from IMP nights, by a Neural ODE bounded by the class ranges.

Pipeline position: classifiers → **fit** → fleet. torch is imported only when a name that needs
it is first used (the names below are resolved lazily), so ``import impctl.fit`` stays light and
reading a result (:mod:`.report`) needs no torch.

* :class:`NightFit` (:mod:`.estimator`): the estimator (torch)
* :func:`prepare_nights` (:mod:`.data`): measured nights → the fit's input
* :func:`fit_to_dict`, :func:`format_table`, :func:`plot_fit` (:mod:`.report`, no torch)

Inside: :mod:`.node` (the ODE), :mod:`.solver` (its torchdiffeq integration), :mod:`.lm` (the
optimiser), :mod:`.uncertainty` (intervals), :mod:`.resample` (fine rows into blocks),
:mod:`.quality` (night quality, model adequacy; no torch), :mod:`.baselines` (the methods the
fit is compared with).
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "NightFit": "estimator",
    "prepare_nights": "data",
    "fit_to_dict": "report",
    "format_table": "report",
    "plot_fit": "report",
}

__all__ = [*_LAZY]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
