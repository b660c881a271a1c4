"""IMP night plans (DST-safe windows) and the night feature function."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from impctl.errors import InputError
from impctl.imp import (
    DEFAULT_BAND_K,
    DEFAULT_CONSTRAINED_SETPOINT_C,
    DEFAULT_SETPOINTS_C,
    EMISSION_LAG_H,
    NIGHT_FEATURE_NAMES,
    NightPlan,
    NightSamples,
    features_from_arrays,
    imp_plans,
    night_features,
)
from impctl.imp.features import EARLY_SPAN_H

TZ = "Europe/Ljubljana"


# --- plans -------------------------------------------------------------------------------------

def test_plan_band_and_setpoints():
    plan = NightPlan("constrained", setpoint_c=23.0)
    assert (plan.t_max_c, plan.t_min_c) == (23.0 + DEFAULT_BAND_K, 23.0 - DEFAULT_BAND_K)
    assert plan.preheat_setpoint_c == plan.t_max_c and plan.window_setpoint_c == plan.t_min_c
    narrow = NightPlan("constrained", setpoint_c=23.0, band_k=1.5)
    assert (narrow.t_max_c, narrow.t_min_c) == (24.5, 21.5)
    free = NightPlan("constrained", 23.0, stop_at_t_min=False)
    assert np.isnan(free.window_setpoint_c)
    normal = NightPlan("normal", 22.0)
    assert normal.preheat_setpoint_c == normal.window_setpoint_c == 22.0


@pytest.mark.parametrize("date, hours", [
    ("2026-01-12", 7.0),
    ("2026-03-28", 6.0),   # clocks go forward at 02:00 on 29 March 2026
    ("2026-10-24", 8.0),   # clocks go back at 03:00 on 25 October 2026
])
def test_window_duration_is_absolute_time_across_dst(date, hours):
    plan = NightPlan("normal")
    start, end = plan.window(date, TZ)
    assert plan.duration_h(date, TZ) == hours
    assert (start.hour, end.hour) == (22, 5)
    assert start.tzinfo is not None and str(start.date()) == date
    assert plan.preheat_start(date, TZ) == start - pd.Timedelta(hours=2)


def test_window_without_midnight_stays_on_one_day():
    plan = NightPlan("normal", window_start=dt.time(1, 0), window_end=dt.time(4, 0))
    start, end = plan.window("2026-01-12", TZ)
    assert str(end.date()) == "2026-01-12" and (end - start) == pd.Timedelta(hours=3)


@pytest.mark.parametrize("kw, place", [
    ({"kind": "warm"}, "kind"),
    ({"kind": "normal", "band_k": 0.0}, "band_k"),
    ({"kind": "normal", "preheat_h": -1.0}, "preheat_h"),
    ({"kind": "normal", "window_start": dt.time(5), "window_end": dt.time(5)}, "window"),
])
def test_bad_plans_are_refused(kw, place):
    with pytest.raises(InputError) as err:
        NightPlan(**kw)
    assert err.value.place == place


def test_imp_plans_are_the_gateways_nights():
    # One constrained plan at the gateway's constrained T_set, a normal plan per normal setpoint.
    plans = imp_plans()
    assert len(plans) == 1 + len(DEFAULT_SETPOINTS_C)
    assert {(p.kind, p.setpoint_c) for p in plans} == {
        ("constrained", DEFAULT_CONSTRAINED_SETPOINT_C)} | {
        ("normal", s) for s in DEFAULT_SETPOINTS_C}
    every = imp_plans(constrained_setpoint_c=None)
    assert {(p.kind, p.setpoint_c) for p in every} == {
        (k, s) for k in ("constrained", "normal") for s in DEFAULT_SETPOINTS_C}


# --- features ----------------------------------------------------------------------------------

def _night(kind, t_air, t_out, q, step_s=600.0, setpoint=23.0):
    n = len(t_air)
    return NightSamples("n", kind, pd.Timestamp("2026-01-12 22:00", tz=TZ),
                        np.arange(n) * step_s, np.asarray(t_air, float),
                        np.broadcast_to(np.asarray(t_out, float), (n,)).copy(),
                        np.broadcast_to(np.asarray(q, float), (n,)).copy(), setpoint)


def _decay(k_per_h, t_out, t0=24.0, step_s=600.0, hours=7.0):
    """Exact solution of dT/dt = −k·(T − T_out(t)) for a piecewise-linear T_out, fine steps."""
    fine = np.arange(0.0, hours * 3600.0 + 1.0, 10.0)
    te = np.interp(fine, np.linspace(0, hours * 3600.0, len(t_out)), t_out)
    t = np.empty_like(fine)
    t[0] = t0
    a = np.exp(-k_per_h * 10.0 / 3600.0)
    for i in range(1, len(fine)):
        t[i] = te[i - 1] + (t[i - 1] - te[i - 1]) * a
    keep = np.arange(0, len(fine) - 1, int(step_s / 10.0))
    return t[keep], te[keep]


@pytest.mark.parametrize("t_out", [[0.0, 0.0], [4.0, -4.0]])
def test_decay_rate_recovers_k_even_when_t_out_drifts(t_out):
    t_air, te = _decay(0.03, t_out)
    f = night_features(_night("constrained", t_air, te, 0.0))
    assert f["decay_rate_per_h"] == pytest.approx(0.03, rel=0.02)
    # A per-sample log-linear fit would be fooled by the falling T_out; this one is not.
    assert f["is_constrained"] == 1.0 and np.isnan(f["q_hc_mean_w"])
    assert f["cooling_time_h"] == pytest.approx(7.0 - 1.0 - 1.0 / 6.0)


def test_samples_inside_the_emitter_lag_are_ignored():
    t_air, te = _decay(0.02, [0.0, 0.0])
    base = night_features(_night("constrained", t_air, te, 0.0))
    garbage = t_air.copy()
    garbage[:6] = [30.0, 10.0, 40.0, 5.0, 50.0, 0.0]   # the first hour: emitters still warm
    assert night_features(_night("constrained", garbage, te, 0.0)) == pytest.approx(
        base, nan_ok=True)
    later = night_features(_night("constrained", t_air, te, 0.0), emission_lag_h=2.0)
    assert later["cooling_time_h"] == pytest.approx(base["cooling_time_h"] - 1.0)


def test_constrained_night_ends_where_the_heating_resumes():
    t_air, te = _decay(0.05, [0.0, 0.0])
    q = np.zeros_like(t_air)
    q[20:] = 2500.0                     # T_min reached: heating back on at 3 h 20 min
    f = night_features(_night("constrained", t_air, te, q))
    assert f["cooling_time_h"] == pytest.approx(20 / 6 - 1.0 - 1 / 6)
    assert f["delta_t_air_k"] == pytest.approx(t_air[6] - t_air[19])
    assert f["decay_rate_per_h"] == pytest.approx(0.05, rel=0.03)


def test_early_decay_rate_is_the_same_whether_the_night_stops_at_t_min_or_not():
    """The early decay rate reads the first EARLY_SPAN_H after the cut on every night: a night
    stopped at T_min (the gateway's) and the same night cooled to 05:00 give the same value,
    while the whole-night decay rate of a two-speed cooling curve depends on where it stops."""
    hours = np.arange(42) / 6.0
    # Fast part (emitter, air, furniture) over a slow mass decay, both towards T_out = 0 °C.
    t_air = 3.0 * np.exp(-hours / 0.8) + 21.0 * np.exp(-hours * 0.02)
    q = np.zeros_like(t_air)
    stopped = q.copy()
    stopped[22:] = 2500.0                 # T_min at 3 h 40 min: heating back on
    whole = night_features(_night("constrained", t_air, 0.0, q))
    cut = night_features(_night("constrained", t_air, 0.0, stopped))
    rows = (hours >= EMISSION_LAG_H) & (hours < EMISSION_LAG_H + EARLY_SPAN_H - 1e-9)
    assert rows.sum() == EARLY_SPAN_H * 6
    assert cut["decay_rate_early_per_h"] == whole["decay_rate_early_per_h"]
    assert cut["decay_rate_early_per_h"] > cut["decay_rate_per_h"] > whole["decay_rate_per_h"]
    assert whole["decay_rate_per_h"] == pytest.approx(0.02, rel=0.5)
    assert np.isnan(night_features(_night("normal", t_air, 0.0, 3000.0))["decay_rate_early_per_h"])


def test_normal_night_heat_loss_features():
    hours = np.arange(42) / 6.0
    t_out = 2.0 - 0.5 * hours + 0.3 * np.sin(hours * 3.0)
    hlc = 180.0
    q = hlc * (22.0 - t_out)
    f = night_features(_night("normal", np.full(42, 22.0), t_out, q, setpoint=22.0))
    assert f["q_per_k_w_per_k"] == pytest.approx(hlc)
    assert f["q_per_t_out_w_per_k"] == pytest.approx(hlc)
    assert f["q_hc_mean_w"] == pytest.approx(q.mean())
    assert f["t_set_c"] == 22.0 and f["t_out_mean_c"] == pytest.approx(t_out.mean())
    assert np.isnan(f["decay_rate_per_h"]) and np.isnan(f["cooling_time_h"])


def test_unknown_setpoint_falls_back_to_median_air_and_short_nights_give_nan():
    f = night_features(_night("normal", [21.9, 22.1, 22.0, 22.0], 0.0, 3000.0,
                              setpoint=float("nan")))
    assert f["t_set_c"] == pytest.approx(22.0)
    short = night_features(_night("normal", [22.0, 22.0], 0.0, 3000.0))
    assert np.isnan(short["q_hc_mean_w"]) and np.isnan(short["q_slope_w_per_h"])
    ended = night_features(_night("constrained", [24.0, 23.0, 22.0], 0.0, 0.0))
    assert ended["cooling_time_h"] == 0.0 and np.isnan(ended["decay_rate_per_h"])


def test_array_form_and_single_night_form_agree():
    rng = np.random.default_rng(3)
    n_t, n = 42, 8
    t_air = 23.0 - np.cumsum(rng.uniform(0, 0.1, (n_t, n)), axis=0)
    t_out = rng.normal(0.0, 2.0, (n_t, n))
    q = rng.uniform(0, 4000, (n_t, n)) * (np.arange(n) % 2 == 1)
    cons = np.arange(n) % 2 == 0
    sp = np.full(n, 23.0)
    valid = np.arange(n_t)[:, None] < rng.integers(10, n_t, n)[None, :]
    batch = features_from_arrays(np.arange(n_t) * 600.0, t_air, t_out, q, constrained=cons,
                                 setpoint_c=sp, valid=valid)
    assert list(batch) == list(NIGHT_FEATURE_NAMES)
    for j in range(n):
        m = valid[:, j]
        one = night_features(NightSamples(
            "x", "constrained" if cons[j] else "normal", pd.Timestamp("2026-01-12", tz=TZ),
            np.arange(n_t)[m] * 600.0, t_air[m, j], t_out[m, j], q[m, j], 23.0))
        assert one == pytest.approx({k: v[j] for k, v in batch.items()}, nan_ok=True)


@settings(max_examples=40, deadline=None)
@given(shift=st.floats(-15, 15), scale=st.floats(0.2, 5.0), k=st.floats(0.005, 0.2))
def test_features_follow_temperature_shifts_and_power_scaling(shift, scale, k):
    t_air, te = _decay(k, [3.0, -2.0])
    hours = np.arange(len(te)) / 6.0
    q = 150.0 * (23.0 - te) + 40.0 * hours
    for kind in ("constrained", "normal"):
        qq = q if kind == "normal" else 0.0 * q
        base = night_features(_night(kind, t_air, te, qq))
        moved = night_features(_night(kind, t_air + shift, te + shift, qq * scale,
                                      setpoint=23.0 + shift))
        assert moved["t_out_mean_c"] == pytest.approx(base["t_out_mean_c"] + shift, abs=1e-9)
        for name in ("decay_rate_per_h", "decay_rate_early_per_h", "cooling_time_h",
                     "delta_t_air_k"):
            assert moved[name] == pytest.approx(base[name], rel=1e-6, abs=1e-9, nan_ok=True)
        for name in ("q_hc_mean_w", "q_per_k_w_per_k", "q_slope_w_per_h", "q_per_t_out_w_per_k"):
            assert moved[name] == pytest.approx(scale * base[name], rel=1e-6, abs=1e-6,
                                                nan_ok=True)


def test_emission_lag_default_is_one_hour():
    assert EMISSION_LAG_H == 1.0
