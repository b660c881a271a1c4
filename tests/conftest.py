"""Fixtures shared across test modules and, where they only read, across the pytest-xdist
worker processes of one run."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import pickle
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from cli_fixtures import run_impctl

_ROOT = Path(__file__).resolve().parent.parent


def _bytecode_dirs() -> set[Path]:
    """Every ``__pycache__`` of the checkout outside its hidden folders (the virtual
    environment's, compiled when installed, stay)."""
    return {p for top in _ROOT.iterdir() if top.is_dir() and not top.name.startswith(".")
            for p in top.rglob("__pycache__")}


def pytest_configure(config) -> None:
    """Bytecode is written this run (:func:`_write_bytecode_this_run`), and the tests' asserts
    are rewritten once before the xdist workers start (:func:`_rewrite_tests_once`)."""
    if hasattr(config, "workerinput"):
        return
    if sys.dont_write_bytecode:
        _write_bytecode_this_run(config)
    _rewrite_tests_once(config)


def _write_bytecode_this_run(config) -> None:
    """Where the environment says not to write bytecode (``PYTHONDONTWRITEBYTECODE``), the run
    writes it all the same and removes what it wrote when it ends: the suite starts about 300
    Python processes (xdist workers, daemons, simulators, commands), and each compiled
    impctl's sources and rewrote the tests' asserts anew — about 25 CPU-s a run. The tree is
    left as it was found."""
    before = _bytecode_dirs()
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)   # the workers and every process they start
    sys.dont_write_bytecode = False

    def remove_written() -> None:
        sys.dont_write_bytecode = True
        for p in _bytecode_dirs() - before:
            shutil.rmtree(p, ignore_errors=True)

    config.add_cleanup(remove_written)


def _rewrite_one(path: Path) -> None:
    """Rewrite one test module's asserts as pytest does at import and keep the result where
    pytest looks for it (its own functions, whose names are not public: on another pytest
    they may be gone, and then each worker rewrites as usual)."""
    from _pytest.assertion.rewrite import (
        PYC_TAIL,
        _rewrite_test,
        _write_pyc,
        assertstate_key,
        get_cache_dir,
    )

    pyc = get_cache_dir(path) / (path.name[:-3] + PYC_TAIL)
    if pyc.exists():
        return
    pyc.parent.mkdir(exist_ok=True)
    source, code = _rewrite_test(path, _CONFIG)
    _write_pyc(_CONFIG.stash[assertstate_key], code, source, pyc)


_CONFIG = None


def _rewrite_tests_once(config) -> None:
    """The xdist workers start together and each rewrote every test module's asserts before
    any of them had kept it: about 6 CPU-s a worker, the same work four times. The main
    process does it once first, on two processes; the workers then load what it kept."""
    global _CONFIG
    if (config.getoption("numprocesses", None) or 0) < 2:
        return
    import concurrent.futures
    import multiprocessing

    _CONFIG = config
    paths = sorted(Path(__file__).parent.glob("test_*.py")) + [Path(__file__)]
    try:
        with concurrent.futures.ProcessPoolExecutor(
                2, mp_context=multiprocessing.get_context("fork")) as pool:
            list(pool.map(_rewrite_one, paths, chunksize=8))
    except Exception:  # noqa: BLE001 - only a saving: the workers rewrite what is missing
        pass


@dataclass(frozen=True)
class Trained:
    """``impctl train --households 20 --seed 4``: its output folder and the finished run."""

    out: Path
    run: subprocess.CompletedProcess


@contextlib.contextmanager
def _once_per_run(tmp_path_factory, name: str) -> Iterator[Path]:
    """The run's folder (above each xdist worker's own), held under the lock ``name``: the
    first worker to get it builds what is missing there, the others wait and read it."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield root


@pytest.fixture(scope="session")
def trained_models(tmp_path_factory) -> Trained:
    """The classifiers that ``impctl train --households 20 --seed 4`` writes, trained once per
    test run and read by every module that classifies or fits with them. Read-only: a test
    that changes the files works on a copy."""
    with _once_per_run(tmp_path_factory, "trained-models") as root:
        out, record = root / "trained-models", root / "trained-models.run.json"
        if not record.exists():
            done = run_impctl("train", "--households", "20", "--seed", "4", "--out", str(out))
            assert done.returncode == 0, done.stderr
            record.write_text(json.dumps({"args": done.args, "stdout": done.stdout,
                                          "stderr": done.stderr}))
        run = json.loads(record.read_text())
    return Trained(out, subprocess.CompletedProcess(run["args"], 0, run["stdout"], run["stderr"]))


#: The shared winter: households, seed and nights of :func:`winter_season`.
WINTER_HOUSEHOLDS, WINTER_SEED, WINTER_NIGHTS = 2, 31, 20


@pytest.fixture(scope="session")
def build_once(tmp_path_factory) -> Callable[[str, Callable[[], object]], object]:
    """``build_once(name, build)``: ``build()``'s result, built by the first worker of the run
    that asks and pickled in the run's folder; every worker unpickles its own copy (read-only
    data: a test that changes it works on a copy)."""
    def built(name: str, build: Callable[[], object]) -> object:
        with _once_per_run(tmp_path_factory, name) as root:
            path = root / f"{name}.pickle"
            if not path.exists():
                part = path.with_suffix(".part")  # a worker killed mid-write leaves no pickle
                part.write_bytes(pickle.dumps(build()))
                part.rename(path)
            return pickle.loads(path.read_bytes())

    return built


@pytest.fixture(scope="session")
def winter_season(build_once):
    """A short winter of two realistic households (``simulate_season``: 20 nights from 20
    November 2026, the IMP campaign every other night from the first, the owner's nights
    between, hot water, defrosts), simulated once per test run (about 9 CPU-s, the same for
    one household as for two) and read by the season model's tests."""
    def build():
        from impctl.population.households import sample_households
        from impctl.population.realism import sample_params
        from impctl.population.season_run.season import SeasonConfig, simulate_season

        houses = sample_households(WINTER_HOUSEHOLDS, seed=WINTER_SEED)
        params = sample_params(WINTER_HOUSEHOLDS, WINTER_SEED)
        return simulate_season(houses, params, SeasonConfig(nights=WINTER_NIGHTS),
                               seed=WINTER_SEED)

    return build_once("winter-season", build)


@pytest.fixture(scope="session")
def two_fleet_households(build_once):
    """The fleet tests' two households' nights (``fleet_fixtures``), simulated once per run."""
    from fleet_fixtures import two_households_nights

    return build_once("two-fleet-households", two_households_nights)
