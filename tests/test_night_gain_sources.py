"""Where a fit's night gain comes from (declared, measured, estimated, assumed), the optional
NIGHTS columns that inform it, the held-setpoint test of auto-cut nights and what a fit must
not report as determined. Quick: no fit here (the fits are in test_fit.py and
test_fit_cli.py)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from impctl.fit.checks.cross_checks import cross_checks
from impctl.fit.checks.undetermined import mark_undetermined, nuisance_at_bound, table_iv
from impctl.fit.gain import resolve
from impctl.fit.nights.data import prepare_nights
from impctl.fit.result.table import format_table
from impctl.imp import read_nights
from impctl.imp.gain import NIGHT_GAIN_SD_W, NIGHT_GAIN_W, measured_gain_w, measured_sd_w

TWIN = Path("/work/shared/realdata/twinhouse")
if not TWIN.is_dir():   # the repository's own checkout: the data beside it
    TWIN = Path(__file__).parents[2] / "shared" / "realdata" / "twinhouse"


def _csv(path: Path, **extra) -> Path:
    """Two labelled nights (one held, one constrained), 15-min rows, with ``extra`` columns."""
    rows = []
    for night, kind, day in (("a", "normal", "2026-01-10"), ("b", "constrained", "2026-01-11")):
        stamps = pd.date_range(f"{day} 22:00", periods=29, freq="15min", tz="Europe/Ljubljana")
        for k, t in enumerate(stamps):
            rows.append({"timestamp": t.isoformat(), "t_air": 21.0 - (0.1 * k if kind ==
                         "constrained" else 0.0), "t_out": 0.0,
                         "q_hc": 2000.0 if kind == "normal" else 0.0, "night": night,
                         "kind": kind})
    frame = pd.DataFrame(rows)
    for col, values in extra.items():
        frame[col] = values(len(frame)) if callable(values) else values
    frame.to_csv(path, index=False)
    return path


def test_p_house_w_measures_the_gain_night_by_night(tmp_path):
    """p_house_w and occupants become each night's mean; bad cells are missing, not numbers
    and not a refused file; the fit's gain is "measured" with the mean and its SD."""
    def p_house(n):
        v = np.full(n, 200.0).astype(object)
        v[3], v[4], v[5] = "", "n/a", -50.0   # empty, text, implausible: missing
        return v

    nights = read_nights(_csv(tmp_path / "n.csv", p_house_w=p_house, occupants=2), "UTC")
    assert [n.p_house_w for n in nights] == [200.0, 200.0]
    assert [n.occupants for n in nights] == [2.0, 2.0]
    gain = resolve(None, None, nights)
    assert gain.source == "measured"
    assert gain.value_w == pytest.approx(measured_gain_w(200.0, 2.0))
    assert gain.value_w == pytest.approx(0.95 * 200.0 + 150.0)
    assert gain.sd_w == pytest.approx(measured_sd_w(200.0, 2.0)) and 20.0 < gain.sd_w < 40.0
    assert "measured" in gain.statement() and "2.0 sleepers" in gain.statement()
    # a column present on too few rows of a night is not a measurement of it
    sparse = read_nights(_csv(tmp_path / "s.csv", p_house_w=lambda n: np.where(
        np.arange(n) % 2 == 0, 100.0, np.nan)), "UTC")
    assert all(math.isnan(n.p_house_w) for n in sparse)


