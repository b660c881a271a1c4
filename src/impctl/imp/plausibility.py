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

Two wrong inputs look like a house and are told by what else the file holds: temperatures in
°F (a room at 70 °F is a 70 °C room to the reader, :func:`fahrenheit_problem`) and, where the
heat pump's electrical power ``p_el_w`` is given, a q_hc that is that electrical power rather
than the heat (COP ≈ 1 instead of 2–5, :func:`electrical_problem`). Without ``p_el_w`` an
electrical power stays plausible (it gives a third of the HLC, still a dwelling's) and cannot
be told.
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


#: Median room air [°F] of a file in °F: 10–32 °C. As °C no heated room is that warm.
FAHRENHEIT_ROOM = (50.0, 90.0)
#: The heat pump counts as running above this electrical power [W] (compressor on; standby
#: and the controller draw tens of watts).
P_EL_RUNNING_W = 200.0
#: q_hc / p_el_w at or below this on running rows is no heat pump's heat [-]: air-source
#: units deliver 2–5 times their electricity, still ~1.5× at −20 °C.
ELECTRICAL_RATIO = 1.3
#: Running rows the ratio needs before it says anything.
MIN_RUNNING_ROWS = 10


def to_celsius(t_f: float) -> float:
    """°F → °C."""
    return (t_f - 32.0) / 1.8


def fahrenheit_problem(t_air: np.ndarray) -> str | None:
    """Why room temperatures ``t_air`` look like °F (their median in
    :data:`FAHRENHEIT_ROOM`, a heated room's 10–32 °C written in °F), or None."""
    finite = np.asarray(t_air, float)
    finite = finite[np.isfinite(finite)]
    if not len(finite):
        return None
    median = float(np.median(finite))
    lo, hi = FAHRENHEIT_ROOM
    if not lo <= median <= hi:
        return None
    return (f"the room temperatures look like °F (median {median:.1f}: "
            f"{to_celsius(median):.1f} °C if it is °F; no heated room is at {median:.0f} °C): "
            "NIGHTS files hold °C — convert t_air, t_out and setpoint with (°F − 32) / 1.8")


def electrical_problem(q_hc_w: np.ndarray, p_el_w: np.ndarray) -> str | None:
    """Why ``q_hc_w`` [W] looks like the heat pump's electrical power ``p_el_w`` [W] rather
    than its heat: on the rows where the heat pump runs (p_el ≥ :data:`P_EL_RUNNING_W`,
    q_hc > :data:`~impctl.imp.features.Q_ON_W`) the median q_hc / p_el is at most
    :data:`ELECTRICAL_RATIO`; None otherwise (or with fewer than
    :data:`MIN_RUNNING_ROWS` running rows)."""
    q, p = np.asarray(q_hc_w, float), np.asarray(p_el_w, float)
    running = np.isfinite(q) & np.isfinite(p) & (p >= P_EL_RUNNING_W) & (q > Q_ON_W)
    if running.sum() < MIN_RUNNING_ROWS:
        return None
    ratio = float(np.median(q[running] / p[running]))
    if ratio > ELECTRICAL_RATIO:
        return None
    return (f"q_hc looks like electrical power, not heat: on the {int(running.sum())} rows "
            f"where p_el_w shows the heat pump running, q_hc is {ratio:.2f} × p_el_w in the "
            "median (a heat pump delivers 2–5 times the electricity it uses) — give the "
            "thermal heat output in W (a heat meter; Kronoterm register 2329)")


def implied_hlc(nights: Sequence[NightSamples]) -> float | None:
    """Median over normal nights of mean q_hc / mean(T_air − T_out) [W/K]; ``None`` when no
    normal night has a difference of at least :data:`MIN_DELTA_T_K`."""
    ratios = []
    for n in nights:
        if n.kind != "normal" or n.phase or len(n.time_s) < 2:  # not a pre-heat
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
