"""The heat a defrost draws from the heating water, read from the flow–return spread.

A defrost runs the heat pump backwards: it takes heat out of the heating water to melt the ice
on its outdoor coil. A heat meter that integrates positive heat only reads nothing then, and
the season model would have to fit the draw — a draw that trades with the HLC, because the heat
pump defrosts most on cold days. The heat pump's own flow and return sensors still see it: the
water leaves colder than it came back. The heat is Q = ṁc·(spread − offset) (the heat
meter's own formula), and :func:`read_draw` puts it on the record's defrost steps:

* the offset of the sensor pair [K] is the median spread of the steps with no heat read
  (|Q| < :data:`~impctl.imp.protocol.Q_ON_W`), no defrost and no hot water: water that runs
  through the heat pump unheated has no spread;
* ṁc [W/K] is read from the steps of heating within :data:`LOCAL_S` of each defrost, the sum
  of their heat over the sum of their spread less the offset — on the meter's own scale, its
  gain error included, and following a circulation pump whose flow changes from day to day;
  the season's own ratio where fewer than :data:`MIN_LOCAL` such steps are near;
* each defrost step's heat is ṁc·(spread − offset): the step's signed mean, its heating and
  its draw together — and so is the heat of the steps within :data:`AFTER_S` after one, where
  a flow or return sensor that lags (a sensor in a pocket or clamped on the pipe) still shows
  part of the draw the meter's step does not hold.

Nothing is rebuilt where the meter reads the draws itself
(:meth:`~.record.SeasonRecord.meter_reads_defrosts`), where the record has no spread, where too
few steps tell the offset or ṁc (:data:`MIN_STEPS`), or where the spread does not follow the
meter's heat on the steps of heating (:data:`MIN_AGREEMENT`: a sensor fallen off its pipe, two
sensors swapped): the draw is then fitted, an estimate.
A defrost step without a spread reading is then left missing, not kept as a reading without its
draw. Units: W, K, s.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..imp.protocol import Q_ON_W
from .record import SeasonRecord, exclude_after

#: Steps of heating around a defrost ṁc is read from: this far either side [s].
LOCAL_S = 3 * 3600.0
#: After a defrost, steps read from the spread as well: a lagging sensor's tail of the draw
#: [s]. On the bench a 2-min lag of both sensors took the HLC's P90 from 9.6 to 14.7 % with
#: the defrost steps alone, back to 9.9 % with the steps after them (decision record 0041).
AFTER_S = 600.0
#: Fewest steps of heating near a defrost for a local ṁc; else the season's.
MIN_LOCAL = 3
#: Fewest steps without heat (the offset) and with heating (ṁc) in the whole record.
MIN_STEPS = 12
#: A step counts as heating from this heat [W] and this spread above the offset [K]: a small
#: spread divides into noise.
HEAT_MIN_W = 3 * Q_ON_W
MIN_SPREAD_K = 0.5
#: Least correlation of the heating steps' heat with their spread for the spread to be read
#: [-]. The realistic plant gives 0.56–0.95 (median 0.82; 40 households, seed 4444: cycling,
#: the sensors' lag and offsets, a wandering flow); a spread that does not track the heat, ~0.
MIN_AGREEMENT = 0.3


def read_draw(rec: SeasonRecord) -> SeasonRecord:
    """``rec`` with its defrost steps' heat read from the flow–return spread (module
    docstring) where its meter reads positive heat only; ``rec`` itself where the meter reads
    the draw or nothing defrosted; ``rec`` with only :attr:`~.record.SeasonRecord.spread_unread`
    set where the spread does not tell it."""
    if rec.meter_reads_defrosts() is not False:
        return rec
    if len(rec.t_spread_k) != rec.n:
        return replace(rec, spread_unread="no flow and return temperatures recorded")
    few = "too few steps with and without heat to read the flow–return spread from"
    q, spread = rec.q_hc_w, rec.t_spread_k
    on = exclude_after(rec.defrost > 0, int(AFTER_S // rec.step_s))
    # hot-water steps are excluded already; their spread is the tank's circuit
    plain = ~on & (rec.excluded != "hot water") & np.isfinite(q) & np.isfinite(spread)
    idle = plain & (np.abs(q) < Q_ON_W)
    if idle.sum() < MIN_STEPS:
        return replace(rec, spread_unread=few)
    offset = float(np.median(spread[idle]))
    x = spread - offset
    heat = plain & (q >= HEAT_MIN_W) & (x >= MIN_SPREAD_K)
    if heat.sum() < MIN_STEPS:
        return replace(rec, spread_unread=few)
    r = float(np.corrcoef(q[heat], x[heat])[0, 1])
    if not r >= MIN_AGREEMENT:
        return replace(rec, spread_unread=f"the flow–return spread does not follow the meter's "
                                          f"heat (correlation {r:.2f} < {MIN_AGREEMENT})")
    # sums of the heating steps' heat and spread within LOCAL_S of every step
    reach = int(LOCAL_S // rec.step_s)
    cum = [np.r_[0.0, np.cumsum(np.where(heat, v, 0.0))] for v in (q, x, np.ones(rec.n))]
    idx = np.flatnonzero(on)
    lo, hi = np.maximum(idx - reach, 0), np.minimum(idx + reach + 1, rec.n)
    q_near, x_near, n_near = (c[hi] - c[lo] for c in cum)
    season = float(q[heat].sum() / x[heat].sum())
    mdot_c = np.where(n_near >= MIN_LOCAL, q_near / np.where(x_near > 0, x_near, 1.0), season)
    out = q.copy()
    # without a spread reading the step's heat is unknown: missing (NaN), never the meter's 0
    out[idx] = mdot_c * x[idx]
    return replace(rec, q_hc_w=out, defrost_from_spread=True)