def test_a_declared_gain_is_known_and_nothing_declared_is_assumed_last(tmp_path):
    nights = read_nights(_csv(tmp_path / "n.csv", p_house_w=300.0), "UTC")
    zero = resolve(0.0, None, nights)
    assert (zero.source, zero.value_w, zero.sd_w) == ("declared", 0.0, 0.0)
    assert zero.statement() == "night gain declared 0 W (known, ± 0 W)"
    assert "p_house_w" in zero.detail           # the measurement was not used, and said so
    assert resolve(100.0, 20.0, nights).sd_w == 20.0
    bare = read_nights(_csv(tmp_path / "b.csv"), "UTC")
    assumed = resolve(None, None, bare)
    assert (assumed.source, assumed.value_w, assumed.sd_w) == (
        "assumed", NIGHT_GAIN_W, NIGHT_GAIN_SD_W)
    assert "assumed" in assumed.statement() and "not measured" in assumed.statement()
    # a fleet's per-household declaration: the nights' own night_gain_w column, night by night
    column = read_nights(_csv(tmp_path / "c.csv", night_gain_w=lambda n: np.where(
        np.arange(n) < n // 2, 100.0, 300.0), p_house_w=50.0), "UTC")
    own = resolve(None, None, column)
    assert (own.source, own.value_w, own.sd_w) == ("declared", 200.0, 0.0)
    assert own.per_night_w == {"a": 100.0, "b": 300.0} and "p_house_w not used" in own.detail
    assert resolve(0.0, None, column).value_w == 0.0   # the option wins over the column


def test_room_sensors_replace_t_air_and_the_outdoor_reference_is_checked(tmp_path):
    """t_rooms_c is the fit's indoor temperature where present (the controller's t_air kept
    as the offset); t_out_ref_c gives the outdoor sensor's offset, flagged when persistent."""
    nights = read_nights(_csv(tmp_path / "n.csv", t_rooms_c=lambda n: np.full(n, 20.6),
                              t_out_ref_c=-2.0), "UTC")
    assert np.allclose(nights[0].t_air_c, 20.6)
    assert nights[0].t_air_offset_k == pytest.approx(0.4)
    assert nights[1].t_out_offset_k == pytest.approx(2.0)
    checks = cross_checks(nights)
    assert checks["t_air_minus_rooms_k"]["nights"] == 2
    assert checks["t_out_minus_ref_k"]["flagged"] and "+2.0 K" in checks[
        "t_out_minus_ref_k"]["statement"]
    small = read_nights(_csv(tmp_path / "m.csv", t_out_ref_c=-1.0), "UTC")
    assert not cross_checks(small)["t_out_minus_ref_k"]["flagged"]
    # implausible room values are missing; too few left: the controller's T_air stays
    bad = read_nights(_csv(tmp_path / "x.csv", t_rooms_c=99.0), "UTC")
    assert np.allclose(bad[0].t_air_c, 21.0) and math.isnan(bad[0].t_air_offset_k)


def test_the_twin_houses_rolbs_nights_are_dropped_with_their_reason(tmp_path):
    """A slice of the real N2_auto.csv (Annex 58): the held 30 °C nights are normal nights;
    the nights of the pseudo-random heat sequence and of a constant 500 W that does not hold
    the room are neither kind, and the fit skips them saying why."""
    src = pd.read_csv(TWIN / "N2_auto.csv")
    stamps = pd.to_datetime(src["timestamp"], utc=True)
    part = src[(stamps >= "2013-08-27T12:00Z") & (stamps < "2013-09-02T12:00Z")]
    path = tmp_path / "N2_slice.csv"
    part.to_csv(path, index=False)
    nights = {n.night_id: n for n in read_nights(path, "Etc/GMT-1")}
    held = ["2013-08-27", "2013-08-28"]
    for i in held:
        assert nights[i].kind == "normal" and nights[i].not_held == ""
    assert "fixed heat input" in nights["2013-08-30"].not_held  # 500 W, T_air falls
    assert "heat pulses" in nights["2013-08-31"].not_held      # the sequence's pulses
    assert "heat pulses" in nights["2013-09-01"].not_held
    assert nights["2013-08-29"].not_held                        # switched off mid-night
    kept, _, skipped = prepare_nights(list(nights.values()))
    assert {n.night_id for n in kept if n.kind == "normal"} == set(held)
    reasons = dict(skipped)
    assert {"2013-08-29", "2013-08-30", "2013-08-31", "2013-09-01"} <= set(reasons)
    assert "not held" in reasons["2013-08-30"] or "heat pulses" in reasons["2013-08-30"]
    # labelled nights are taken as labelled: the test is for auto-cut nights only
    labelled = part.assign(night="x", kind="normal")
    labelled = labelled[pd.to_datetime(labelled["timestamp"], utc=True).between(
        "2013-08-30T21:00Z", "2013-08-31T04:00Z")]
    labelled.to_csv(path, index=False)
    assert read_nights(path, "Etc/GMT-1")[0].not_held == ""


def test_a_nuisance_term_at_its_bound_is_named_and_its_quantities_not_determined():
    from impctl.fit.nights.data import Estimate

    nuisance = {"night_gain_w": {"value": 250.0, "low": 80.0, "high": 420.0,
                                 "bounds": [0.0, 500.0], "assumed": True, "pinned": True},
                "emitter_w": {"value": 3999.0, "low": 3500.0, "high": 4000.0,
                              "bounds": [0.0, 4000.0]},
                "emitter_tau_h": {"value": 0.21, "low": 0.2, "high": 1.0,
                                  "bounds": [0.2, 8.0]},    # the low bound says nothing
                "furniture_j_per_m2k": None}
    at = nuisance_at_bound(nuisance)
    assert [t["term"] for t in at] == ["emitter_w"]
    assert at[0]["statement"] == "emitter release at its 4 kW bound: C_m, τ not determined"
    lumped = {k: Estimate(1.0, 0.9, 1.1, True) for k in ("hlc", "c_m", "tau")}
    marked = mark_undetermined(lumped, at)
    assert marked["hlc"].determined and not marked["c_m"].determined
    assert not marked["tau"].determined
    summary = _summary(lumped=marked, at=at)
    text = format_table(summary)
    assert "emitter release at its 4 kW bound: C_m, τ not determined" in text
    assert text.count("NOT determined by these nights") == 2


def test_a_table_iv_parameter_the_data_do_not_determine_is_reported_as_its_prior():
    params = {"floor_area": 290.0, "u_walls": 0.61}
    rep = table_iv(params, {"floor_area": False, "u_walls": True},
                   {"floor_area": (100.0, 200.0), "u_walls": (0.2, 1.0)})
    assert rep["floor_area"] == {"value": 150.0, "source": "prior", "fitted": 290.0,
                                 "prior": 150.0}
    assert rep["u_walls"]["value"] == 0.61 and rep["u_walls"]["source"] == "data"


def _summary(lumped, at) -> dict:
    """The smallest fit summary :func:`format_table` prints."""
    from impctl.fit.ode.parameters import PARAM_NAMES

    return {
        "classes": {}, "lumped": {k: {**e.as_dict(), "unit": "-"} for k, e in lumped.items()},
        "fit": {"nuisance_at_bound": at, "mode": "joint", "normal_model": "demand",
                "time_s": 1.0},
        "bounds": {n: [1.0, 2.0] for n in PARAM_NAMES},
        "parameters": {n: 1.5 for n in PARAM_NAMES},
        "basis": {n: "physical bounds" for n in PARAM_NAMES},
        "validation": {"normal": [], "constrained": [], "mean": {}},
        "per_night": [], "skipped": [], "notes": [],
    }


def test_fleet_fit_takes_the_declared_gain_options(tmp_path):
    """``impctl fleet fit`` has ``--night-gain-w``/``--night-gain-sd-w`` as ``impctl fit``:
    an SD without a declared gain is one line, exit 2, nothing written."""
    from cli_fixtures import run_impctl

    out = tmp_path / "FLEET.parquet"
    res = run_impctl("fleet", "fit", str(tmp_path), "--out", str(out), "--night-gain-sd-w", "10")
    assert res.returncode == 2 and "--night-gain-w" in res.stderr and not out.exists()
    helped = run_impctl("fleet", "fit", "--help")
    assert "--night-gain-w" in helped.stdout and "night_gain_source" in helped.stdout
