"""Fleet fitting for aggregators: many households' nights fitted together on Dask.

Pipeline position: fit → **fleet**. Nothing is imported until used (Dask, torch and pandas load
lazily), so ``import impctl.fleet`` stays light.

* :func:`fit_fleet` (:mod:`.run`): INPUT → FLEET.parquet on a Dask cluster, batch by batch
* :func:`discover` (:mod:`.inputs`): the households of INPUT
* :func:`fit_batch` (:mod:`.worker`): one batch of households on a worker
* :func:`read_fleet`, :data:`COLUMNS` (:mod:`.table`): FLEET.parquet
* :func:`read_manifest`, :func:`completeness` (:mod:`.manifest`): expected and done households
* :func:`fleet_flexibility` (:mod:`.flex_rows`): ``impctl flex`` on FLEET rows
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "fit_fleet": "run",
    "discover": "inputs",
    "fit_batch": "worker",
    "read_fleet": "table",
    "COLUMNS": "table",
    "read_manifest": "manifest",
    "completeness": "manifest",
    "fleet_flexibility": "flex_rows",
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
