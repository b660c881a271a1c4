"""Fixtures shared across test modules (with pytest-xdist: once per worker process)."""

from __future__ import annotations

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
    """The classifiers that ``impctl train --households 20 --seed 4`` writes, trained once and
    read by every module that classifies or fits with them. Read-only: a test that changes
    the files works on a copy."""
    out = tmp_path_factory.mktemp("trained-models")
    done = run_impctl("train", "--households", "20", "--seed", "4", "--out", str(out))
    assert done.returncode == 0, done.stderr
    return Trained(out, done)
