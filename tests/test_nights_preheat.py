"""NIGHTS files with an IMP night's pre-heat (``phase`` = ``preheat`` on its first rows): read as
a piece of its own — the night's id and kind — that the season model puts on its grid and the
IMP fit, the classifiers and the campaign leave out (their night starts at the window, as
before); a ``phase`` that cannot be right refuses the file in one line (exit 2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_nights_owner import HOUSE, TZ, _file, _imp_frame, _owner_frame, run_cli

from impctl.fit.household import choose_nights
from impctl.imp.files.nights_csv import read_nights, write_nights
from impctl.imp.night import split_owner
from impctl.population.imp_run.synth import synth_nights
from impctl.season import record_from_nights

PREHEAT_ROWS = 24  # 2 h of 5-min rows


@pytest.fixture(scope="module")
def imp_nights():
    return synth_nights(HOUSE, seed=11, sample_step_s=900.0, n_normal=3)


def _with_preheat(nights, which: int = 0) -> pd.DataFrame:
    """The nights' rows, night ``which`` after a pre-heat of 2 h: the room raised from 21 to
    23.5 °C with the heating on, setpoint T_max."""
    frame = _imp_frame(nights).reset_index(drop=True)
    frame["phase"] = ""
    night = nights[which]
    stamps = night.start - pd.to_timedelta(np.arange(PREHEAT_ROWS, 0, -1) * 300, unit="s")
    pre = pd.DataFrame({
        "timestamp": [t.isoformat() for t in stamps],
        "t_air": np.linspace(21.0, 23.4, PREHEAT_ROWS), "t_out": night.t_out_c[0],
        "q_hc": 4200.0, "setpoint": 23.5, "heating": 1, "night": night.night_id,
        "kind": night.kind, "t_flow_c": 45.0, "t_return_c": 38.0, "t_flow_target_c": 47.0,
        "dhw": 0.0, "label": "", "phase": "preheat"})
    frame["heating"] = (frame["kind"] == "normal").astype(int)
    at = int(np.flatnonzero(frame["night"] == night.night_id)[0])
    return pd.concat([frame.iloc[:at], pre, frame.iloc[at:]], ignore_index=True)


def _same(a, b) -> bool:
    return (a.night_id, a.kind, a.start, a.setpoint_c) == (b.night_id, b.kind, b.start,
                                                          b.setpoint_c) and all(
        np.array_equal(getattr(a, f), getattr(b, f)) for f in ("time_s", "t_air_c", "q_hc_w"))


def test_a_preheat_is_its_nights_piece_read_by_the_season_model_only(tmp_path, imp_nights):
    constrained = next(i for i, n in enumerate(imp_nights) if n.kind == "constrained")
    owner = _owner_frame("2026-01-03", heating=1)
    path = tmp_path / "pre.csv"
    pd.concat([owner, _with_preheat(imp_nights, constrained)]).to_csv(path, index=False)
    nights = read_nights(path, TZ)
    plain = read_nights(_file(tmp_path / "plain.csv", owner.drop(columns=["heating"]),
                              _imp_frame(imp_nights)), TZ)
    k = next(i for i, n in enumerate(nights) if n.phase)
    night = imp_nights[constrained]
    assert sum(bool(n.phase) for n in nights) == 1 and len(nights) == len(plain) + 1
    piece = nights[k]
    # the night's id and kind; its own rows, time 0 at its first; right before its night
    assert (piece.night_id, piece.kind, piece.phase) == (night.night_id, "constrained",
                                                         "preheat")
    assert piece.start == night.start - pd.Timedelta(hours=2) and len(piece.time_s) == 24
    assert piece.setpoint_c == 23.5 and (piece.t_flow_target_c == 47.0).all()
    assert (nights[k + 1].night_id, nights[k + 1].phase) == (night.night_id, "")
    # every night as it was read without the pre-heat: the window starts the night
    rest = [n for n in nights if not n.phase]
    assert len(rest) == len(plain) and all(_same(a, b) for a, b in zip(rest, plain,
                                                                       strict=True))
    # the IMP fit's side leaves it out; the same nights chosen
    imp, note = split_owner(nights)
    assert len(imp) == len(imp_nights) and not any(n.phase for n in imp)
    assert note.endswith("(1)")  # the one owner night; the pre-heat is its night's
    with_pre, without = choose_nights(nights), choose_nights(plain)
    assert [n.night_id for n in with_pre.chosen] == [n.night_id for n in without.chosen]
    assert all(_same(a, b) for a, b in zip(with_pre.nights, without.nights, strict=True))
    # the season model's grid: the 2 h before the switch-off are recorded, not a gap
    rec = record_from_nights(nights)
    t = rec.t0_s + np.arange(rec.n) * rec.step_s
    span = (t >= piece.start.timestamp()) & (t < night.start.timestamp())
    assert span.sum() == 24 and np.isfinite(rec.t_air_c[span]).all()
    assert (rec.night_id[span] == night.night_id).all()
    gap = record_from_nights(plain)
    assert not np.isfinite(gap.t_air_c[(gap.t0_s + np.arange(gap.n) * gap.step_s
                                        >= piece.start.timestamp())][:24]).any()
    # written and read back the same (the pre-heat right before its night)
    again = read_nights(write_nights(nights, tmp_path / "again.csv"), TZ)
    assert [(n.night_id, n.phase) for n in again] == [(n.night_id, n.phase) for n in nights]
    assert all(a.start == b.start and a.kind == b.kind and np.allclose(a.t_air_c, b.t_air_c)
               and np.array_equal(a.time_s, b.time_s)
               for a, b in zip(again, nights, strict=True))


def _refused(tmp_path: Path, frame: pd.DataFrame, name: str) -> str:
    path = tmp_path / f"{name}.csv"
    frame.to_csv(path, index=False)
    res = run_cli("fit", "--nights", str(path), model_dir=tmp_path / "none")
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0], lines
    return lines[0]


def test_a_phase_that_cannot_be_right_is_refused_in_one_line(tmp_path, imp_nights):
    good = _with_preheat(imp_nights)
    first = int(np.flatnonzero(good["phase"] == "preheat")[0])
    word = good.copy()
    word.loc[first + 3, "phase"] = "pre-heat"
    line = _refused(tmp_path, word, "word")
    assert "column 'phase': 'pre-heat' is not 'preheat' or empty" in line, line
    assert f"row {first + 5}" in line, line
    late = good.copy()
    late.loc[first + PREHEAT_ROWS + 2, "phase"] = "preheat"  # inside the window
    line = _refused(tmp_path, late, "late")
    assert "has a pre-heat row after a row of its window" in line, line
    assert f"row {first + PREHEAT_ROWS + 4}" in line, line
    owner = _owner_frame("2026-01-05", rows=20)
    owner["phase"] = ["preheat"] * 3 + [""] * 17
    line = _refused(tmp_path, owner, "owner")
    assert "only IMP nights have a pre-heat (night 'owner-2026-01-05' is an owner night)" in (
        line), line
    line = _refused(tmp_path, good.drop(columns=["night"]), "no-night")
    assert "pre-heat rows need the 'night' column" in line and f"row {first + 2}" in line, line


def test_the_heating_curve_does_not_read_a_preheat(tmp_path, imp_nights):
    from impctl.curve.data.rows import read_rows

    normal = next(i for i, n in enumerate(imp_nights) if n.kind == "normal")
    path = tmp_path / "pre.csv"
    frame = _with_preheat(imp_nights, normal)
    frame.to_csv(path, index=False)
    rows = read_rows(path, TZ)
    # impctl's raised setpoint is neither the curve the heat pump runs nor the owner's need
    assert len(rows) == len(frame) - PREHEAT_ROWS
    assert not (rows["setpoint"] == 23.5).any() and not (rows["t_flow_target_c"] == 47.0).any()
