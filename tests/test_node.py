"""The night-time ODE module: eq. 5/6 as written in the model, torchdiffeq against the exact
solution, agreement with the Annex C simulator, and gradients through the solver."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from impctl.fit.baselines import exact_linear
from impctl.fit.ode.node import ROW_AIR, ROW_DEMAND, NightODE, build_rows
from impctl.fit.ode.packing import pack_nights, smooth
from impctl.fit.ode.parameters import (
    DTYPE,
    PARAM_NAMES,
    PHYSICAL_BOUNDS,
    bounds_tensor,
    network,
    to_physical,
    to_unconstrained,
)
from impctl.fit.optim import lm as fit_lm
from impctl.imp.night import NightSamples
from impctl.model import HouseParameters, air_derivative, air_temperature, simulate

HOUSE = dict(floor_area=140.0, wall_height=2.7, walls_area=180.0, windows_area=28.0, c_f=2.2,
             u_walls=0.7, u_windows=1.6)
ACH = (0.0, 0.3)


def _params(**kw) -> torch.Tensor:
    values = {**HOUSE, **kw}
    return torch.tensor([[values[n] for n in PARAM_NAMES]], dtype=DTYPE)


def _night(kind, t_s, t_air, t_out, q) -> NightSamples:
    import pandas as pd

    return NightSamples("n", kind, pd.Timestamp("2026-01-10 22:00", tz="UTC"),
                        np.asarray(t_s, float), np.asarray(t_air, float),
                        np.asarray(t_out, float), np.asarray(q, float))


@pytest.mark.parametrize("method", ["rk4", "exact"])
def test_both_solvers_on_the_grid_match_the_exact_solution(method):
    rng = np.random.default_rng(3)
    grid = np.cumsum(np.r_[0.0, rng.uniform(200, 400, 40)])
    a = -1.0 / (30 * 3600.0)
    u0 = rng.normal(0, 2e-4, len(grid))
    u1 = rng.normal(0, 1e-7, len(grid))
    ode = NightODE(torch.tensor(grid, dtype=DTYPE), torch.tensor([a], dtype=DTYPE),
                   torch.tensor(u0[None], dtype=DTYPE), torch.tensor(u1[None], dtype=DTYPE),
                   method=method)
    got = ode.integrate(torch.tensor([21.0], dtype=DTYPE))[0].numpy()
    want = exact_linear(a, 21.0, grid, u0, u1)
    # rk4's local error ~ (aΔt)^5/120 and (Δt)^4 terms of the linear forcing: far below 1e-9 K;
    # the closed form is the same arithmetic as the scipy baseline's, to rounding
    assert np.max(np.abs(got - want)) < (1e-9 if method == "rk4" else 1e-11)
    # the lookup happens per step: without an announced step, forward() falls back correctly
    t = torch.tensor(grid[5] + 10.0, dtype=DTYPE)
    z = torch.tensor([20.0], dtype=DTYPE)
    assert float(ode(t, z)) == pytest.approx(a * 20.0 + u0[5] + u1[5] * 10.0, rel=1e-12)


def test_air_rows_are_the_papers_eq5_and_eq6():
    """The module's dz/dt with z = T_air − k_Φ·Φ equals air_derivative (eq. 5/6) at any state."""
    t = np.array([0.0, 600.0, 1200.0])
    t_out = np.array([2.0, 1.4, 1.1])
    night = _night("normal", t, [22.0, 22.0, 22.0], t_out, [3000.0, 2500.0, 2400.0])
    packed = pack_nights([night], [0.0])
    params = _params()
    phi = packed.q_w
    rows = build_rows(packed, params, torch.tensor([19.0], dtype=DTYPE), torch.tensor([0]),
                      torch.tensor([ROW_AIR]), phi, packed.q_in_w, *ACH)
    net = network(params, *ACH)
    k_phi = float(air_temperature(0.0, 0.0, 1.0, net))
    for k, dt in ((0, 100.0), (1, 350.0)):
        tt = torch.tensor(t[k] + dt, dtype=DTYPE)
        z = torch.tensor([20.3], dtype=DTYPE)
        got = float(rows.ode(tt, z))
        slope = (t_out[k + 1] - t_out[k]) / (t[k + 1] - t[k])
        t_e = t_out[k] + slope * dt
        want = float(air_derivative(20.3 + k_phi * float(phi[0, k]), t_e, slope,
                                    float(phi[0, k]), net))
        assert got == pytest.approx(want, rel=1e-10)
    # eq. 6: constrained rows see Φ_HC = 0, and z is then T_air itself
    assert float(rows.z0[0]) == pytest.approx(float(air_temperature(19.0, 2.0, 0.0, net)))


