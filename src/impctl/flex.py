"""Flexibility of a fitted house: how long the heating can stay off, and what it costs afterwards.

The figure an aggregator trades. From the fitted 5R1C house (:mod:`impctl.model`):

1. **Steady state** at T_set (``t_set_c``) indoors and T_out (``t_out_c``) outdoors, heating
   holding T_air: Φ_ss = HLC·(T_set − T_out) [W], θ_m from the model's air-node balance.
2. **Coast** (``coast_h`` [h]): heating switched off, Annex C stepped at ``step_s`` with T_out
   held, until T_air has fallen by ``drop_k``. The 5R1C air node has no heat capacity, so at
   switch-off the model's T_air jumps down at once by ``switch_off_drop_k`` (Φ_ss over the
   air-node conductances; ~1–3 K for typical houses). That jump is a model artefact — air,
   furniture and emitters spread it over 15–60 min in a real house, and impctl's fit leaves the
   first emission-lag hour out for the same reason (identifiability.md §11.2) — and counting it
   would give 0 h for almost every house. The drop is therefore counted from the air
   temperature just after the jump: ``coast_h`` is the time the *slow*, mass-driven cooling
   takes to lower T_air by ``drop_k``. ``switch_off_drop_k`` is reported next to it.
3. **Rebound** (``rebound_kwh`` [kWh]): heating back on at T_set from the state at the end of
   the coast (Annex C demand, C.13, capped at the house's ``max_heating_power``, uncapped by
   default); the heat delivered in the following ``rebound_h`` (2 h) beyond the steady-state
   demand Φ_ss·2 h.

Intervals: ``coast_h_low`` / ``coast_h_high`` are the coast of the same house with its heat
capacity moved (through c_f) so that τ sits at the low / high end of its 95 % interval — τ is what
governs the coast.

Temperatures °C, powers W, energies kWh, times h. Pure model code: needs only
:mod:`impctl.model` (no torch, no pandas).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from .errors import InputError
from .model import HouseParameters, air_temperature, mass_from_air, simulate

#: Keys of the ``"flexibility"`` block in the fit JSON (read by the MQTT publisher).
BLOCK_KEYS = ("coast_h", "coast_h_low", "coast_h_high", "rebound_kwh")
DEFAULTS = {"t_set_c": 21.0, "t_out_c": 0.0, "drop_k": 1.0, "rebound_h": 2.0}


@dataclass(frozen=True)
class Flexibility:
    """One house's flexibility (see the module docstring); NaN where it could not be computed.

    Attributes
    ----------
    coast_h, coast_h_low, coast_h_high : hours until T_air has fallen by ``drop_k`` [h]
    rebound_kwh : heat beyond steady-state demand in the ``rebound_h`` after the coast [kWh]
    switch_off_drop_k : the model's instantaneous T_air drop at switch-off (not counted) [K]
    steady_state_w : heat demand at steady state Φ_ss [W]
    t_set_c, t_out_c, drop_k, rebound_h : the conditions [°C, °C, K, h]
    """

    coast_h: float
    coast_h_low: float
    coast_h_high: float
    rebound_kwh: float
    switch_off_drop_k: float
    steady_state_w: float
    t_set_c: float
    t_out_c: float
    drop_k: float
    rebound_h: float

    def block(self) -> dict[str, float | None]:
        """The fit JSON's ``"flexibility"`` block: :data:`BLOCK_KEYS` plus the conditions."""
        out = {k: _num(v) for k, v in asdict(self).items()}
        return {k: out[k] for k in (*BLOCK_KEYS, "switch_off_drop_k", "steady_state_w",
                                    "t_set_c", "t_out_c", "drop_k", "rebound_h")}


