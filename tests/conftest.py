"""Fixtures shared across test modules and, where they only read, across the pytest-xdist
worker processes of one run."""

from __future__ import annotations

import fcntl
import json
import os
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest
from cli_fixtures import run_impctl


@dataclass(frozen=True)
class Trained:
    """``impctl train --households 20 --seed 4``: its output folder and the finished run."""

    out: Path
    run: subprocess.CompletedProcess


@pytest.fixture(scope="session")
def trained_models(tmp_path_factory) -> Trained:
    """The classifiers that ``impctl train --households 20 --seed 4`` writes, trained once per
    test run and read by every module that classifies or fits with them. Read-only: a test
    that changes the files works on a copy."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the run's folder, above each worker's own: one training per run
    out, record = root / "trained-models", root / "trained-models.run.json"
    with open(root / "trained-models.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # the other workers wait for the first one's training
        if not record.exists():
            done = run_impctl("train", "--households", "20", "--seed", "4", "--out", str(out))
            assert done.returncode == 0, done.stderr
            record.write_text(json.dumps({"args": done.args, "stdout": done.stdout,
                                          "stderr": done.stderr}))
        run = json.loads(record.read_text())
    return Trained(out, subprocess.CompletedProcess(run["args"], 0, run["stdout"], run["stderr"]))
