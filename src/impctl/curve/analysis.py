"""From a house's recorded rows (and its fit) to the curve it needs and what it saves."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputError
from .cop import fit_cop
from .data.blocks import heated, hourly, steady_blocks
from .emitter import EmitterUnknown, fit_emitter
from .need import FLOW_LIMITS_C, NeedUnknown, heat_need, need_curve, recommend, writable
from .result import CurveResult
from .running import running_curve
from .savings import season_savings, winter_climate

#: The stated margin above the bound [K]: the room sensor's and the controller's tolerance.
DEFAULT_MARGIN_K = 1.0
#: Setpoint assumed when neither the option nor owner rows give one [°C].
ASSUMED_SETPOINT_C = 21.0
#: A heated hour this far below the setpoint counts as cold [K].
COLD_K = 0.5


def owner_setpoint(rows: pd.DataFrame) -> tuple[float, str] | None:
    """The median setpoint of the owner's own rows (``kind`` owner), or None."""
    own = rows[(rows["kind"] == "owner").to_numpy()]
    sp = own["setpoint"].to_numpy(dtype=float)
    sp = sp[np.isfinite(sp)]
    return (float(np.median(sp)), "the owner's nights") if len(sp) else None


def analyse(rows: pd.DataFrame, fit: dict | None = None, *, setpoint_c: float | None = None,
            margin_k: float = DEFAULT_MARGIN_K, source: str | Path = "NIGHTS",
            seed: int = 0) -> CurveResult:
    """The curve result of a house (:mod:`impctl.curve`).

    Parameters
    ----------
    rows : :func:`impctl.curve.data.rows.read_rows`'s table.
    fit : an ``impctl fit --json`` result (its ``lumped.hlc`` and ``fit.night_gain``), or None.
    setpoint_c : the owner's room setpoint [°C]; None: from the owner's rows, else assumed.
    margin_k : kelvin added above the bound [K].
    source : the file, for messages.
    seed : the draws' seed (the same inputs give the same result).

    Raises
    ------
    InputError
        The rows do not hold what the curve is worked out from (one line: what is missing).
    """
    rng = np.random.default_rng(seed)
    notes: list[str] = []
    blocks = steady_blocks(rows)
    try:
        emitter = fit_emitter(blocks)
        need = heat_need(blocks, fit)
    except (EmitterUnknown, NeedUnknown) as exc:
        raise InputError(str(exc), source) from None
    if setpoint_c is not None:
        sp, sp_source = float(setpoint_c), "given"
    elif (own := owner_setpoint(rows)) is not None:
        sp, sp_source = own
    else:
        sp, sp_source = ASSUMED_SETPOINT_C, "assumed"
        notes.append(f"the owner's setpoint is not in the file: {sp:g} °C assumed "
                     "(--setpoint-c sets it)")
    if need.gain_source == "fit":
        notes.append("no steady night with the heating on: the heat need rests on the fit's "
                     "heat loss and night gain alone")
    elif not blocks["night"].astype(bool).any():
        notes.append("no steady block inside 22:00–06:00: the heat need is read from daytime "
                     "blocks, whose sun and occupants make it read low")
    climate = winter_climate(rows)
    curve = need_curve(need, emitter, sp, rng)
    anchor = need.anchor_t_out_c if need.anchor_t_out_c is not None else 0.0
    recommended = recommend(curve, margin_k, climate.weights(need, sp), sp, climate.cold_c(),
                            anchor)
    slope = (recommended.flow_b_c - recommended.flow_a_c) / 30.0
    running = running_curve(rows, sp, slope)
    if not writable(recommended, running.line if running is not None else None):
        hi = FLOW_LIMITS_C[1]
        notes.append(f"this house needs a curve above the {hi:g} °C impctl writes, and above "
                     f"the curve the heat pump runs ({recommended.flow_a_c:.0f} °C at −15 °C "
                     "outside): advice only, impctl does not set it")
    if running is None:
        notes.append("no flow target (t_flow_c, t_flow_target_c) recorded on enough heated "
                     "hours: the curve the heat pump runs is unknown, so is the saving")
    elif not running.slope_read:
        lo, hi = running.t_out_range_c
        notes.append(f"the running curve was seen only at {lo:.0f}…{hi:.0f} °C outside: its "
                     "level is read, its slope assumed to be the recommended one")
    cop = fit_cop(blocks)
    if cop.assumed:
        notes.append(f"the heat pump's electricity (p_el_w) is not recorded: its efficiency is "
                     f"ASSUMED ({cop.eta:.2f} of the ideal), so is the saving in kWh")
    cold, total, excess = _room_hours(rows, sp)
    savings = (season_savings(need, cop, running.line, recommended, climate, sp, rng,
                              room_excess_k=excess,
                              need_at_anchor_c=float(np.interp(anchor, curve.t_out_c,
                                                               curve.central_c)))
               if running is not None else None)
    if climate.source == "assumed":
        notes.append("the saving is over an ASSUMED winter (the file spans less than a "
                     "season of outdoor temperatures)")
    return CurveResult(sp, sp_source, float(margin_k), emitter, need, curve, recommended,
                       running, cop, climate, savings, notes, cold, total)


def _room_hours(rows: pd.DataFrame, setpoint_c: float) -> tuple[int, int, float]:
    """Of the heated hours at the owner's setpoint: those with the room ≥ :data:`COLD_K`
    below it, all of them, and the room's mean above the setpoint over them [K] (0 without
    any)."""
    on = heated(rows)
    sp = rows["setpoint"].to_numpy(dtype=float)
    own = on & ((rows["kind"] == "owner").to_numpy()
                | (np.isfinite(sp) & (np.abs(sp - setpoint_c) <= 0.25)))
    hours = hourly(rows, "t_air", own)
    if hours.empty:
        return 0, 0, 0.0
    room = hours["value"].to_numpy(dtype=float)
    cold = room < setpoint_c - COLD_K
    return int(cold.sum()), int(len(hours)), float(np.mean(room) - setpoint_c)
