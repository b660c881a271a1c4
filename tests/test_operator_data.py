"""Issue 12, the data side of NIGHTS.csv: heat output in kW, gaps inside nights, naive
timestamps across a DST change, long logs — tried exactly as the issue writes them; each must
be refused loudly (exit 2, one line naming the file, nothing written) or handled by a
documented rule that the output reports.

Runs the real ``impctl`` command line in-process (the helpers of ``test_reliability_input``)
on NIGHTS.csv files written from simulated nights (``operator_fixtures``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from operator_fixtures import base_nights, fit_refused, nights, nights_csv, scaled
from test_reliability_input import cli, refused

from impctl.errors import InputError
from impctl.imp import read_nights
from impctl.imp.gaps import MIN_GAP_S, cut_at_gaps, gap_indices
from impctl.imp.plausibility import check_units, fit_problem, hlc_problem

FAST = settings(max_examples=60, deadline=None, derandomize=True)
__all__ = ["nights", "nights_csv"]  # module-scoped fixtures shared with test_operator_options

# -- 7. units --------------------------------------------------------------------------------------
@pytest.mark.parametrize("labels", [True, False])
def test_fit_on_q_hc_in_kw_is_refused_naming_the_unit(tmp_path, nights_csv, labels):
    """The issue: q_hc in kW gave exit 0, HLC 7.9 W/K, ε 14,487 %."""
    kw = scaled(nights_csv, tmp_path / "kw.csv", 1e-3, labels=labels)
    (line,) = fit_refused(tmp_path, kw)
    assert "column 'q_hc'" in line and "kW" in line and "1000" in line
    (line,) = refused(cli("classify", "--nights", str(kw)), kw)
    assert "kW" in line


def test_a_signed_reading_in_a_defrost_is_fitted_not_refused(tmp_path, nights_csv):
    """A heat reading that goes negative while a defrost draws heat from the water (the
    gateway stores what the heat pump reports) is data: ``impctl fit`` fits the file, lists the
    defrost among the held night's interruptions and keeps the night."""
    frame = pd.read_csv(nights_csv)
    held = frame.index[frame["kind"] == "normal"]
    frame.loc[held[8], "q_hc"] = -1500.0
    path = tmp_path / "defrost.csv"
    frame.to_csv(path, index=False)
    code, _, err = cli("fit", "--nights", str(path), "--json", str(tmp_path / "fit.json"))
    assert code == 0, err
    quality = json.loads((tmp_path / "fit.json").read_text())["night_quality"]
    defrosted = [q for q in quality if any(i["kind"] == "defrost" for i in q["interruptions"])]
    assert len(defrosted) == 1 and defrosted[0]["used"]
    frame.loc[held[8], "q_hc"] = -40000.0   # not a defrost: a wrong column or unit
    frame.to_csv(path, index=False)
    (work := tmp_path / "refused").mkdir()
    (line,) = fit_refused(work, path)
    assert "column 'q_hc': -40000 is outside -25000…100000 W" in line


@pytest.mark.parametrize("factor, words", [(0.03, "far too small"), (0.04, "far too small"),
                                           (13.0, "far too large")])
def test_power_implausible_for_the_temperature_difference_is_refused(tmp_path, nights_csv,
                                                                       factor, words):
    """q_hc × 0.03, × 0.04 or × 13 (a wrong unit or column): the fit would end at a bound of
    its search box with exit 0 — refused before fitting, naming the cause."""
    bad = scaled(nights_csv, tmp_path / "bad.csv", factor)
    (line,) = fit_refused(tmp_path, bad)
    assert words in line and "10–2,000 W/K" in line


