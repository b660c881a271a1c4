"""The 5R1C model: derived quantities by hand, Table 12, Annex C against the scalar oracle,
the demand method, the continuous-time form."""

from __future__ import annotations

import math

import numpy as np
import oracle_5r1c as oracle
import pytest

from impctl.errors import InputError
from impctl.model import (
    HouseParameters,
    air_derivative,
    air_temperature,
    am_factor,
    mass_derivative,
    mass_from_air,
    simulate,
)

# The worked house: 100 m², h 2.5 m, walls 120 m² at 0.5, windows 20 m² at 1.5,
# c_f 1.65 (medium), ach 0.3 + 0.2.
HOUSE = dict(floor_area=100.0, wall_height=2.5, walls_area=120.0, windows_area=20.0, c_f=1.65,
             u_walls=0.5, u_windows=1.5, ach_vent=0.3, ach_infl=0.2)


def test_derived_quantities_worked_by_hand():
    net = HouseParameters(**HOUSE).network
    # A_t = 4.5·100 = 450 m²; H_tr,is = 3.45·450 = 1552.5 W/K.
    assert net.a_t_m2 == pytest.approx(450.0)
    assert net.h_tr_is == pytest.approx(1552.5)
    # c_f = 1.65 → medium → A_m = 2.5·100 = 250 m²; H_tr,ms = 9.1·250 = 2275 W/K.
    assert net.a_m_m2 == pytest.approx(250.0)
    assert net.h_tr_ms == pytest.approx(2275.0)
    # H_tr,op = 0.5·120 = 60; H_tr,em = 1/(1/60 − 1/2275) = 136500/2215 = 61.6253 W/K.
    assert net.h_tr_op == pytest.approx(60.0)
    assert net.h_tr_em == pytest.approx(136500.0 / 2215.0, rel=1e-12)
    # H_tr,w = 1.5·20 = 30 W/K.
    assert net.h_tr_w == pytest.approx(30.0)
    # V = 250 m³; H_ve = 1200·250·0.5/3600 = 41.6667 W/K.
    assert net.h_ve == pytest.approx(125.0 / 3.0, rel=1e-12)
    # C_m = 1.65e5·100 = 1.65e7 J/K.
    assert net.c_m_j_per_k == pytest.approx(1.65e7)
    # H_tr,1 = 1/(1/41.6667 + 1/1552.5) = 40.5776; H_tr,2 = 70.5776; H_tr,3 = 68.4540 (C.6–C.8).
    h1 = 1.0 / (3.0 / 125.0 + 1.0 / 1552.5)
    assert net.h_tr_1 == pytest.approx(h1, rel=1e-12)
    assert net.h_tr_1 == pytest.approx(40.5776, abs=1e-4)
    assert net.h_tr_2 == pytest.approx(h1 + 30.0, rel=1e-12)
    h3 = 1.0 / (1.0 / (h1 + 30.0) + 1.0 / 2275.0)
    assert net.h_tr_3 == pytest.approx(h3, rel=1e-12)
    assert net.h_tr_3 == pytest.approx(68.4540, abs=1e-4)


def test_lumped_quantities_worked_by_hand():
    house = HouseParameters(**HOUSE)
    # HLC = H_ve + 1/(1/H_tr,is + 1/(H_tr,w + H_tr,op)) = 41.6667 + 1/(1/1552.5 + 1/90) = 126.735
    hlc = 125.0 / 3.0 + 1.0 / (1.0 / 1552.5 + 1.0 / 90.0)
    assert house.hlc_w_per_k == pytest.approx(hlc, rel=1e-12)
    assert house.hlc_w_per_k == pytest.approx(126.7352, abs=1e-4)
    assert house.c_m_j_per_k == pytest.approx(1.65e7)
    # τ = C_m/(H_tr,em + H_tr,3)/3600 = 1.65e7/(61.6253 + 68.4540)/3600 = 35.235 h
    assert house.tau_h == pytest.approx(1.65e7 / (136500 / 2215 + 68.45397) / 3600, rel=1e-6)
    assert house.tau_h == pytest.approx(35.235, abs=1e-3)