def _simulated(house: HouseParameters, setpoint: float | None, hours: float = 7.0):
    dt = 60.0
    n = int(hours * 3600 / dt)
    t_out = 1.0 + 2.0 * np.cos(np.arange(n) * dt / 3600.0 / 4.0)
    sp = np.full(n, np.nan if setpoint is None else setpoint)
    sim = simulate(house, t_out, dt, setpoint_c=sp, t_m_init_c=20.5)
    return dt, t_out, sim


def test_demand_and_air_rows_reproduce_the_annex_c_simulator():
    house = HouseParameters(**HOUSE, ach_vent=ACH[0], ach_infl=ACH[1])
    params = _params()
    # normal night: setpoint held, the model predicts the heat power from the held T_air
    dt, t_out, sim = _simulated(house, 22.0)
    idx = np.arange(0, len(t_out), 5)
    t_s = idx * dt
    night = _night("normal", t_s, sim.t_air_c[idx], t_out[idx],
                   [sim.phi_hc_w[i:i + 5].mean() for i in idx])
    packed = pack_nights([night], [0.0])
    rows = build_rows(packed, params, torch.tensor([20.5], dtype=DTYPE), torch.tensor([0]),
                      torch.tensor([ROW_DEMAND]), packed.q_w, packed.q_in_w, *ACH)
    pred = rows.predict()[0][rows.mask[0]].numpy()
    meas = rows.measured[0][rows.mask[0]].numpy()
    assert np.max(np.abs(pred / meas - 1)) < 2e-3   # Annex C's step vs the continuous form
    # constrained night: heating off, eq. 6 from the same initial mass temperature
    dt, t_out, sim = _simulated(house, None)
    night = _night("constrained", t_s, sim.t_air_c[idx], t_out[idx], np.zeros(len(idx)))
    packed = pack_nights([night], [0.0])
    rows = build_rows(packed, params, torch.tensor([20.5], dtype=DTYPE), torch.tensor([0]),
                      torch.tensor([ROW_AIR]), torch.zeros_like(packed.q_w),
                      torch.zeros_like(packed.q_w), *ACH)
    err = (rows.predict() - rows.measured)[rows.mask].numpy()
    assert np.max(np.abs(err)) < 5e-3


def test_pack_nights_puts_each_night_on_its_own_samples():
    a = _night("constrained", [0, 300, 600, 900], [20, 19.9, 19.8, 19.7], [1, 1, 1, 1],
               [0, 0, 0, 0])
    b = _night("normal", [0, 600, 1200], [22, 22, 22], [0, 0.5, 1.0], [1000, 2000, 3000])
    packed = pack_nights([a, b], [0.0, 0.0])
    # the shorter night is padded with its last sample: zero-length intervals
    assert packed.grid_s.tolist() == [[0, 300, 600, 900], [0, 600, 1200, 1200]]
    assert packed.mask.tolist() == [[1, 1, 1, 1], [1, 1, 1, 0]]
    # power holds until the next sample; T_out slopes are the night's own
    assert packed.q_w[1].tolist() == [1000, 2000, 3000, 3000]
    assert packed.t_out_slope[1, 0] == pytest.approx(0.5 / 600)
    assert packed.t_out_slope[1, 2] == 0.0
    assert packed.next_node[1, 0] == 1 and packed.next_node[1, 2] == 2 and bool(packed.last[1, 2])
    # mean power weighs each sample by its interval (the last one covers nothing)
    assert float(packed.q_mean_w[1]) == pytest.approx(1500.0)
    # "interval" stamps: nodes move to the interval middles, power on a node-to-node
    # interval is the mean of the two samples it straddles
    mid = pack_nights([b], [0.0], timestamps="interval")
    assert mid.grid_s.tolist() == [[300, 900, 1500]]
    assert mid.q_in_w[0].tolist() == [1500, 2500, 3000]


