"""Shared pieces of the issue-12 tests: simulated nights as NIGHTS.csv, and refusal helpers."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from test_reliability_input import cli, refused

from impctl.imp import write_nights
from impctl.model import HouseParameters
from impctl.population.imp_run.synth import synth_nights

HOUSE = HouseParameters(floor_area=150.0, wall_height=2.6, walls_area=200.0, windows_area=30.0,
                        c_f=1.65, u_walls=0.6, u_windows=1.4, ach_vent=0.0, ach_infl=0.01)
_BASE: dict[float, list] = {}


def base_nights(step_s: float) -> list:
    """1 constrained + 1 normal night, simulated once per sampling step."""
    if step_s not in _BASE:
        _BASE[step_s] = synth_nights(HOUSE, seed=4, sample_step_s=step_s, n_normal=1,
                                     n_constrained=1)
    return _BASE[step_s]


@pytest.fixture(scope="module")
def nights():
    # 2 constrained + 3 normal nights, 15-minute samples (fits in a few seconds)
    return synth_nights(HOUSE, seed=4, sample_step_s=900.0, n_normal=3)


@pytest.fixture(scope="module")
def nights_csv(nights, tmp_path_factory):
    return write_nights(nights, tmp_path_factory.mktemp("good") / "nights.csv")


def fit_refused(work: Path, nights: Path) -> list[str]:
    """``impctl fit`` refuses NIGHTS with one line and writes neither --json nor --plot."""
    lines = refused(cli("fit", "--nights", str(nights), "--json", str(work / "fit.json"),
                        "--plot", str(work / "fit.png")), nights)
    assert not (work / "fit.json").exists() and not (work / "fit.png").exists()
    return lines


def scaled(src: Path, dst: Path, factor: float, *, labels: bool = True) -> Path:
    """NIGHTS.csv with q_hc × ``factor`` (and without night/kind/heating if not ``labels``)."""
    frame = pd.read_csv(src)
    frame["q_hc"] = frame["q_hc"] * factor
    if not labels:
        frame = frame.drop(columns=["night", "kind", "heating"])
    frame.to_csv(dst, index=False)
    return dst