def test_reference_document_hlc_example():
    # iso13790-5r1c.md: 150 m² medium house, H_tr,op 120, H_tr,w 42, H_ve 62 W/K → HLC 213.5 W/K.
    h_is = 3.45 * 4.5 * 150
    hlc = 62 + 1 / (1 / h_is + 1 / (120 + 42))
    assert hlc == pytest.approx(213.5, abs=0.05)
    house = HouseParameters(floor_area=150, wall_height=2.5, walls_area=240, windows_area=28,
                            c_f=1.65, u_walls=0.5, u_windows=1.5, ach_vent=0,
                            ach_infl=62 * 3600 / 1200 / 375)
    assert house.hlc_w_per_k == pytest.approx(hlc, rel=1e-9)


@pytest.mark.parametrize(
    "c_f, factor",
    [(0.5, 2.5), (0.8, 2.5), (1.0, 2.5), (1.1, 2.5), (1.65, 2.5), (2.125, 2.75), (2.6, 3.0),
     (3.15, 3.25), (3.7, 3.5), (5.0, 3.5)],
)
def test_table12_am_factor_interpolation(c_f, factor):
    assert am_factor(c_f) == pytest.approx(factor, abs=1e-12)
    assert am_factor(np.array([c_f]))[0] == pytest.approx(factor, abs=1e-12)


def test_am_factor_is_piecewise_linear_and_monotone():
    x = np.linspace(0.5, 5.0, 2001)
    y = am_factor(x)
    assert np.all(np.diff(y) >= -1e-15)
    assert np.allclose(y, np.interp(x, [0.8, 1.1, 1.65, 2.6, 3.7], [2.5, 2.5, 2.5, 3.0, 3.5]))


def _random_houses(rng, n):
    a_f = rng.uniform(50, 300, n)
    return dict(
        floor_area=a_f, wall_height=rng.uniform(2.3, 3.2, n),
        walls_area=a_f * rng.uniform(0.6, 1.8, n),
        windows_area=a_f * rng.uniform(0.08, 0.25, n), c_f=rng.uniform(0.6, 4.5, n),
        u_walls=rng.uniform(0.15, 2.0, n), u_windows=rng.uniform(0.7, 3.0, n),
        ach_vent=rng.uniform(0, 1.0, n), ach_infl=rng.uniform(0.01, 0.6, n),
        heat_recovery=rng.uniform(0, 0.8, n), max_heating_power=rng.uniform(3000, 15000, n),
    )