@FAST
@given(st.floats(1e-4, 1e3))
def test_unit_check_accepts_exactly_plausible_implied_hlc(scale):
    """check_units refuses iff the implied HLC leaves 10–2,000 W/K (or q never exceeds 100 W
    while heating), whatever the scale of q_hc."""
    base = base_nights(3600.0)
    scaled = [type(n)(**{**n.__dict__, "q_hc_w": np.asarray(n.q_hc_w) * scale}) for n in base]
    normal = [n for n in scaled if n.kind == "normal"]
    implied = np.median([np.mean(n.q_hc_w) / np.mean(n.t_air_c - n.t_out_c) for n in normal])
    q_max = max(float(np.max(n.q_hc_w)) for n in scaled)
    expect_ok = 10 <= implied <= 2000 and not 1 <= q_max <= 100
    try:
        check_units(scaled, "x.csv")
        assert expect_ok, (scale, implied, q_max)
    except InputError as exc:
        assert not expect_ok, (scale, implied, q_max)
        assert str(exc).startswith("x.csv: column 'q_hc': ")


def test_a_fitted_hlc_outside_a_dwelling_names_the_likely_cause():
    assert hlc_problem(150.0, "HLC") is None
    assert "looks like kW" in hlc_problem(0.15, "HLC")
    assert "far too small" in hlc_problem(1e-6, "HLC")
    assert "far too large" in hlc_problem(5000.0, "HLC")
    assert fit_problem(150.0, 19.0) is None
    assert "misses the measured heat" in fit_problem(150.0, 150.0)
    assert "the fitted HLC" in fit_problem(5.0, 10.0)


# -- 8. gaps ---------------------------------------------------------------------------------------
def _drop_hours(src: Path, dst: Path, night_no: int, start_h: float, end_h: float) -> Path:
    frame = pd.read_csv(src)
    stamps = pd.to_datetime(frame["timestamp"], utc=True)
    night = frame["night"].unique()[night_no]
    t0 = stamps[frame["night"] == night].iloc[0]
    drop = ((frame["night"] == night) & (stamps >= t0 + pd.Timedelta(hours=start_h))
            & (stamps < t0 + pd.Timedelta(hours=end_h)))
    frame[~drop].to_csv(dst, index=False)
    return dst


def test_three_hour_gap_in_a_normal_night_is_not_bridged(tmp_path, nights, nights_csv):
    """The issue: a 3-hour gap inside a normal night was bridged (its energy doubled)."""
    normal_no = [n.kind for n in nights].index("normal")
    gap = _drop_hours(nights_csv, tmp_path / "gap.csv", normal_no, 1.0, 4.0)
    code, out, err = cli("fit", "--nights", str(gap), "--json", str(tmp_path / "fit.json"))
    assert code == 0, err
    result = json.loads((tmp_path / "fit.json").read_text())
    night_id = nights[normal_no].night_id
    (g,) = result["gaps"]
    assert g["night_id"] == night_id and g["kind"] == "normal" and 3.0 <= g["hours"] <= 3.5
    assert f"gap in normal night {night_id}" in out
    # The longest piece (after the gap) is 2.8 h, under the 3 h minimum: the night is dropped,
    # said out loud, and no validation row bridges the gap.
    assert any(s["night_id"] == night_id for s in result["skipped"])
    assert night_id not in [r["night_id"] for r in result["validation"]["normal"]]
    truth = {n.night_id: np.sum(n.q_hc_w[:-1] * np.diff(n.time_s)) / 3.6e6 for n in nights}
    for row in result["validation"]["normal"]:
        assert row["q_measured_kwh"] == pytest.approx(truth[row["night_id"]], rel=0.01)


def test_gap_rule_constrained_keeps_before_the_gap_normal_keeps_the_longest_piece(nights):
    cons = next(n for n in nights if n.kind == "constrained")
    normal = next(n for n in nights if n.kind == "normal")

    def without(night, lo_h, hi_h):
        keep = (night.time_s < lo_h * 3600) | (night.time_s >= hi_h * 3600)
        return type(night)(**{**night.__dict__, **{k: np.asarray(getattr(night, k))[keep]
                                                    for k in ("time_s", "t_air_c", "t_out_c",
                                                              "q_hc_w")}})

    (c, n), gaps = cut_at_gaps([without(cons, 4.0, 5.0), without(normal, 2.0, 3.0)])
    assert len(gaps) == 2
    assert c.time_s[-1] < 4 * 3600 and c.time_s[0] == cons.time_s[0]
    assert n.time_s[0] >= 3 * 3600 and n.time_s[-1] == normal.time_s[-1]  # 3–7 h > 0–2 h
    # one lost 15-minute sample is no gap; a gap inside the emission lag is ignored
    (same,), none = cut_at_gaps([without(normal, 2.0, 2.25)])
    assert not none and len(same.time_s) == len(normal.time_s) - 1
    (lag,), none = cut_at_gaps([without(cons, 0.25, 1.0)], emission_lag_h=1.0)
    assert not none


