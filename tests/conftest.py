"""Fixtures shared across test modules and, where they only read, across the pytest-xdist
worker processes of one run."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import pickle
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from cli_fixtures import run_impctl

#: The modules that take most of a run's CPU (each ≥ 20 CPU-s on the 2-core reference
#: machine; docs/explanation/benchmarks.md), costliest first. They run first: with the
#: README's ``-n 4 --dist loadfile --no-loadscope-reorder`` each xdist worker takes the next
#: whole module, so the long ones start at once and the many short ones fill the end of the
#: run instead of one long module running alone at its end. Not test_season_refit: its
#: daemon runs on the wall clock and waits for a niced refit, which beside these modules got
#: a sliver of a core while the simulator ran on (232 s and 53 CPU-s instead of 38 s and 14).
FIRST = ("test_demo", "test_fleet_guards", "test_season", "test_record_daemon",
         "test_daemon_campaign", "test_fleet", "test_reliability_crash",
         "test_fit", "test_season_figure", "test_daemon_campaign_adaptive",
         "test_season_change", "test_fleet_cluster", "test_fit_noise", "test_mqtt_daemon",
         "test_reliability_comfort", "test_mqtt_commands_careless", "test_demo_determinism",
         "test_curve_daemon", "test_reliability_comfort_plant")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The modules of :data:`FIRST` first, in that order; the rest as collected (a stable
    sort: each module's tests keep their order)."""
    rank = {name: i for i, name in enumerate(FIRST)}
    items.sort(key=lambda item: rank.get(item.path.stem, len(FIRST)))


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
def winter_season(tmp_path_factory):
    """A short winter of two realistic households (``simulate_season``: 20 nights from 20
    November 2026, the IMP campaign every other night from the first, the owner's nights
    between, hot water, defrosts), simulated once per test run (about 9 CPU-s, the same for
    one household as for two) and read by the season model's tests. Read-only: each worker
    unpickles its own copy."""
    with _once_per_run(tmp_path_factory, "winter-season") as root:
        path = root / "winter-season.pickle"
        if not path.exists():
            from impctl.population.households import sample_households
            from impctl.population.imp_run.season import SeasonConfig, simulate_season
            from impctl.population.realism import sample_params

            houses = sample_households(WINTER_HOUSEHOLDS, seed=WINTER_SEED)
            params = sample_params(WINTER_HOUSEHOLDS, WINTER_SEED)
            season = simulate_season(houses, params, SeasonConfig(nights=WINTER_NIGHTS),
                                     seed=WINTER_SEED)
            part = path.with_suffix(".part")  # a worker killed mid-write leaves no pickle
            part.write_bytes(pickle.dumps(season))
            part.rename(path)
        return pickle.loads(path.read_bytes())