@pytest.mark.parametrize("method", ["rk4", "exact"])
def test_padding_and_sub_steps_do_not_change_the_solution(method):
    """A padded row equals the same row alone; a fast mode gets rk4 sub-steps and stays exact
    (the closed form needs none)."""
    rng = np.random.default_rng(5)
    grid = np.cumsum(np.r_[0.0, rng.uniform(200, 400, 30)])
    u0 = rng.normal(0, 2e-3, len(grid))
    u1 = rng.normal(0, 1e-6, len(grid))
    for a in (-1.0 / (30 * 3600.0), -1.0 / 180.0, -1e-11):   # mass, fast air node, ~constant
        padded = np.r_[grid, [grid[-1]] * 5]
        ode = NightODE(torch.tensor(np.stack([padded, padded]), dtype=DTYPE),
                       torch.tensor([a, a], dtype=DTYPE),
                       torch.tensor(np.stack([np.r_[u0, [0.0] * 5]] * 2), dtype=DTYPE),
                       torch.tensor(np.stack([np.r_[u1, [0.0] * 5]] * 2), dtype=DTYPE),
                       method=method)
        got = ode.integrate(torch.tensor([21.0, 21.0], dtype=DTYPE)).numpy()
        want = exact_linear(a, 21.0, grid, u0, u1)
        # a 21 K jump relaxing in one interval: the sub-steps keep it to micro-kelvins
        assert np.max(np.abs(got[0, :len(grid)] - want)) < (2e-5 if method == "rk4" else 1e-11)
        assert np.all(got[0, len(grid):] == got[0, len(grid) - 1])
        if a < -1e-3 and method == "rk4":
            assert ode.n_sub > 1


def test_smoothing_removes_quantisation_flicker_but_keeps_the_level():
    t = np.arange(0, 7 * 3600, 300.0)
    y = np.where(np.arange(len(t)) % 7 == 3, 22.1, 22.0)
    s = smooth(t, y, 3600.0)
    assert np.ptp(s) < np.ptp(y) / 2
    assert abs(s.mean() - y.mean()) < 0.01


def test_sigmoid_map_round_trips_inside_the_bounds():
    b = bounds_tensor(PHYSICAL_BOUNDS)
    x = torch.tensor([[150.0, 2.7, 200.0, 30.0, 1.65, 0.6, 1.4]], dtype=DTYPE)
    assert torch.allclose(to_physical(to_unconstrained(x, b), b), x, rtol=1e-9)
    far = to_physical(torch.full((1, 7), 50.0, dtype=DTYPE), b)
    assert torch.all(far <= b[:, 1]) and torch.all(far >= b[:, 0])


