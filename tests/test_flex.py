"""Flexibility (impctl.flex): coast time against the closed-form decay of the continuous 5R1C,
the rebound's energy balance, intervals, and bad conditions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from impctl.errors import InputError
from impctl.flex import BLOCK_KEYS, flexibility_many, flexibility_of_fit
from impctl.model import HouseParameters, air_temperature, load_house, mass_from_air

HOUSES = HouseParameters(
    floor_area=np.array([90.0, 150.0, 240.0]), wall_height=np.array([2.5, 2.6, 2.8]),
    walls_area=np.array([120.0, 200.0, 260.0]), windows_area=np.array([15.0, 30.0, 45.0]),
    c_f=np.array([0.9, 1.65, 3.0]), u_walls=np.array([0.3, 0.6, 1.1]),
    u_windows=np.array([1.0, 1.4, 2.5]), ach_vent=np.zeros(3), ach_infl=np.full(3, 0.01))


def closed_form_coast_h(house: HouseParameters, i: int, t_set: float, t_out: float,
                        drop: float) -> float:
    """Heating off, T_out held: θ_m relaxes with τ exactly, and T_air (Φ = 0) is affine in
    θ_m, so T_air − T_out decays with τ from its value just after switch-off."""
    h = house.take(i)
    net = h.network
    phi = float(net.hlc_w_per_k) * (t_set - t_out)
    t_m = float(mass_from_air(t_set, t_out, phi, net))
    start = float(air_temperature(t_m, t_out, 0.0, net)) - t_out
    return -float(net.tau_h) * math.log(1.0 - drop / start)


def test_coast_matches_the_closed_form_decay():
    flex = flexibility_many(HOUSES, t_set_c=21.0, t_out_c=0.0, drop_k=1.0, step_s=120.0)
    for i, f in enumerate(flex):
        expected = closed_form_coast_h(HOUSES, i, 21.0, 0.0, 1.0)
        assert f.coast_h == pytest.approx(expected, rel=2e-3)
        assert f.coast_h_low == f.coast_h == f.coast_h_high  # no τ interval given
    # a heavier, better insulated house coasts longer; a colder night shortens the coast
    assert flex[2].coast_h > flex[0].coast_h
    colder = flexibility_many(HOUSES, t_out_c=-10.0)
    assert all(c.coast_h < f.coast_h for c, f in zip(colder, flex, strict=True))


def test_switch_off_jump_is_reported_not_counted():
    demo = load_house(__import__("impctl").__path__[0] + "/data/demo_house.toml")
    f = flexibility_many(demo)[0]
    # the massless air node drops ~1.2 K at once; counting it would end the coast at t = 0
    assert 0.8 < f.switch_off_drop_k < 2.0
    assert 4.0 < f.coast_h < 10.0
    assert f.steady_state_w == pytest.approx(float(demo.hlc_w_per_k) * 21.0)


def test_rebound_is_the_mass_deficit_order_of_magnitude():
    f = flexibility_many(HOUSES)
    for i, x in enumerate(f):
        h = HOUSES.take(i)
        # the mass lost C_m·Δθ_m during the coast; 2 h of reheating refill part of it, plus
        # the air-node jump; the rebound is positive and below the whole stored-heat deficit
        # plus the extra losses of 2 h at a warmer air node
        assert x.rebound_kwh > 0
        ceiling = float(h.c_m_j_per_k) * (x.drop_k + x.switch_off_drop_k) / 3.6e6
        assert x.rebound_kwh < ceiling
    longer = flexibility_many(HOUSES, rebound_h=4.0)
    assert all(b.rebound_kwh > a.rebound_kwh for a, b in zip(f, longer, strict=True))


def test_coast_interval_follows_tau_interval():
    tau = np.asarray(HOUSES.tau_h, float)
    f = flexibility_many(HOUSES, tau * 0.9, tau * 1.1)
    for x in f:
        assert x.coast_h_low < x.coast_h < x.coast_h_high
        # coast ∝ τ for a fixed start: ±10 % in τ gives about ±10 % in coast
        assert x.coast_h_low / x.coast_h == pytest.approx(0.9, abs=0.02)
        assert x.coast_h_high / x.coast_h == pytest.approx(1.1, abs=0.02)


def test_from_fit_summary_and_block_keys():
    h = HOUSES.take(1)
    summary = {"parameters": {k: float(v) for k, v in h.as_dict().items()
                              if k not in ("ach_vent", "ach_infl", "heat_recovery",
                                           "max_heating_power")},
               "fixed": {"ach_vent": 0.0, "ach_infl": 0.01},
               "lumped": {"tau": {"value": float(h.tau_h), "low": 0.95 * float(h.tau_h),
                                  "high": 1.05 * float(h.tau_h)}}}
    block = flexibility_of_fit(summary).block()
    assert set(BLOCK_KEYS) <= set(block)
    assert block["coast_h_low"] < block["coast_h"] < block["coast_h_high"]
    with pytest.raises(InputError, match="not an impctl fit"):
        flexibility_of_fit({"lumped": {}})


@pytest.mark.parametrize("kw", [{"t_out_c": 20.5}, {"drop_k": 0.0}, {"drop_k": -1.0}])
def test_bad_conditions_are_refused(kw):
    with pytest.raises(InputError):
        flexibility_many(HOUSES, **kw)
