"""Unit plausibility of measured nights: is the heat output in W, do power and temperature
difference fit a dwelling?

On a normal night the heating holds T_air, so the mean heat output divided by the mean
indoor–outdoor difference is roughly the house's heat-loss coefficient (the mass and internal
gains give or take some). Dwellings have HLC :data:`HLC_W_PER_K` = 10–2,000 W/K (a
passive-house flat … a large old villa); a ratio outside that is a wrong unit or a wrong
column, not a house — above all q_hc logged in kW, which the fit would otherwise turn into an
HLC of a few W/K with exit 0. After the fit, a model that misses the measured heat of its own
normal nights by more than :data:`MAX_EPS_PCT` is refused the same way
(:func:`fit_problem`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from .features import Q_ON_W
from .night import NightSamples

#: Plausible heat-loss coefficient of a dwelling [W/K].
HLC_W_PER_K = (10.0, 2000.0)
#: Largest mean heat-demand error ε of a fit on its own normal nights [%]: the paper reports
#: ~19 %; a model that misses the measured heat by more cannot be a fit of this house (the
#: search box keeps the fitted HLC physical, so a wrong unit shows up here).
MAX_EPS_PCT = 100.0
#: Normal nights whose mean T_air − T_out is below this [K] do not tell the ratio well.
MIN_DELTA_T_K = 3.0


def implied_hlc(nights: Sequence[NightSamples]) -> float | None:
    """Median over normal nights of mean q_hc / mean(T_air − T_out) [W/K]; ``None`` when no
    normal night has a difference of at least :data:`MIN_DELTA_T_K`."""
    ratios = []
    for n in nights:
        if n.kind != "normal" or len(n.time_s) < 2:
            continue
        dt_k = float(np.mean(np.asarray(n.t_air_c) - np.asarray(n.t_out_c)))
        if dt_k >= MIN_DELTA_T_K:
            ratios.append(float(np.mean(n.q_hc_w)) / dt_k)
    return float(np.median(ratios)) if ratios else None


def hlc_problem(hlc_w_per_k: float, what: str) -> str | None:
    """Why ``hlc_w_per_k`` is no dwelling's HLC, with the likely cause; ``None`` if plausible."""
    lo, hi = HLC_W_PER_K
    if lo <= hlc_w_per_k <= hi:
        return None
    head = (f"{what} is {hlc_w_per_k:.3g} W/K, outside the {lo:g}–{hi:,.0f} W/K of a "
            "dwelling")
    if hlc_w_per_k < lo and lo <= 1000.0 * hlc_w_per_k <= hi:
        return (head + ": q_hc looks like kW — give the thermal heat output in W "
                "(multiply the column by 1000)")
    if hlc_w_per_k < lo:
        return (head + ": q_hc is far too small for the indoor–outdoor difference — is it "
                "the thermal heat output in W (not kW, not a pump's electrical power in kW, "
                "not a percentage)?")
    return (head + ": q_hc is far too large for the indoor–outdoor difference — is it the "
            "heat output in W of this house only (not mW, not a district meter), and are "
            "t_air and t_out in °C?")


def check_units(nights: Sequence[NightSamples], source: str | Path | None = None) -> None:
    """Refuse nights whose heat output cannot be in W for the measured temperatures.

    Raises
    ------
    InputError
        One line naming ``source``, what was found and the likely cause.
    """
    q_max = max((float(np.max(n.q_hc_w)) for n in nights if len(n.q_hc_w)), default=0.0)
    if 1.0 <= q_max <= Q_ON_W:
        raise InputError(
            f"q_hc never exceeds {q_max:.3g} W, but a running heat pump delivers kilowatts: "
            "q_hc looks like kW — give the thermal heat output in W (multiply the column by "
            "1000)", source, "column 'q_hc'")
    hlc = implied_hlc(nights)
    if hlc is not None:
        why = hlc_problem(hlc, "mean q_hc / (T_air − T_out) on the normal nights")
        if why is not None:
            raise InputError(why, source, "column 'q_hc'")


def fit_problem(hlc_w_per_k: float, eps_pct: float | None) -> str | None:
    """Why a finished fit cannot be a house's: a fitted HLC outside :data:`HLC_W_PER_K`, or a
    mean heat-demand error on the normal nights above :data:`MAX_EPS_PCT`; ``None`` if fine."""
    why = hlc_problem(hlc_w_per_k, "the fitted HLC")
    if why is None and eps_pct is not None and eps_pct > MAX_EPS_PCT:
        why = (f"the fitted model misses the measured heat of the normal nights by "
               f"{eps_pct:.0f} % on average (a house fit is within ~20–30 %): q_hc does not "
               "match the temperatures — is it the thermal heat output in W of this house, "
               "and are t_air and t_out in °C?")
    return why
