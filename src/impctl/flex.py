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
from .model import (
    HouseParameters,
    air_temperature,
    mass_derivative,
    mass_from_air,
    simulate,
)

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
    switch_off_drop_k : the model's instantaneous T_air drop at switch-off [K] (0 with a
        fitted emitter release; not counted when no switch-off term was fitted)
    steady_state_w : heat loss at steady state Φ_ss = HLC·(T_set − T_out) [W]
    t_set_c, t_out_c, drop_k, rebound_h : the conditions [°C, °C, K, h]
    coast_method : what the coast was computed with (the model and the fitted terms)
    coast_gain_w : the internal gain the coast assumes during the coast [W]
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
    coast_method: str = "5R1C, switch-off jump not counted"
    coast_gain_w: float = 0.0

    def block(self) -> dict[str, float | None]:
        """The fit JSON's ``"flexibility"`` block: :data:`BLOCK_KEYS` plus the conditions."""
        out = {k: v if isinstance(v, str) else _num(v) for k, v in asdict(self).items()}
        return {k: out[k] for k in (*BLOCK_KEYS, "switch_off_drop_k", "steady_state_w",
                                    "t_set_c", "t_out_c", "drop_k", "rebound_h",
                                    "coast_method", "coast_gain_w")}


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


#: Furniture–air time constant [s]: the fit's (:data:`impctl.fit.node.FURNITURE_TAU_S`,
#: real-houses.md §1); repeated here so that this module needs no torch.
FURNITURE_TAU_S = 1.0 / 0.00022
#: Names of the fit's nuisance terms the coast uses (the fit JSON's ``"nuisance"`` block).
SWITCH_OFF_TERMS = ("night_gain_w", "emitter_tau_h", "furniture_j_per_m2k")


@dataclass(frozen=True)
class SwitchOff:
    """What the fit found the real house does at switch-off beyond the 5R1C (its nuisance
    terms, :data:`impctl.fit.node.NUISANCE_NAMES`): each field (value, low, high), floats or
    arrays (n,); NaN = the term was not fitted.

    Attributes
    ----------
    night_gain_w : constant heat to the air node (sleepers, base load) [W]
    emitter_tau_h : time constant of the emitter's release after switch-off [h]
    furniture_j_per_m2k : air + furniture capacity at the air node, per m² of floor [J/(m²K)]
    """

    night_gain_w: tuple = (np.nan, np.nan, np.nan)
    emitter_tau_h: tuple = (np.nan, np.nan, np.nan)
    furniture_j_per_m2k: tuple = (np.nan, np.nan, np.nan)

    def values(self, n: int) -> dict[str, np.ndarray]:
        """(3, n) arrays (value, low, high) per term."""
        return {k: np.broadcast_to(np.asarray(getattr(self, k), float).reshape(3, -1),
                                   (3, n)).copy() for k in SWITCH_OFF_TERMS}


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


def _coast(houses: HouseParameters, terms: dict[str, np.ndarray], t_set_c: float,
           t_out_c: float, drop_k: float, rebound_h: float, step_s: float, horizon_h: float):
    """Vectorised core: arrays (n,) of coast [h], rebound [kWh], jump [K], Φ_ss [W].

    ``terms``: (n,) arrays of the switch-off terms (NaN = not fitted)."""
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


def _with_tau(houses: HouseParameters, tau_h: np.ndarray) -> HouseParameters:
    """The houses with c_f moved so that τ ≈ ``tau_h`` (a few fixed-point steps; τ ∝ c_f
    nearly, the Table 12 area factor bends it slightly)."""
    c_f = np.asarray(houses.c_f, float).copy()
    for _ in range(4):
        tau = np.asarray(replace(houses, c_f=c_f).tau_h, float)
        c_f = np.clip(c_f * tau_h / tau, 0.5, 5.0)
    return replace(houses, c_f=c_f)


def _method(terms: dict[str, np.ndarray], i: int) -> str:
    used = [name for name, key in (("emitter release", "emitter_tau_h"),
                                   ("furniture", "furniture_j_per_m2k"),
                                   ("night gain", "night_gain_w"))
            if np.isfinite(terms[key][0, i])]
    return ("5R1C + " + " + ".join(used) if used
            else "5R1C, switch-off jump not counted")


