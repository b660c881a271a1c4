"""The coast: a fitted house switched off from steady state, simulated exactly.

The 5R1C mass node θ_m, plus what the fit found beyond the 5R1C (:mod:`.switch_off`): a
furniture node T_fur (capacity C_fur at the air node, coupled with the fit's time constant
:data:`FURNITURE_TAU_S`), a constant night gain, and the emitter's release E(t) after
switch-off. The system is linear with constant coefficients, so it is stepped exactly:
z' = A·z with z = (θ_m, T_fur, 1, E) and z(t + Δt) = exp(A·Δt)·z(t). The air node is
massless (ISO 13790): T_air = w·z.

Temperatures °C, powers W, time s unless named _h. numpy only.
"""

from __future__ import annotations

import numpy as np

from ..model import HouseParameters, air_temperature, mass_derivative, mass_from_air, simulate

#: Furniture–air time constant [s]: the fit's (:data:`impctl.fit.ode.parameters.FURNITURE_TAU_S`,
#: real-houses.md §1); repeated here so that this module needs no torch.
FURNITURE_TAU_S = 1.0 / 0.00022


def _expm(m: np.ndarray) -> np.ndarray:
    """exp of a batch of small matrices (…, k, k): scaling and squaring of a Taylor series."""
    norm = float(np.abs(m).sum(axis=-1).max()) if m.size else 0.0
    s = max(0, int(np.ceil(np.log2(max(norm, 1e-300) / 0.25))))
    a = m / 2.0 ** s
    out = term = np.broadcast_to(np.eye(m.shape[-1]), m.shape).copy()
    for j in range(1, 12):
        term = term @ a / j
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


def _switch_off_system(net, t_out_c: float, gain_w, c_fur_j_per_k, tau_em_s):
    """The coast as a linear system z' = A·z, z = (θ_m, T_fur, 1, E): the 5R1C mass, the
    furniture node (heat C_fur·dT_fur/dt taken from the air node, time constant
    :data:`FURNITURE_TAU_S`, as in the fit), the constant gain and the emitter's release E
    [W] decaying with τ_em. The massless air node is algebraic: T_air = w·z. Returns (A, w),
    (n, 4, 4) and (n, 4)."""
    n = len(gain_w)
    g_fur = c_fur_j_per_k / FURNITURE_TAU_S
    # air_temperature and mass_derivative are affine: their coefficients from unit inputs
    p = air_temperature(1.0, 0.0, 0.0, net) - air_temperature(0.0, 0.0, 0.0, net)
    k = air_temperature(0.0, 0.0, 1.0, net) - air_temperature(0.0, 0.0, 0.0, net)
    r = air_temperature(0.0, t_out_c, 0.0, net) - air_temperature(0.0, 0.0, 0.0, net)
    q_m = mass_derivative(1.0, 0.0, 0.0, net) - mass_derivative(0.0, 0.0, 0.0, net)
    q_phi = mass_derivative(0.0, 0.0, 1.0, net) - mass_derivative(0.0, 0.0, 0.0, net)
    q_e = mass_derivative(0.0, t_out_c, 0.0, net) - mass_derivative(0.0, 0.0, 0.0, net)
    p, k, r, q_m, q_phi, q_e = (np.broadcast_to(np.asarray(x, float), (n,))
                                for x in (p, k, r, q_m, q_phi, q_e))
    den = 1.0 + k * g_fur
    zero = np.zeros(n)
    # T_air = (p·θ_m + k·g_fur·T_fur + (r + k·gain)·1 + k·E) / (1 + k·g_fur)
    w = np.stack([p, k * g_fur, r + k * gain_w, k], axis=-1) / den[:, None]
    # heat into the air node from the rest: gain + E − g_fur·(T_air − T_fur)
    unit_fur = np.stack([zero, np.ones(n), zero, zero], axis=-1)
    phi = np.stack([zero, zero, gain_w, np.ones(n)], axis=-1) - g_fur[:, None] * (w - unit_fur)
    a = np.zeros((n, 4, 4))
    a[:, 0] = q_phi[:, None] * phi
    a[:, 0, 0] += q_m
    a[:, 0, 2] += q_e
    a[:, 1] = (w - unit_fur) / FURNITURE_TAU_S
    a[:, 3, 3] = -1.0 / tau_em_s
    return a, w