def test_backprop_through_the_solver_gives_the_jacobian_gradient():
    """Direct backprop (no adjoint) and the batched finite-difference Jacobian agree."""
    t = np.arange(0, 4 * 3600 + 1, 900.0)
    cons = _night("constrained", t, 21 - 0.4 * t / 3600, np.full(len(t), 2.0),
                  np.zeros(len(t)))
    norm = _night("normal", t, np.full(len(t), 22.0), 1 + 0.2 * t / 3600,
                  3000 - 50 * t / 3600)
    norm = dataclasses.replace(norm, night_id="m")
    packed = pack_nights([cons, norm], [0.0, 0.0])
    ctx = fit_lm.Context(packed, *ACH)
    rows = fit_lm.Rows(torch.tensor([0, 0]), torch.tensor([0, 1]),
                       torch.tensor([ROW_AIR, ROW_DEMAND]), torch.zeros(2, len(t), dtype=DTYPE),
                       torch.zeros(2, len(t), dtype=DTYPE),
                       torch.tensor([1 / 0.05, 1 / 100.0], dtype=DTYPE),
                       bounds_tensor(PHYSICAL_BOUNDS)[None], 1)
    u = torch.tensor([[0.3, -0.2, 0.1, 0.5, -0.4, 0.2, 0.0]], dtype=DTYPE)
    m = torch.tensor([19.0, 21.0], dtype=DTYPE)
    loss, gu, gm = fit_lm.loss_gradient(ctx, rows, u, m)
    ne = fit_lm._normal_equations(ctx, rows, u, m)
    assert float(ne.loss[0]) == pytest.approx(float(loss), rel=1e-12)
    # ∂loss/∂u = 2·Jᵀr (+ 2·ridge·u), the Jacobian by forward differences in the same batch
    assert torch.allclose(gu[0], 2 * ne.g[0], rtol=1e-4, atol=1e-6 * float(gu.abs().max()))
    assert torch.allclose(gm, 2 * ne.gm, rtol=1e-4)


def test_emitter_lag_gives_the_metered_power_of_a_house_with_a_screed():
    """A held night of a house whose emitter holds 40 % of C_m (a screed, H_e = 800 W/K),
    simulated here step by step from the 5R1C mass equation and the emitter's own balance:
    with ``emitter_lag`` the DEMAND rows give the heat the meter sees (into the screed, not
    into the room), without it they miss the screed's charging."""
    from impctl.model.continuous import mass_derivative

    share, h_e = 0.4, 800.0
    params = _params()
    net = network(params, *ACH)
    c_m = float(net.c_m_j_per_k[0])
    net_m = dataclasses.replace(net, c_m_j_per_k=net.c_m_j_per_k * (1.0 - share))
    tau_e_s = share * c_m / h_e
    dt, hours, t_out = 10.0, 8.0, 0.0
    t = np.arange(0.0, hours * 3600.0 + dt, dt)
    t_air = 21.0 + 2.0 * np.minimum(t / 7200.0, 1.0)          # a setpoint step, then held
    t_m = torch.tensor([18.0], dtype=DTYPE)
    phi = np.zeros(len(t))
    for k in range(len(t)):
        free = air_temperature(t_m, t_out, 0.0, net_m)
        k_phi = air_temperature(t_m, t_out, 1.0, net_m) - free
        phi[k] = float((t_air[k] - free) / k_phi)
        t_m = t_m + dt * mass_derivative(t_m, t_out, phi[k], net_m)
    t_e = t_air + phi / h_e                                    # the screed's temperature
    meter = phi[:-1] + share * c_m * np.diff(t_e) / dt         # heat into the screed
    step = 30                                                  # 5-minute meter means
    idx = np.arange(0, len(t) - 1, step)
    q = np.array([meter[i:i + step].mean() for i in idx])
    night = _night("normal", t[idx], t_air[idx], np.full(len(idx), t_out), q)
    row = torch.cat([params, torch.tensor([[0.0, 0.0, tau_e_s / 3600.0, 0.0, share]],
                                          dtype=DTYPE)], dim=1)

    def predicted(lag: bool) -> np.ndarray:
        packed = pack_nights([night], [0.0])
        packed.emitter_lag = lag
        rows = build_rows(packed, row if lag else params, torch.tensor([18.0], dtype=DTYPE),
                          torch.tensor([0]), torch.tensor([ROW_DEMAND]), packed.q_w,
                          packed.q_in_w, *ACH)
        return rows.predict()[0][rows.mask[0]].numpy()

    meas = q[:-1]
    with_lag, without = predicted(True), predicted(False)
    assert np.max(np.abs(with_lag - meas)) < 0.02 * np.max(meas)
    assert np.max(np.abs(without - meas)) > 0.2 * np.max(meas)