@FAST
@given(st.lists(st.integers(0, 27), max_size=15, unique=True))
def test_no_kept_night_holds_a_gap(drops):
    """Whatever samples are lost, every night after the cut is gap-free and a contiguous run
    of the original samples."""
    base = base_nights(900.0)
    lost = []
    for n in base:
        keep = np.ones(len(n.time_s), bool)
        keep[[d for d in drops if d < len(keep)]] = False
        lost.append(type(n)(**{**n.__dict__, **{k: np.asarray(getattr(n, k))[keep] for k in
                                                ("time_s", "t_air_c", "t_out_c", "q_hc_w")}}))
    cut, gaps = cut_at_gaps(lost, emission_lag_h=1.0)
    for before, after in zip(lost, cut, strict=True):
        if after.kind == "normal" or not len(after.time_s):
            assert not len(gap_indices(after.time_s))
        start = int(np.searchsorted(before.time_s, after.time_s[0]))
        assert np.array_equal(before.time_s[start:start + len(after.time_s)], after.time_s)
        steps = np.diff(after.time_s)
        assert after.kind == "constrained" or not np.any(steps > max(2 * np.median(
            np.diff(before.time_s)), MIN_GAP_S))
    assert all(g.hours > 0 for g in gaps)


# -- 13. DST --------------------------------------------------------------------------------------
@pytest.mark.parametrize("day, words", [("2026-10-25", "occurs twice"),
                                        ("2026-03-29", "does not exist")])
def test_naive_timestamps_across_a_dst_change_name_the_row_and_what_to_do(tmp_path, day, words):
    path = tmp_path / "nights.csv"
    hours = ["00:00", "01:00", "01:30", "02:00", "02:30", "03:00", "04:00"]
    path.write_text("timestamp,t_air,t_out,q_hc\n" + "".join(
        f"{day}T{h},21.0,2.0,0\n" for h in hours))
    (line,) = fit_refused(tmp_path, path)
    assert "row 5" in line and words in line and "UTC offset" in line
    for pandas_words in ("infer", "ambiguous=", "NonExistentTimeError", "AmbiguousTimeError"):
        assert pandas_words not in line
    if words == "occurs twice":
        assert f"{day}T02:00:00+02:00" in line and f"{day}T02:00:00+01:00" in line


# -- fit on a long log -----------------------------------------------------------------------------
def test_fit_uses_the_most_recent_nights_and_says_so(tmp_path, nights_csv):
    code, out, err = cli("fit", "--nights", str(nights_csv), "--max-nights", "3", "--json",
                         str(tmp_path / "fit.json"))
    assert code == 0, err
    result = json.loads((tmp_path / "fit.json").read_text())
    used = [p["night_id"] for p in result["per_night"]]
    all_ids = [n.night_id for n in read_nights(nights_csv)]
    assert len(used) == 3 and used == sorted(used)
    assert {p["kind"] for p in result["per_night"]} == {"constrained", "normal"}
    assert used[-1] == all_ids[-1]
    assert any("the 3 most recent" in n for n in result["notes"])
    assert "fitting 3 nights" in err


def test_a_file_above_the_documented_size_is_refused_before_reading(tmp_path):
    from impctl.cli.checks import MAX_FILE_MB

    big = tmp_path / "big.csv"
    with big.open("wb") as fh:
        fh.truncate(int((MAX_FILE_MB + 1) * 1e6))
    (line,) = fit_refused(tmp_path, big)
    assert "MB" in line and "last 60 days" in line
    refused(cli("classify", "--nights", str(big)), big)
    assert math.isfinite(MAX_FILE_MB)
