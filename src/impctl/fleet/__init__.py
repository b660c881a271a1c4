"""Fleet fitting for aggregators: many households' nights fitted together on Dask.

Pipeline position: fit → **fleet**. Nothing is imported until used (Dask, torch and pandas load
lazily), so ``import impctl.fleet`` stays light.

* :func:`fit_fleet` (:mod:`.run`): INPUT → FLEET.parquet on a Dask cluster, batch by batch
* :func:`discover` (:mod:`.inputs`): the households of INPUT
* :func:`fit_batch` (:mod:`.worker`): one batch of households on a worker
* :func:`read_fleet`, :data:`COLUMNS` (:mod:`.results.table`): FLEET.parquet
* :func:`read_manifest`, :func:`completeness` (:mod:`.results.manifest`): expected and done
  households
* :func:`fleet_flexibility` (:mod:`.results.flex_rows`): ``impctl flex`` on FLEET rows
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "fit_fleet": "run",
    "discover": "inputs",
    "fit_batch": "worker",
    "read_fleet": "results.table",
    "COLUMNS": "results.table",
    "read_manifest": "results.manifest",
    "completeness": "results.manifest",
    "fleet_flexibility": "results.flex_rows",
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