def _num(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _check(t_set_c: float, t_out_c: float, drop_k: float, rebound_h: float) -> None:
    if not drop_k > 0:
        raise InputError(f"--drop must be > 0 K, got {drop_k:g}")
    if not rebound_h > 0:
        raise InputError(f"the rebound window must be > 0 h, got {rebound_h:g}")
    if not t_out_c < t_set_c - drop_k:
        raise InputError(f"--t-out {t_out_c:g} °C must lie below --t-set − --drop = "
                         f"{t_set_c - drop_k:g} °C, or the house never cools by {drop_k:g} K")


def _coast(houses: HouseParameters, t_set_c: float, t_out_c: float, drop_k: float,
           rebound_h: float, step_s: float, horizon_h: float):
    """Vectorised core: arrays (n,) of coast [h], rebound [kWh], jump [K], Φ_ss [W]."""
    net = houses.network
    n = houses.n_houses or 1
    hlc = np.broadcast_to(np.asarray(net.hlc_w_per_k, float), (n,))
    phi_ss = hlc * (t_set_c - t_out_c)
    t_m = np.broadcast_to(np.asarray(mass_from_air(t_set_c, t_out_c, phi_ss, net), float),
                          (n,)).copy()
    t_air0 = np.broadcast_to(np.asarray(air_temperature(t_m, t_out_c, 0.0, net), float), (n,))
    target = t_air0 - drop_k
    coast = np.full(n, np.nan)
    t_m_at = np.full(n, np.nan)
    chunk = int(round(24 * 3600 / step_s))
    elapsed = 0
    prev_air, prev_t, prev_m = t_air0.copy(), np.zeros(n), t_m.copy()
    while elapsed * step_s < horizon_h * 3600 and np.isnan(coast).any():
        sim = simulate(houses, np.full((chunk, n), t_out_c), step_s, t_m_init_c=t_m)
        air = np.atleast_2d(sim.t_air_c.T).T
        m_end = np.atleast_2d(sim.t_m_c.T).T
        # Annex C's T_air of a step belongs to its middle (it uses the step-mean θ_m).
        mid_h = (elapsed + np.arange(chunk) + 0.5) * step_s / 3600.0
        ends_h = (elapsed + np.arange(chunk) + 1.0) * step_s / 3600.0
        all_air = np.vstack([prev_air, air])
        all_t = np.concatenate([[0.0], mid_h]) if elapsed == 0 else np.concatenate(
            [[prev_t[0]], mid_h])
        below = all_air <= target
        for j in np.flatnonzero(np.isnan(coast) & below.any(axis=0)):
            i = int(below[:, j].argmax())
            a0, a1 = all_air[i - 1, j], all_air[i, j]
            t0, t1 = all_t[i - 1], all_t[i]
            coast[j] = t0 + (t1 - t0) * (a0 - target[j]) / (a0 - a1) if a0 != a1 else t1
            m_t = np.concatenate([[prev_m[j]], m_end[:, j]])
            m_h = np.concatenate([[elapsed * step_s / 3600.0], ends_h])
            t_m_at[j] = np.interp(coast[j], m_h, m_t)
        prev_air, prev_t, prev_m = air[-1], np.full(n, mid_h[-1]), m_end[-1]
        t_m = m_end[-1].copy()
        elapsed += chunk
    rebound = np.full(n, np.nan)
    ok = np.isfinite(t_m_at)
    if ok.any():
        steps = int(round(rebound_h * 3600 / step_s))
        start = np.where(ok, t_m_at, t_m)
        sim = simulate(houses, np.full((steps, n), t_out_c), step_s,
                       setpoint_c=np.full((steps, n), t_set_c), t_m_init_c=start)
        phi = np.atleast_2d(sim.phi_hc_w.T).T
        extra = (phi - phi_ss).sum(axis=0) * step_s / 3.6e6
        rebound = np.where(ok, extra, np.nan)
    return coast, rebound, t_set_c - t_air0, phi_ss


def _with_tau(houses: HouseParameters, tau_h: np.ndarray) -> HouseParameters:
    """The houses with c_f moved so that τ ≈ ``tau_h`` (a few fixed-point steps; τ ∝ c_f
    nearly, the Table 12 area factor bends it slightly)."""
    c_f = np.asarray(houses.c_f, float).copy()
    for _ in range(4):
        tau = np.asarray(replace(houses, c_f=c_f).tau_h, float)
        c_f = np.clip(c_f * tau_h / tau, 0.5, 5.0)
    return replace(houses, c_f=c_f)


def flexibility_many(
    houses: HouseParameters,
    tau_low_h: Any = None,
    tau_high_h: Any = None,
    *,
    t_set_c: float = 21.0,
    t_out_c: float = 0.0,
    drop_k: float = 1.0,
    rebound_h: float = 2.0,
    step_s: float = 300.0,
    horizon_h: float = 480.0,
) -> list[Flexibility]:
    """Flexibility of each house in ``houses`` (array-valued or one), vectorised.

    Parameters
    ----------
    houses : the fitted houses (:class:`~impctl.model.HouseParameters`)
    tau_low_h, tau_high_h : array (n,) or float, optional
        Ends of τ's 95 % interval [h]; without them the coast interval is the point value.
    t_set_c, t_out_c : steady-state indoor setpoint and outdoor temperature [°C]
    drop_k : the T_air drop that ends the coast [K]
    rebound_h : the window after the coast for ``rebound_kwh`` [h]
    step_s : Annex C step [s]
    horizon_h : longest coast simulated [h]; a longer one is NaN

    Raises
    ------
    InputError
        When the conditions make no sense (T_out not below T_set − drop, drop ≤ 0).
    """
    _check(t_set_c, t_out_c, drop_k, rebound_h)
    n = houses.n_houses or 1
    if houses.n_houses is None:
        houses = HouseParameters.stack([houses])
    variants = [houses]
    for tau in (tau_low_h, tau_high_h):
        if tau is not None:
            target = np.broadcast_to(np.asarray(tau, float), (n,))
            ok = np.isfinite(target) & (target > 0)
            variants.append(_with_tau(houses, np.where(ok, target, houses.tau_h)))
    stacked = HouseParameters(**{k: np.concatenate([np.broadcast_to(
        np.asarray(getattr(v, k), float), (n,)) for v in variants]) for k in houses.as_dict()})
    coast, rebound, jump, phi_ss = _coast(stacked, t_set_c, t_out_c, drop_k, rebound_h,
                                          step_s, horizon_h)
    coast = coast.reshape(len(variants), n)
    lo = coast.min(axis=0) if len(variants) > 1 else coast[0]
    hi = coast.max(axis=0) if len(variants) > 1 else coast[0]
    return [Flexibility(float(coast[0, i]), float(lo[i]), float(hi[i]), float(rebound[i]),
                        float(jump[i]), float(phi_ss[i]), t_set_c, t_out_c, drop_k, rebound_h)
            for i in range(n)]


def house_from_fit(summary: dict) -> HouseParameters:
    """The fitted house of an ``impctl fit`` JSON summary (its parameters and fixed air change).

    Raises
    ------
    InputError
        When the summary lacks the parameters.
    """
    try:
        params = {k: float(v) for k, v in summary["parameters"].items()}
        fixed = summary.get("fixed", {})
        return HouseParameters(**params, ach_vent=float(fixed.get("ach_vent", 0.0)),
                               ach_infl=float(fixed.get("ach_infl", 0.01)))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"not an impctl fit result (parameters: {exc})") from None


def flexibility_of_fit(summary: dict, **conditions) -> Flexibility:
    """:func:`flexibility_many` for one ``impctl fit`` JSON summary (τ interval from it)."""
    tau = summary.get("lumped", {}).get("tau", {})
    return flexibility_many(house_from_fit(summary), tau.get("low"), tau.get("high"),
                            **conditions)[0]