@pytest.mark.parametrize("dt_s", [3600.0, 900.0, 60.0])
def test_vectorised_model_matches_scalar_oracle(dt_s):
    rng = np.random.default_rng(int(dt_s))
    n_h, n_t = 25, 60
    params = _random_houses(rng, n_h)
    houses = HouseParameters(**params)
    t_out = rng.uniform(-15, 12, (n_t, n_h))
    sp = rng.uniform(18, 24, (n_t, n_h))
    sp[rng.random((n_t, n_h)) < 0.25] = np.nan  # heating off
    forced = np.full((n_t, n_h), np.nan)
    mask = rng.random((n_t, n_h)) < 0.15
    forced[mask] = rng.uniform(0, 8000, mask.sum())
    gains_i = rng.uniform(0, 600, (n_t, n_h))
    gains_s = rng.uniform(0, 1500, (n_t, n_h))
    t_m0 = rng.uniform(15, 23, n_h)
    sim = simulate(houses, t_out, dt_s, setpoint_c=sp, phi_hc_w=forced, internal_gains_w=gains_i,
                   solar_gains_w=gains_s, t_m_init_c=t_m0)
    capped = 0
    for j in range(n_h):
        p = {k: float(v[j]) for k, v in params.items()}
        rows = oracle.run(
            p, t_out[:, j],
            [None if math.isnan(x) else x for x in sp[:, j]],
            [None if math.isnan(x) else x for x in forced[:, j]],
            gains_i[:, j], gains_s[:, j], dt_s, t_m0[j],
        )
        ref = np.array(rows)
        np.testing.assert_allclose(sim.t_air_c[:, j], ref[:, 0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(sim.t_s_c[:, j], ref[:, 1], rtol=0, atol=1e-9)
        np.testing.assert_allclose(sim.t_m_c[:, j], ref[:, 2], rtol=0, atol=1e-9)
        np.testing.assert_allclose(sim.phi_hc_w[:, j], ref[:, 3], rtol=1e-12, atol=1e-6)
        capped += int(np.sum(np.isclose(ref[:, 3], p["max_heating_power"])))
    assert capped > 0, "the random inputs should exercise the power cap"


def test_setpoint_is_met_exactly_when_power_suffices():
    house = HouseParameters(**HOUSE)
    sim = simulate(house, np.full(48, -5.0), 3600, setpoint_c=np.full(48, 21.0), t_m_init_c=18.0)
    np.testing.assert_allclose(sim.t_air_c, 21.0, atol=1e-9)
    assert np.all(sim.phi_hc_w > 0)
    # Steady state after the mass has charged: power → HLC·ΔT.
    long = simulate(house, np.full(24 * 40, -5.0), 3600, setpoint_c=21.0, t_m_init_c=21.0)
    assert long.phi_hc_w[-1] == pytest.approx(house.hlc_w_per_k * 26.0, rel=1e-3)


def test_power_cap_limits_heating_and_temperature_falls_short():
    house = HouseParameters(**HOUSE, max_heating_power=1500.0)
    sim = simulate(house, np.full(24, -10.0), 3600, setpoint_c=21.0, t_m_init_c=21.0)
    assert np.all(sim.phi_hc_w <= 1500.0 + 1e-9)
    assert sim.phi_hc_w[-1] == pytest.approx(1500.0)
    assert sim.t_air_c[-1] < 21.0 - 0.1


def test_free_floating_step_needs_no_heating():
    house = HouseParameters(**HOUSE)
    # Mass at 25 °C with a 21 °C setpoint and mild weather: the first step floats above 21.
    sim = simulate(house, np.full(3, 15.0), 3600, setpoint_c=21.0, t_m_init_c=25.0)
    assert sim.phi_hc_w[0] == 0.0
    assert sim.t_air_c[0] > 21.0


def test_heating_off_cools_towards_outside():
    house = HouseParameters(**HOUSE)
    sim = simulate(house, np.full(72, 0.0), 3600, setpoint_c=np.full(72, np.nan), t_m_init_c=21.0)
    assert np.all(sim.phi_hc_w == 0.0)
    assert np.all(np.diff(sim.t_m_c) < 0)
    assert 0.0 < sim.t_air_c[-1] < sim.t_air_c[0] < 21.0


def test_forced_power_overrides_setpoint():
    house = HouseParameters(**HOUSE)
    # The demand at 0 °C outside is 1.3–1.8 kW here: 800 W falls short, 4 kW overshoots.
    forced = np.array([np.nan, 800.0, np.nan, 4000.0])
    sim = simulate(house, np.full(4, 0.0), 3600, setpoint_c=21.0, phi_hc_w=forced,
                   t_m_init_c=21.0)
    assert sim.phi_hc_w[1] == 800.0 and sim.phi_hc_w[3] == 4000.0
    assert sim.t_air_c[0] == pytest.approx(21.0) and sim.t_air_c[2] == pytest.approx(21.0)
    assert sim.t_air_c[1] < 21.0 < sim.t_air_c[3]


def test_single_house_returns_1d_and_many_houses_2d():
    one = simulate(HouseParameters(**HOUSE), np.zeros(5), 3600, setpoint_c=20.0)
    assert one.t_air_c.shape == (5,)
    many = HouseParameters.stack([HouseParameters(**HOUSE)] * 3)
    sim = simulate(many, np.zeros(5), 3600, setpoint_c=20.0)
    assert sim.t_air_c.shape == (5, 3)
    np.testing.assert_allclose(sim.t_air_c[:, 2], one.t_air_c)


def test_zero_ventilation_limit_is_finite():
    # ach = 0 is refused in house files, but the network itself stays finite as H_ve → 0.
    p = dict(HOUSE, ach_vent=0.0, ach_infl=1e-12)
    sim = simulate(HouseParameters(**p), np.zeros(4), 3600, setpoint_c=20.0,
                   internal_gains_w=300.0)
    assert np.all(np.isfinite(sim.t_air_c)) and np.all(np.isfinite(sim.phi_hc_w))


@pytest.mark.parametrize(
    "change, key",
    [
        (dict(floor_area=0.0), "floor_area"),
        (dict(walls_area=-1.0), "walls_area"),
        (dict(windows_area=0.0), "windows_area"),
        (dict(c_f=0.4), "c_f"),
        (dict(c_f=5.1), "c_f"),
        (dict(ach_vent=0.0, ach_infl=0.0), "ach_infl"),
        (dict(heat_recovery=1.5), "heat_recovery"),
        (dict(max_heating_power=0.0), "max_heating_power"),
        (dict(u_walls=40.0), "u_walls"),
    ],
)
def test_invalid_parameters_name_the_key(change, key):
    with pytest.raises(InputError, match=f"key '{key}'"):
        HouseParameters(**{**HOUSE, **change})


# --- continuous-time form -------------------------------------------------------------------


def test_air_and_mass_forms_are_inverse():
    net = HouseParameters(**HOUSE).network
    for phi in (0.0, 3500.0):
        t_air = air_temperature(19.3, -4.0, phi, net)
        assert mass_from_air(t_air, -4.0, phi, net) == pytest.approx(19.3, abs=1e-12)


def test_air_derivative_matches_chain_rule_of_mass_derivative():
    net = HouseParameters(**HOUSE).network
    t_m, t_e, phi, dte = 20.0, -3.0, 2500.0, -1.0 / 3600
    t_air = air_temperature(t_m, t_e, phi, net)
    h = 1.0
    # Numerical d/dt of θ_air(θ_m(t), θ_e(t)) with θ_m following the ODE.
    dm = mass_derivative(t_m, t_e, phi, net)
    numeric = (air_temperature(t_m + dm * h, t_e + dte * h, phi, net) - t_air) / h
    assert air_derivative(t_air, t_e, dte, phi, net) == pytest.approx(numeric, rel=1e-9)


def _rk4_mass(net, t_m0, t_out, phi, dt_outer, n_sub):
    """Integrate dθ_m/dt with RK4 at dt_outer/n_sub, inputs constant per outer step."""
    t_m = t_m0
    h = dt_outer / n_sub
    out = []
    for te, ph in zip(t_out, phi, strict=True):
        for _ in range(n_sub):
            k1 = mass_derivative(t_m, te, ph, net)
            k2 = mass_derivative(t_m + 0.5 * h * k1, te, ph, net)
            k3 = mass_derivative(t_m + 0.5 * h * k2, te, ph, net)
            k4 = mass_derivative(t_m + h * k3, te, ph, net)
            t_m = t_m + h * (k1 + 2 * k2 + 2 * k3 + k4) / 6
        out.append(t_m)
    return np.array(out)


def test_annex_c_converges_to_the_continuous_form_at_second_order():
    """Annex C (Crank–Nicolson) stepped at Δt/k approaches the fine RK4 solution of
    dθ_m/dt as k grows; the error falls ~4× per halving (order 2). Tolerance: at Δt = 225 s
    the end-of-hour θ_m agrees to 1e-5 K."""
    house = HouseParameters(**dict(HOUSE, c_f=0.8))  # light house: larger Δt/τ, clearer errors
    net = house.network
    rng = np.random.default_rng(3)
    hours = 24
    t_out = rng.uniform(-10, 5, hours)
    phi = np.where(rng.random(hours) < 0.5, 0.0, rng.uniform(1000, 6000, hours))
    ref = _rk4_mass(net, 20.0, t_out, phi, 3600.0, 240)
    errors = []
    for k in (1, 2, 4, 8, 16):
        sim = simulate(house, np.repeat(t_out, k), 3600.0 / k, phi_hc_w=np.repeat(phi, k),
                       t_m_init_c=20.0)
        errors.append(np.max(np.abs(sim.t_m_c[k - 1 :: k] - ref)))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all(ratios > 3.5) and np.all(ratios < 4.5), (errors, ratios)
    assert errors[-1] < 1e-5
