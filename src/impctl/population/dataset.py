"""The virtual-population dataset: households, their IMP nights' features, and a manifest.

Files in a dataset directory:

* ``households.parquet`` — one row per household (:func:`~.households.sample_population`);
* ``nights.parquet`` — one row per night (:class:`~.imp_run.ideal.ImpResult` ``nights``);
* ``manifest.json`` — seed, sizes, population and IMP settings, ranges, feature names and units,
  weather source, package versions, creation time.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import multiprocessing
import os
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd

from ..imp import NIGHT_FEATURES
from .households import PopulationConfig, households_from_table, sample_population
from .imp_run.ideal import simulate_imp
from .imp_run.setup import ImpSimConfig, default_weather
from .ranges import DEFAULT_RANGES, Ranges, validate_ranges

#: Households simulated per vectorised block: bounds memory (~30 MB of samples per block) and
#: paces the progress bar. Fixed, so a seed gives the same dataset whatever the machine.
CHUNK_HOUSEHOLDS = 100
#: Most worker processes that simulate blocks side by side: each holds one block's arrays
#: (about 150 MB on the realistic plant), so a small gateway's memory bounds it, not its cores.
MAX_WORKERS = 4
DATASET_FORMAT = 1
#: The plants a population can live on (see :func:`generate_dataset`).
PLANTS = ("iso", "realistic")


def package_versions() -> dict[str, str]:
    """Versions of impctl and the numeric packages (for manifests and model metadata)."""
    out = {}
    for name in ("impctl", "numpy", "pandas", "pyarrow", "scikit-learn", "joblib"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "unknown"
    return out


@dataclass
class Dataset:
    """A generated population: ``households`` and ``nights`` tables and their ``manifest``."""

    households: pd.DataFrame
    nights: pd.DataFrame
    manifest: dict

    def save(self, directory: str | Path) -> Path:
        """Write the three files into ``directory`` (created if needed)."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        self.households.to_parquet(directory / "households.parquet", index=False)
        self.nights.to_parquet(directory / "nights.parquet", index=False)
        (directory / "manifest.json").write_text(json.dumps(self.manifest, indent=2) + "\n")
        return directory

    @classmethod
    def load(cls, directory: str | Path) -> Dataset:
        """Read a dataset written by :meth:`save`."""
        directory = Path(directory)
        return cls(
            pd.read_parquet(directory / "households.parquet"),
            pd.read_parquet(directory / "nights.parquet"),
            json.loads((directory / "manifest.json").read_text()),
        )


def _weather_source(weather_path: str | Path | None, seed: int) -> dict:
    if weather_path is None:
        return {"kind": "builtin winter generator", "seed": seed}
    path = Path(weather_path)
    return {"kind": "file", "path": str(path),
            "sha256": hashlib.sha256(path.read_bytes()).hexdigest()}