def flexibility_many(
    houses: HouseParameters,
    tau_low_h: Any = None,
    tau_high_h: Any = None,
    *,
    switch_off: SwitchOff | None = None,
    t_set_c: float = 21.0,
    t_out_c: float = 0.0,
    drop_k: float = 1.0,
    rebound_h: float = 2.0,
    step_s: float = 60.0,
    horizon_h: float = 480.0,
) -> list[Flexibility]:
    """Flexibility of each house in ``houses`` (array-valued or one), vectorised.

    Parameters
    ----------
    houses : the fitted houses (:class:`~impctl.model.HouseParameters`)
    tau_low_h, tau_high_h : array (n,) or float, optional
        Ends of the fit's τ 95 % interval [h] (the reported τ: with a fitted furniture term it
        includes that capacity); without them τ adds nothing to the coast interval.
    switch_off : :class:`SwitchOff`, optional
        The fit's nuisance terms (value, low, high); without them the coast is the pure 5R1C's
        with its switch-off jump not counted.
    t_set_c, t_out_c : steady-state indoor setpoint and outdoor temperature [°C]
    drop_k : the T_air drop that ends the coast [K]
    rebound_h : the window after the coast for ``rebound_kwh`` [h]
    step_s : time step of the coast (exact discretisation) and of the Annex C rebound [s]
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
    terms = (switch_off or SwitchOff()).values(n)
    # Variant 0 the point value; then each uncertain input at the low and the high end of its
    # 95 % interval, the others at their values.
    variants = [(houses, {k: v[0] for k, v in terms.items()})]
    group = [-1]
    c_fur = np.nan_to_num(terms["furniture_j_per_m2k"][0]) * np.asarray(houses.floor_area)
    tau_model = np.asarray(houses.tau_h, float)
    c_m = np.asarray(houses.c_m_j_per_k, float)
    tau_reported = tau_model * (c_m + c_fur) / c_m
    for tau in (tau_low_h, tau_high_h):
        if tau is not None:
            target = np.broadcast_to(np.asarray(tau, float), (n,))
            ok = np.isfinite(target) & (target > 0)
            # the reported τ carries the furniture: move the 5R1C's τ by the same factor
            variants.append((_with_tau(houses, np.where(ok, tau_model * target / tau_reported,
                                                        tau_model)),
                             {k: v[0] for k, v in terms.items()}))
            group.append(0)
    for j, (key, v) in enumerate(terms.items(), start=1):
        for end in (1, 2):
            if np.isfinite(v[end]).any():
                variants.append((houses, {**{k: x[0] for k, x in terms.items()},
                                          key: np.where(np.isfinite(v[end]), v[end], v[0])}))
                group.append(j)
    stacked = HouseParameters(**{k: np.concatenate([np.broadcast_to(
        np.asarray(getattr(h, k), float), (n,)) for h, _ in variants])
        for k in houses.as_dict()})
    stacked_terms = {k: np.concatenate([t[k] for _, t in variants]) for k in terms}
    coast, rebound, jump, phi_ss = _coast(stacked, stacked_terms, t_set_c, t_out_c, drop_k,
                                          rebound_h, step_s, horizon_h)
    coast = coast.reshape(len(variants), n)
    lo, hi = _interval(coast, np.array(group))
    return [Flexibility(float(coast[0, i]), float(lo[i]), float(hi[i]), float(rebound[i]),
                        float(jump[i]), float(phi_ss[i]), t_set_c, t_out_c, drop_k, rebound_h,
                        _method(terms, i), float(np.nan_to_num(terms["night_gain_w"][0, i])))
            for i in range(n)]


def _interval(coast: np.ndarray, group: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coast interval from the variants (row 0 the point value; ``group`` names the input each
    row moved): per input the largest log-shift below and above the point value, the inputs
    added in quadrature (independent errors)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.log(coast / coast[0])
    shift = np.where(np.isfinite(shift), shift, 0.0)
    down, up = np.zeros(coast.shape[1]), np.zeros(coast.shape[1])
    for g in np.unique(group[group >= 0]):
        rows = shift[group == g]
        down += np.minimum(rows.min(axis=0), 0.0) ** 2
        up += np.maximum(rows.max(axis=0), 0.0) ** 2
    return coast[0] * np.exp(-np.sqrt(down)), coast[0] * np.exp(np.sqrt(up))


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


def switch_off_from_fit(summary: dict) -> SwitchOff:
    """The switch-off terms of an ``impctl fit`` JSON summary (its ``"nuisance"`` block; a term
    the fit did not keep is null there, NaN here)."""
    nuis = summary.get("nuisance") or {}
    out = {}
    for name in SWITCH_OFF_TERMS:
        v = nuis.get(name) or {}
        try:
            out[name] = tuple(float(v[k]) if v.get(k) is not None else np.nan
                              for k in ("value", "low", "high"))
        except (TypeError, ValueError, AttributeError):
            raise InputError(f"not an impctl fit result (nuisance {name}: {v!r})") from None
    return SwitchOff(**out)


def flexibility_of_fit(summary: dict, **conditions) -> Flexibility:
    """:func:`flexibility_many` for one ``impctl fit`` JSON summary (τ interval and the
    switch-off terms from it)."""
    tau = summary.get("lumped", {}).get("tau", {})
    return flexibility_many(house_from_fit(summary), tau.get("low"), tau.get("high"),
                            switch_off=switch_off_from_fit(summary), **conditions)[0]
