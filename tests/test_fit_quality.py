"""Night quality and model adequacy (impctl.fit.nights.quality) on signals with known answers, and
the coarsening of fine rows (impctl.fit.nights.resample)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from impctl.fit.nights.quality import adequacy, night_quality
from impctl.fit.nights.resample import coarsen
from impctl.imp.night import NightSamples


def _night(kind, t, t_air, t_out, q) -> NightSamples:
    return NightSamples("n1", kind, pd.Timestamp("2026-01-10 22:00", tz="UTC"),
                        np.asarray(t, float), np.asarray(t_air, float),
                        np.asarray(t_out, float) * np.ones(len(t)), np.asarray(q, float))


def test_cycling_dhw_block_and_defrost_are_found_on_a_held_night():
    t = np.arange(0, 7 * 3600, 60.0)
    # on/off heat pump: 20 min on, 20 min off → 1.5 cycles per hour
    q = np.where((t // 1200) % 2 == 0, 4000.0, 0.0)
    dhw = (t >= 3 * 3600) & (t < 3 * 3600 + 45 * 60)      # 45 min without space heat
    q[dhw] = 0.0
    q[(t >= 5 * 3600) & (t < 5 * 3600 + 6 * 60)] = -1500.0  # a defrost draws heat
    t_air = np.round(22.0 + 0.2 * np.sin(t / 900.0), 1)
    out = night_quality(_night("normal", t, t_air, 0.0, q))
    assert 1.0 < out["cycles_per_h"] < 1.6
    kinds = [(i["kind"], round(i["start_h"], 1)) for i in out["interruptions"]]
    assert ("defrost", 5.0) in kinds
    assert any(k == "dhw_or_stop" and abs(h - 3.0) < 0.4 for k, h in kinds)
    # ordinary 20-min off phases are cycling, not interruptions
    assert len([k for k, _ in kinds if k == "dhw_or_stop"]) == 1
    assert out["t_air_resolution_k"] == pytest.approx(0.1)


def test_emitter_discharge_time_is_the_time_t_air_stays_off_the_later_cooling_curve():
    t = np.arange(0, 7 * 3600, 300.0)
    tau_s = 30 * 3600.0
    slow = 2.0 + 19.0 * np.exp(-t / tau_s)
    for lag_h in (0.0, 1.5):
        # an emitter adds heat that fades over lag_h: T_air sits above the slow curve
        bump = 0.0 if lag_h == 0 else 0.8 * np.clip(1 - t / (lag_h * 3600), 0, None) ** 2
        out = night_quality(_night("constrained", t, slow + bump, 2.0, np.zeros(len(t))))
        got = out["emitter_discharge_h"]
        if lag_h == 0:
            assert got == 0.0
        else:
            assert 0.5 < got <= lag_h + 0.1


def test_adequacy_speaks_up_when_residuals_are_correlated_or_too_large():
    noise = {"constrained_t_air_k": 0.03, "normal_t_air_k": 0.01, "normal_power_w": 50.0}
    good = adequacy(dict(noise), noise, {"constrained": 0.2, "normal_power": 0.1})
    assert good["adequate"] and "NOT" not in good["statement"]
    bad = adequacy({**noise, "normal_power_w": 400.0}, noise,
                   {"constrained": 0.93, "normal_power": 0.1})
    assert not bad["adequate"]
    assert "autocorrelated" in bad["statement"] and "8.0×" in bad["statement"]


def test_coarsening_keeps_the_energy_and_the_temperature_at_the_nodes():
    rng = np.random.default_rng(0)
    t = np.arange(0, 7 * 3600, 60.0)
    t_air = 20 + 2 * np.exp(-t / 36000.0)
    q = rng.uniform(0, 5000, len(t))
    night = _night("normal", t, t_air + rng.normal(0, 0.05, len(t)), 1.0, q)
    c = coarsen(night, 300.0)
    assert np.all(np.diff(c.time_s) == 300.0) and c.time_s[0] == 0.0
    # energy over the night is unchanged (power held until the next row)
    e_raw = np.sum(q[:-1] * np.diff(t))
    e_new = np.sum(c.q_hc_w[:-1] * np.diff(c.time_s)) + c.q_hc_w[-1] * (t[-1] - c.time_s[-1])
    assert e_new == pytest.approx(e_raw, rel=1e-9)
    # temperatures: centred means estimate the value at the node, with less noise
    true_at = 20 + 2 * np.exp(-c.time_s / 36000.0)
    assert np.abs(c.t_air_c[1:-1] - true_at[1:-1]).std() < 0.05 / 1.8
    # rows already as coarse as the step are left alone
    assert coarsen(c, 300.0) is c


def test_a_held_night_settles_when_t_air_reaches_its_held_level():
    from impctl.fit.nights.data import settled

    rng = np.random.default_rng(3)
    t = np.arange(0.0, 7 * 3600.0, 300.0)
    # a 3 K setpoint step the heat pump needs 2.5 h to climb, then held (sensor noise, 0.1 K)
    t_air = np.round(21.0 + np.minimum(t / 9000.0, 1.0) * 3.0 + rng.normal(0, 0.05, len(t)), 1)
    night = _night("normal", t, t_air, np.zeros(len(t)), np.full(len(t), 3000.0))
    fixed = settled(night, 1.0)
    assert not fixed[t < 3600.0].any() and fixed[t >= 3600.0].all()
    held = settled(night, 1.0, until_held=True)
    first = t[held.argmax()]
    assert 2.0 * 3600.0 <= first <= 2.6 * 3600.0 and held[t >= first].all()
    # a night that starts at its level settles after the fixed hour only
    flat = _night("normal", t, np.full(len(t), 22.0), np.zeros(len(t)), np.full(len(t), 3e3))
    assert np.array_equal(settled(flat, 1.0, until_held=True), settled(flat, 1.0))
