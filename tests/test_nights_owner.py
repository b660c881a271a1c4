"""NIGHTS files with owner nights (the house recorded between IMP nights) and the columns they
bring: read into nights of kind owner with the heating water, the curve, the hot water and the
label per row; a bad value refused in one line (exit 2); the fit leaves owner nights out and
says so, fitting what it fits without them."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from cli_fixtures import run_impctl

from impctl.fit.household import choose_nights
from impctl.imp.files.nights_csv import read_nights
from impctl.imp.night import OWNER_NOTE
from impctl.model import HouseParameters
from impctl.population.imp_run.synth import synth_nights

HOUSE = HouseParameters(floor_area=120.0, wall_height=2.7, walls_area=160.0, windows_area=25.0,
                        c_f=2.2, u_walls=0.5, u_windows=1.3, ach_vent=0.0, ach_infl=0.01)
TZ = "Europe/Ljubljana"


def run_cli(*args: str, model_dir: Path) -> subprocess.CompletedProcess:
    # in this process: the tests check the output, not the process
    return run_impctl(*args, env={"IMPCTL_MODEL_DIR": str(model_dir)})


@pytest.fixture(scope="module")
def imp_nights():
    return synth_nights(HOUSE, seed=11, sample_step_s=900.0, n_normal=3)


def _imp_frame(nights) -> pd.DataFrame:
    frames = []
    for n in nights:
        stamps = n.start + pd.to_timedelta(n.time_s, unit="s")
        frames.append(pd.DataFrame({
            "timestamp": [t.isoformat() for t in stamps], "t_air": n.t_air_c, "t_out": n.t_out_c,
            "q_hc": np.round(n.q_hc_w, 1), "setpoint": n.setpoint_c, "night": n.night_id,
            "kind": n.kind, "t_flow_c": "", "t_return_c": "", "t_flow_target_c": "",
            "dhw": "", "label": ""}))
    return pd.concat(frames)


def _owner_frame(day: str, label: str = "", rows: int = 288, **cells) -> pd.DataFrame:
    stamps = pd.date_range(pd.Timestamp(f"{day} 12:00", tz=TZ), periods=rows, freq="5min")
    i = np.arange(rows)
    frame = pd.DataFrame({
        "timestamp": [t.isoformat() for t in stamps], "t_air": 21.0 + 0.2 * np.sin(i / 40),
        "t_out": -1.0 + np.cos(i / 60), "q_hc": 2500.0 + 400 * np.sin(i / 7),
        "setpoint": 21.0, "night": f"owner-{day}", "kind": "owner",
        "t_flow_c": 36.0, "t_return_c": 31.0, "t_flow_target_c": 37.5,
        "dhw": np.where(i % 48 < 4, 0.6, 0.0), "label": label})
    for col, value in cells.items():
        frame[col] = value
    return frame


def _file(path: Path, *frames: pd.DataFrame) -> Path:
    pd.concat(frames).sort_values("timestamp", kind="stable").to_csv(path, index=False)
    return path


def test_owner_nights_are_read_with_their_rows_columns_and_labels(tmp_path, imp_nights):
    path = _file(tmp_path / "n.csv", _owner_frame("2026-01-05"),
                 _owner_frame("2026-01-06", "data missing: 40 % of the night's rows"),
                 _imp_frame(imp_nights))
    nights = read_nights(path, TZ)
    owner = [n for n in nights if n.kind == "owner"]
    assert [n.night_id for n in owner] == ["owner-2026-01-05", "owner-2026-01-06"]
    first = owner[0]
    assert first.duration_h == pytest.approx(24 - 5 / 60) and first.setpoint_c == 21.0
    assert (first.t_flow_c == 36.0).all() and (first.t_return_c == 31.0).all()
    assert (first.t_flow_target_c == 37.5).all() and first.dhw.max() == 0.6
    assert first.label == "" and owner[1].label.startswith("data missing: 40 %")
    # the IMP nights of the same file: no value in these columns, no label
    imp = [n for n in nights if n.kind != "owner"]
    assert len(imp) == len(imp_nights) and all(np.isnan(n.t_flow_c).all() and n.label == ""
                                               for n in imp)
    # a file without the columns: None, not made up
    plain = read_nights(_file(tmp_path / "p.csv", _imp_frame(imp_nights).drop(
        columns=["t_flow_c", "t_return_c", "t_flow_target_c", "dhw", "label"])), TZ)
    assert all(n.t_flow_c is None and n.dhw is None for n in plain)


@pytest.mark.parametrize("cells, words", [
    ({"t_flow_c": 160.0}, "column 't_flow_c': 160 is outside 0…100 °C"),
    ({"t_flow_target_c": "warm"}, "column 't_flow_target_c': 'warm' is not a finite number"),
    ({"dhw": 1.5}, "column 'dhw': 1.5 is outside 0…1"),
    ({"t_return_c": -5.0}, "column 't_return_c': -5 is outside 0…100 °C"),
    ({"kind": "owners"}, "column 'kind': 'owners' is not 'constrained', 'normal' or 'owner'"),
], ids=["flow-hot", "target-text", "dhw-share", "return-frozen", "kind"])
def test_a_bad_value_is_one_line_exit_2_naming_file_and_row(tmp_path, cells, words):
    path = _file(tmp_path / "bad.csv", _owner_frame("2026-01-05", rows=20, **cells))
    res = run_cli("fit", "--nights", str(path), model_dir=tmp_path / "none")
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and "row 2" in lines[0], lines
    assert words in lines[0], lines


def test_a_label_is_an_owner_nights_and_the_same_on_all_its_rows(tmp_path, imp_nights):
    frame = _owner_frame("2026-01-05", "heating off: loop 1 off", rows=20)
    frame.iloc[7, frame.columns.get_loc("label")] = ""
    res = run_cli("fit", "--nights", str(_file(tmp_path / "a.csv", frame)),
                  model_dir=tmp_path / "none")
    assert res.returncode == 2 and "row 9" in res.stderr
    assert "night 'owner-2026-01-05' changes label from 'heating off: loop 1 off'" in res.stderr
    imp = _imp_frame(imp_nights[:1])
    imp["label"] = "why"
    res = run_cli("fit", "--nights", str(_file(tmp_path / "b.csv", imp)),
                  model_dir=tmp_path / "none")
    assert res.returncode == 2 and "only owner nights carry a label" in res.stderr, res.stderr


def test_the_fit_leaves_owner_nights_out_and_says_so(tmp_path, imp_nights):
    owner = [_owner_frame(f"2026-01-0{d}") for d in (3, 4)]
    both = read_nights(_file(tmp_path / "both.csv", *owner, _imp_frame(imp_nights)), TZ)
    alone = read_nights(_file(tmp_path / "imp.csv", _imp_frame(imp_nights)), TZ)
    with_owner, without = choose_nights(both), choose_nights(alone)
    assert [n.night_id for n in with_owner.chosen] == [n.night_id for n in without.chosen]
    assert with_owner.note == f"{OWNER_NOTE} (2)" and without.note is None
    assert all(n.kind != "owner" for n in with_owner.nights + with_owner.all_nights)
    # impctl fit on the file: the same fit, the note printed
    res = run_cli("fit", "--nights", str(tmp_path / "both.csv"), "--json",
                  str(tmp_path / "fit.json"), model_dir=tmp_path / "none")
    assert res.returncode == 0, res.stderr
    assert f"{OWNER_NOTE} (2)" in res.stdout
    fitted = json.loads((tmp_path / "fit.json").read_text())
    assert fitted["lumped"]["hlc"]["value"] > 0
    assert sorted(n["night_id"] for n in fitted["per_night"]) == sorted(
        n.night_id for n in imp_nights)