def generate_dataset(
    n_households: int = 900,
    seed: int = 0,
    *,
    weather: pd.Series | None = None,
    weather_path: str | Path | None = None,
    ranges: Ranges = DEFAULT_RANGES,
    population: PopulationConfig | None = None,
    imp: ImpSimConfig | None = None,
    progress: Callable[[int], None] | None = None,
    plant: str = "iso",
    workers: int | None = None,
) -> Dataset:
    """Draw ``n_households`` and run the IMP on all of them (vectorised in blocks).

    Parameters
    ----------
    n_households : int
    seed : int
        Seeds the households, their weather days, the noise and the built-in weather.
    weather : Series, optional
        Outdoor temperature [°C], tz-aware index; default the built-in winter for ``seed``.
    weather_path : path, optional
        Where ``weather`` came from (recorded in the manifest with its SHA-256).
    ranges : mapping
        Classifier ranges; the population spans their hull.
    population : PopulationConfig, optional
        Default :meth:`PopulationConfig.for_ranges` of ``ranges``.
    imp : ImpSimConfig, optional
        Default :meth:`ImpSimConfig.for_plant` of ``plant`` (the nights the gateway records).
    progress : callable, optional
        Called with the number of households finished after each block.
    plant : {"iso", "realistic"}
        ``iso``: the ideal 5R1C (:func:`~.imp_run.ideal.simulate_imp`); ``realistic``: every
        household on the realistic plant with its realism options drawn over their documented
        ranges (:func:`impctl.population.realism.sample_params`, same seed → same options;
        :func:`~.imp_run.realistic.simulate_imp_plant`); the options are extra
        ``<section>.<field>`` columns (``emitter.kind`` …) of the households table.
    workers : int, optional
        Processes simulating blocks of :data:`CHUNK_HOUSEHOLDS` side by side; default one per
        available core, at most :data:`MAX_WORKERS`. Each block has its own random stream, so
        the dataset is the same for any number of workers.

    Returns
    -------
    Dataset
    """
    ranges = validate_ranges(ranges)
    pop_cfg = population or PopulationConfig.for_ranges(ranges)
    if plant not in PLANTS:
        raise ValueError(f"plant must be one of {PLANTS}, got {plant!r}")
    imp_cfg = imp or ImpSimConfig.for_plant(plant)
    if weather is None:
        weather = default_weather(seed, imp_cfg.tz)
    households = sample_population(n_households, seed, pop_cfg)
    realism = None
    if plant == "realistic":
        from .realism import params_table, sample_params, take_params

        realism = sample_params(n_households, seed)
    streams = np.random.SeedSequence([int(seed), 0x1_4D9]).spawn(
        -(-n_households // CHUNK_HOUSEHOLDS))
    blocks = []
    for block, stream in enumerate(streams):
        lo = block * CHUNK_HOUSEHOLDS
        hi = min(lo + CHUNK_HOUSEHOLDS, n_households)
        params = None
        if realism is not None:
            params = take_params(realism, np.arange(lo, hi), n_households)
        blocks.append((lo, households.iloc[lo:hi], params, weather, imp_cfg, stream))
    parts = []
    for (lo, chunk, *_), nights_of_block in zip(blocks, _run_blocks(blocks, workers),
                                                strict=True):
        nights_of_block["household"] += lo
        parts.append(nights_of_block)
        if progress is not None:
            progress(len(chunk))
    nights = pd.concat(parts, ignore_index=True)
    households.insert(0, "household", np.arange(n_households))
    if realism is not None:
        households = pd.concat([households, params_table(realism, n_households)], axis=1)
    manifest = {
        "format": DATASET_FORMAT,
        "seed": int(seed),
        "plant": plant,
        "n_households": int(n_households),
        "n_nights": int(len(nights)),
        "population": pop_cfg.as_dict(),
        "imp": imp_cfg.as_dict(),
        "ranges": {k: [list(r) for r in v] for k, v in ranges.items()},
        "night_features": {name: {"unit": unit, "meaning": meaning}
                           for name, unit, meaning in NIGHT_FEATURES},
        "weather": _weather_source(weather_path, seed),
        "versions": package_versions(),
        "created": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
    }
    return Dataset(households, nights, manifest)


def _simulate_block(block: tuple) -> pd.DataFrame:
    """The nights of one block of households (``household`` numbered from 0 in the block)."""
    _, chunk, params, weather, imp_cfg, stream = block
    houses = households_from_table(chunk)
    if params is None:
        return simulate_imp(houses, weather, imp_cfg, stream, keep_samples=False).nights
    from .imp_run.realistic import simulate_imp_plant

    return simulate_imp_plant(houses, params, weather, imp_cfg, stream,
                              keep_samples=False).nights


def _run_blocks(blocks: list[tuple], workers: int | None) -> Iterator[pd.DataFrame]:
    """Each block's nights, in block order; in worker processes when more than one is
    available and the platform forks (a forked worker starts in milliseconds, with the
    modules already imported)."""
    if workers is None:
        workers = min(len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                      else os.cpu_count() or 1, MAX_WORKERS)
    workers = max(1, min(workers, len(blocks)))
    if workers == 1 or "fork" not in multiprocessing.get_all_start_methods():
        yield from map(_simulate_block, blocks)
        return
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork")) as pool:
        yield from pool.map(_simulate_block, blocks)
