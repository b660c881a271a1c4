"""A plain scalar, one-house-at-a-time implementation of ISO 13790 Annex C: the test oracle.

Written straight from the standard's equations (C.1–C.13) with no shared code from impctl.model,
so that the vectorised model is checked against an independent transcription. Units: °C, W, s.
"""

from __future__ import annotations

import math


def derived(p: dict) -> dict:
    """Every derived quantity of the house ``p`` (Table I keys), literally per ISO 13790."""
    a_f = p["floor_area"]
    c_f = p["c_f"]
    # Table 12 A_m factor by linear interpolation between the class points.
    pts = [(0.8, 2.5), (1.1, 2.5), (1.65, 2.5), (2.6, 3.0), (3.7, 3.5)]
    if c_f <= pts[0][0]:
        f = pts[0][1]
    elif c_f >= pts[-1][0]:
        f = pts[-1][1]
    else:
        for (x0, y0), (x1, y1) in zip(pts, pts[1:], strict=False):
            if x0 <= c_f <= x1:
                f = y0 + (y1 - y0) * (c_f - x0) / (x1 - x0)
                break
    a_t = 4.5 * a_f
    a_m = f * a_f
    h_is = 3.45 * a_t
    h_ms = 9.1 * a_m
    h_op = p["u_walls"] * p["walls_area"]
    h_em = 1.0 / (1.0 / h_op - 1.0 / h_ms)
    h_w = p["u_windows"] * p["windows_area"]
    vol = a_f * p["wall_height"]
    n = p["ach_vent"] * (1.0 - p.get("heat_recovery", 0.0)) + p["ach_infl"]
    h_ve = 1200.0 * vol * n / 3600.0
    h1 = 1.0 / (1.0 / h_ve + 1.0 / h_is)
    h2 = h1 + h_w
    h3 = 1.0 / (1.0 / h2 + 1.0 / h_ms)
    c_m = c_f * 1e5 * a_f
    return dict(a_t=a_t, a_m=a_m, h_is=h_is, h_ms=h_ms, h_op=h_op, h_em=h_em, h_w=h_w,
                h_ve=h_ve, h1=h1, h2=h2, h3=h3, c_m=c_m, a_f=a_f)


def evaluate(d: dict, t_m_prev: float, t_e: float, phi_hc: float, phi_int: float,
             phi_sol: float, dt_s: float) -> tuple[float, float, float]:
    """C.1–C.11 for one step with a given Φ_HC at the air node → (θ_m,t, θ_s, θ_air)."""
    phi_ia = 0.5 * phi_int + phi_hc
    phi_m = d["a_m"] / d["a_t"] * (0.5 * phi_int + phi_sol)
    phi_st = (1 - d["a_m"] / d["a_t"] - d["h_w"] / (9.1 * d["a_t"])) * (0.5 * phi_int + phi_sol)
    t_sup = t_e
    phi_mtot = (phi_m + d["h_em"] * t_e
                + d["h3"] * (phi_st + d["h_w"] * t_e + d["h1"] * (phi_ia / d["h_ve"] + t_sup))
                / d["h2"])
    c = d["c_m"] / dt_s
    hh = 0.5 * (d["h3"] + d["h_em"])
    t_m = (t_m_prev * (c - hh) + phi_mtot) / (c + hh)
    t_mean = 0.5 * (t_m + t_m_prev)
    t_s = ((d["h_ms"] * t_mean + phi_st + d["h_w"] * t_e + d["h1"] * (t_sup + phi_ia / d["h_ve"]))
           / (d["h_ms"] + d["h_w"] + d["h1"]))
    t_air = (d["h_is"] * t_s + d["h_ve"] * t_sup + phi_ia) / (d["h_is"] + d["h_ve"])
    return t_m, t_s, t_air


def step(d: dict, p_max: float, t_m_prev: float, t_e: float, setpoint: float | None,
         forced: float | None, phi_int: float, phi_sol: float, dt_s: float):
    """One step: forced power, heating off (setpoint None) or the C.13 demand with a cap.

    Returns (θ_m,t, θ_s, θ_air, Φ_HC).
    """
    if forced is not None:
        return (*evaluate(d, t_m_prev, t_e, forced, phi_int, phi_sol, dt_s), forced)
    t_m0, t_s0, t_air0 = evaluate(d, t_m_prev, t_e, 0.0, phi_int, phi_sol, dt_s)
    if setpoint is None or t_air0 >= setpoint:
        return t_m0, t_s0, t_air0, 0.0
    phi_10 = 10.0 * d["a_f"]
    _, _, t_air10 = evaluate(d, t_m_prev, t_e, phi_10, phi_int, phi_sol, dt_s)
    phi_un = phi_10 * (setpoint - t_air0) / (t_air10 - t_air0)
    phi = min(phi_un, p_max)
    return (*evaluate(d, t_m_prev, t_e, phi, phi_int, phi_sol, dt_s), phi)


def run(p: dict, t_out, setpoint, forced, phi_int, phi_sol, dt_s: float, t_m0: float):
    """Simulate one house over lists of inputs (None = no setpoint / not forced)."""
    d = derived(p)
    p_max = p.get("max_heating_power", math.inf)
    t_m = t_m0
    rows = []
    for i in range(len(t_out)):
        t_m, t_s, t_air, phi = step(d, p_max, t_m, t_out[i], setpoint[i], forced[i], phi_int[i],
                                    phi_sol[i], dt_s)
        rows.append((t_air, t_s, t_m, phi))
    return rows
