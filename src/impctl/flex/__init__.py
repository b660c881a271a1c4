"""Flexibility of a fitted house: how long the heating can stay off, and what it costs afterwards.

The figure an aggregator trades. From the fitted house — the 5R1C (:mod:`impctl.model`) plus the
switch-off terms the fit kept (:mod:`.switch_off`):

1. **Steady state** at T_set (``t_set_c``) indoors and T_out (``t_out_c``) outdoors, heating
   holding T_air: Φ_ss = HLC·(T_set − T_out) [W] (the heating supplies it less the night gain,
   if the fit estimated one), θ_m from the model's air-node balance.
2. **Coast** (``coast_h`` [h]): heating switched off, T_out held, until T_air has fallen by
   ``drop_k`` (:func:`.coast.simulate_coast`, exact steps). A real house does not drop at
   switch-off: its emitter keeps releasing heat and the air and furniture cool over 15–60 min.
   When the fit kept its nuisance terms (its likelihood-ratio test: the nights need them) the
   coast simulates them: the emitter's release, continuous at switch-off (it still delivers the
   steady-state heat) and fading with the fitted τ_em; the air/furniture node; the night gain.
   Without them the 5R1C's massless air node jumps down at once by ``switch_off_drop_k``
   (~1–3 K) and the drop is counted from just after that jump (the fit found no release after
   its emission lag, so the pure-5R1C house it describes coasts on its mass).
   ``coast_method`` names what was used; ``coast_gain_w`` the gain assumed: the fit's own (its
   fitted gain, or the gain it assumed, :mod:`impctl.imp.gain`, 250 W unless the installer
   set it) — 0 W only for an older fit that assumed none (its HLC then carries the gains).
3. **Rebound** (``rebound_kwh`` [kWh]): heating back on at T_set from the state at the end of
   the coast (Annex C demand, C.13, capped at the house's ``max_heating_power``, uncapped by
   default); the heat delivered in the following ``rebound_h`` (2 h) beyond the steady-state
   demand Φ_ss·2 h.

Intervals (``coast_h_low`` / ``coast_h_high``): the coast recomputed with each uncertain input
at the ends of its 95 % interval — τ (the heat capacity moved through c_f), τ_em, the
air/furniture capacity, the night gain (:mod:`.switch_off`: undetermined terms take their
documented physical range) — and a structural share, half the log-difference to the coast of
the other model structure (with the terms: the pure 5R1C, jump not counted; without: the jump
released over a third of the emission lag, a release the fit could not have seen), the fit's
own rule for its intervals (``structure_share``). The shifts below and above the point value
are added in quadrature.

Temperatures °C, powers W, energies kWh, times h. numpy only: needs :mod:`impctl.model` (no
torch, no pandas; the daemon's MQTT publisher imports it).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from ..errors import InputError
from ..model import HouseParameters
from .coast import simulate_coast
from .switch_off import SwitchOff, switch_off_from_fit

__all__ = ["BLOCK_KEYS", "DEFAULTS", "Flexibility", "SwitchOff", "flexibility_many",
           "flexibility_of_fit", "house_from_fit", "switch_off_from_fit"]

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


def _with_tau(houses: HouseParameters, tau_h: np.ndarray) -> HouseParameters:
    """The houses with c_f moved so that τ ≈ ``tau_h`` (a few fixed-point steps; τ ∝ c_f
    nearly, the Table 12 area factor bends it slightly)."""
    c_f = np.asarray(houses.c_f, float).copy()
    for _ in range(4):
        tau = np.asarray(replace(houses, c_f=c_f).tau_h, float)
        c_f = np.clip(c_f * tau_h / tau, 0.5, 5.0)
    return replace(houses, c_f=c_f)


def _method(terms: dict[str, np.ndarray], documented: Any, i: int) -> str:
    names = {"emitter_tau_h": "emitter release", "furniture_j_per_m2k": "air/furniture",
             "night_gain_w": "night gain"}
    doc = documented if documented and isinstance(documented[0], str) else (
        documented[i] if documented else ())
    used = [names[k] + (" (documented range)" if k in doc else "")
            for k in ("emitter_tau_h", "furniture_j_per_m2k", "night_gain_w")
            if np.isfinite(terms[k][0, i]) and not (k == "night_gain_w" and k in doc)]
    gain = terms["night_gain_w"][0, i]
    assumed = (f" + assumed night gain {gain:.0f} W" if "night_gain_w" in doc
               and np.isfinite(gain) else "")
    return ("5R1C + fitted " + " + ".join(used) + assumed if used
            else "5R1C" + assumed + ", switch-off jump not counted" if assumed
            else "5R1C, switch-off jump not counted")


#: Emitter release time constant of the structural alternative to a pure-5R1C coast: a third of
#: the fit's emission lag (1 h) — a release that has faded (to 5 %) before the fit window [h].
UNSEEN_RELEASE_H = 1.0 / 3.0


def flexibility_many(
    houses: HouseParameters,
    tau_low_h: Any = None,
    tau_high_h: Any = None,
    *,
    switch_off: SwitchOff | None = None,
    structure_share: bool = True,
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
        The fit's switch-off terms (:func:`switch_off_from_fit`); without them the coast is
        the pure 5R1C's with its switch-off jump not counted.
    structure_share : bool
        Widen the interval by the structural share (module docstring).
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
    switch_off = switch_off or SwitchOff()
    terms = switch_off.values(n)
    point = {k: v[0] for k, v in terms.items()}
    # Row 0 the point value; then each uncertain input (a group) at the ends of its interval.
    variants, group, scale = [(houses, point)], [-1], {}
    c_fur = np.nan_to_num(point["furniture_j_per_m2k"]) * np.asarray(houses.floor_area)
    tau_model = np.asarray(houses.tau_h, float)
    c_m = np.asarray(houses.c_m_j_per_k, float)
    tau_reported = tau_model * (c_m + c_fur) / c_m
    for tau in (tau_low_h, tau_high_h):
        if tau is not None:
            target = np.broadcast_to(np.asarray(tau, float), (n,))
            ok = np.isfinite(target) & (target > 0)
            # the reported τ carries the furniture: move the 5R1C's τ by the same factor
            variants.append((_with_tau(houses, np.where(
                ok, tau_model * target / tau_reported, tau_model)), point))
            group.append(0)
    for j, (key, v) in enumerate(terms.items(), start=1):
        for end in (1, 2):
            if np.isfinite(v[end]).any():
                variants.append((houses, {**point, key: np.where(np.isfinite(v[end]), v[end],
                                                                 v[0])}))
                group.append(j)
    if structure_share:
        dynamic = np.isfinite(point["emitter_tau_h"]) | (np.nan_to_num(
            point["furniture_j_per_m2k"]) > 0)
        # the other structure: without the release terms, or with a release nobody saw
        variants.append((houses, {**point, "emitter_tau_h": np.where(
            dynamic, np.nan, UNSEEN_RELEASE_H), "furniture_j_per_m2k": np.where(
            dynamic, np.nan, point["furniture_j_per_m2k"])}))
        group.append(len(terms) + 1)
        scale[len(terms) + 1] = 0.5
    stacked = HouseParameters(**{k: np.concatenate([np.broadcast_to(
        np.asarray(getattr(h, k), float), (n,)) for h, _ in variants])
        for k in houses.as_dict()})
    stacked_terms = {k: np.concatenate([t[k] for _, t in variants]) for k in terms}
    coast, rebound, jump, phi_ss = simulate_coast(stacked, stacked_terms, t_set_c, t_out_c,
                                                  drop_k, rebound_h, step_s, horizon_h)
    coast = coast.reshape(len(variants), n)
    lo, hi = _interval(coast, np.array(group), scale)
    return [Flexibility(float(coast[0, i]), float(lo[i]), float(hi[i]), float(rebound[i]),
                        float(jump[i]), float(phi_ss[i]), t_set_c, t_out_c, drop_k, rebound_h,
                        _method(terms, switch_off.documented, i),
                        float(np.nan_to_num(point["night_gain_w"][i])))
            for i in range(n)]


def _interval(coast: np.ndarray, group: np.ndarray, scale: dict[int, float]
              ) -> tuple[np.ndarray, np.ndarray]:
    """Coast interval from the variants (row 0 the point value; ``group`` names the input each
    row moved, ``scale`` a factor on a group's shift): per input the largest log-shift below
    and above the point value, the inputs added in quadrature (independent errors)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.log(coast / coast[0])
    shift = np.where(np.isfinite(shift), shift, 0.0)
    down, up = np.zeros(coast.shape[1]), np.zeros(coast.shape[1])
    for g in np.unique(group[group >= 0]):
        rows = shift[group == g] * scale.get(int(g), 1.0)
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


def flexibility_of_fit(summary: dict, **conditions) -> Flexibility:
    """:func:`flexibility_many` for one ``impctl fit`` JSON summary (τ interval and the
    switch-off terms from it)."""
    tau = summary.get("lumped", {}).get("tau", {})
    return flexibility_many(house_from_fit(summary), tau.get("low"), tau.get("high"),
                            switch_off=switch_off_from_fit(summary), **conditions)[0]
