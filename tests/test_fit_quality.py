"""Night quality and model adequacy (impctl.fit.nights.quality) on signals with known answers, and
the coarsening of fine rows (impctl.fit.nights.resample)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from impctl.fit.nights.quality import adequacy, night_quality, residual_blocks
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


def _adequacy_of(residual_k, residual_w, resolution_k=0.1, mean_power_w=3000.0):
    """The verdict on given residual series (one 7 h night each, 5-min rows)."""
    grid = np.arange(len(residual_k)) * 300.0
    blocks = {"constrained": residual_blocks(residual_k[None], np.ones((1, len(grid)), bool),
                                             grid[None]),
              "normal_power": residual_blocks(residual_w[None], np.ones((1, len(grid)), bool),
                                              grid[None])}
    sigma = {"constrained_t_air_k": float(np.std(residual_k)), "normal_t_air_k": 0.01,
             "normal_power_w": float(np.std(residual_w))}
    noise = {"constrained_t_air_k": 0.01, "normal_t_air_k": 0.01,
             "normal_power_w": float(np.std(np.diff(residual_w, 2)) / np.sqrt(6))}
    return adequacy(sigma, noise, {"constrained": 0.3, "normal_power": 0.2}, blocks,
                    resolution_k, mean_power_w)


def test_adequacy_passes_white_residuals_and_names_hour_scale_structure():
    rng = np.random.default_rng(3)
    n = 7 * 12 * 4   # four nights' worth of 5-min rows in one series
    t_h = np.arange(n) / 12.0
    white_k, white_w = rng.normal(0, 0.03, n), rng.normal(0, 150.0, n)
    good = _adequacy_of(white_k, white_w)
    assert good["adequate"], good["statement"]
    g = good["groups"]["constrained"]
    assert 0.5 < g["low_frequency_ratio"] < 1.6 and g["whiteness_p"] > 0.01
    # rounding to 0.1 K leaves 0.1/√12 K: the data's own floor (0.01 K) does not set it
    assert g["reading_noise"] == pytest.approx(0.1 / np.sqrt(12))
    # a slow swing the model misses: 0.2 K on T_air, 400 W (13 %) on the held power
    bad = _adequacy_of(white_k + 0.2 * np.sin(t_h / 1.5), white_w + 400 * np.sin(t_h / 1.5))
    assert not bad["adequate"]
    assert "constrained-night T_air" in bad["statement"] and "0.05 K" in bad["statement"]
    assert "held-night heat power" in bad["statement"] and "5 % of the mean" in bad["statement"]
    assert bad["groups"]["constrained"]["hour_scale_residual"] == pytest.approx(0.2 / np.sqrt(2),
                                                                                rel=0.15)
    # the same swing, clearly significant but below the sensors' accuracy and the meter's
    # class: structure, but not a model error worth a warning
    small = _adequacy_of(0.01 * rng.normal(size=n) + 0.04 * np.sin(t_h / 1.5),
                         white_w * 0.2 + 100 * np.sin(t_h / 1.5))
    assert small["groups"]["constrained"]["whiteness_p"] < 1e-6
    assert small["adequate"], small["statement"]


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