def simulate_coast(houses: HouseParameters, terms: dict[str, np.ndarray], t_set_c: float,
                   t_out_c: float, drop_k: float, rebound_h: float, step_s: float,
                   horizon_h: float):
    """Arrays (n,) of coast [h], rebound [kWh], switch-off jump [K], Φ_ss [W].

    ``terms``: (n,) arrays of the switch-off terms (:data:`.switch_off.SWITCH_OFF_TERMS`,
    NaN = not fitted). Steady state at ``t_set_c``: the heating supplies HLC·ΔT minus the gain;
    with an emitter release the emitter's output is continuous at switch-off (it still delivers
    that heat) and fades with τ_em. The coast ends when T_air has fallen ``drop_k`` below
    T_set — or, without any switch-off term, below the pure 5R1C's T_air just after its
    instantaneous switch-off jump (the jump is not counted). The rebound: Annex C demand with
    the heating back on at T_set from θ_m at the coast's end, its heat beyond Φ_ss over
    ``rebound_h`` [kWh]. A coast longer than ``horizon_h`` is NaN."""
    net = houses.network
    n = houses.n_houses or 1
    hlc = np.broadcast_to(np.asarray(net.hlc_w_per_k, float), (n,))
    phi_ss = hlc * (t_set_c - t_out_c)
    gain = np.nan_to_num(terms["night_gain_w"])
    has_em = np.isfinite(terms["emitter_tau_h"])
    c_fur = np.nan_to_num(terms["furniture_j_per_m2k"]) * np.broadcast_to(
        np.asarray(houses.floor_area, float), (n,))
    dynamic = has_em | (c_fur > 0)
    t_m = np.broadcast_to(np.asarray(mass_from_air(t_set_c, t_out_c, phi_ss, net), float),
                          (n,)).copy()
    # the heating supplies what the gain does not; at switch-off the emitter's output is
    # continuous (it still delivers that heat) and fades with τ_em
    heat = np.clip(phi_ss - gain, 0.0, None)
    tau_em_s = np.where(has_em, np.nan_to_num(terms["emitter_tau_h"]) * 3600.0, np.inf)
    a, w = _switch_off_system(net, t_out_c, gain, c_fur, np.maximum(tau_em_s, 60.0))
    z = np.stack([t_m, np.full(n, t_set_c), np.ones(n), np.where(has_em, heat, 0.0)], axis=-1)
    step = _expm(a * step_s)
    air0 = np.einsum("nk,nk->n", w, z)
    # without any switch-off term the model's T_air jumps at once (massless air node): that
    # jump is not counted (identifiability.md §11.2); with them T_air starts from T_set
    ref = np.where(dynamic, t_set_c, air0)
    target = ref - drop_k
    coast = np.full(n, np.nan)
    t_m_at = np.full(n, np.nan)
    prev_air, prev_m = air0, t_m
    for i in range(1, int(horizon_h * 3600 / step_s) + 1):
        z = np.einsum("nij,nj->ni", step, z)
        air = np.einsum("nk,nk->n", w, z)
        hit = np.isnan(coast) & (air <= target)
        if hit.any():
            frac = np.where(prev_air > air, (prev_air - target) / np.where(
                prev_air > air, prev_air - air, 1.0), 1.0)[hit]
            coast[hit] = (i - 1 + frac) * step_s / 3600.0
            t_m_at[hit] = prev_m[hit] + frac * (z[hit, 0] - prev_m[hit])
            if not np.isnan(coast).any():
                break
        prev_air, prev_m = air, z[:, 0]
    rebound = np.full(n, np.nan)
    ok = np.isfinite(t_m_at)
    if ok.any():
        steps = int(round(rebound_h * 3600 / step_s))
        sim = simulate(houses, np.full((steps, n), t_out_c), step_s,
                       setpoint_c=np.full((steps, n), t_set_c),
                       t_m_init_c=np.where(ok, t_m_at, t_m))
        phi = np.atleast_2d(sim.phi_hc_w.T).T
        extra = (phi - phi_ss).sum(axis=0) * step_s / 3.6e6
        rebound = np.where(ok, extra, np.nan)
    return coast, rebound, t_set_c - air0, phi_ss
