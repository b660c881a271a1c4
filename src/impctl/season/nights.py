"""A household's nights (NIGHTS.csv, the store's export) as one season record.

Every row the gateway logged — the owner's days and nights (kind ``owner``), the constrained
and the normal IMP nights — goes onto one regular grid (:class:`~.record.SeasonRecord`): the
means of the samples whose time falls in each step. The grid is 5 min, or the next whole part
of the likelihood's 30-min block (10, 15, 30 min) at or above the rows' own interval, so that
every step of a gateway sampling every 10 min holds a reading. What the season model leaves out, and
why, is said per step:

* a hot-water charge and the hour after it (the meter may read the tank; the emitter refills);
* a record whose clock stepped (its rows' times are not to be trusted);
* the first half hour of each stretch without gaps (the model's filters start there).

An owner's changed setpoint, a night with the heating off and an IMP night's own steps stay in:
the model is driven by the measured room temperature, whatever moved it. Where the meter reads
positive heat only, the defrost steps' heat is read from the flow–return spread
(:mod:`.defrost`). Units: °C, W, s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from ..imp.night import NightSamples
from .defrost import read_draw
from .record import BLOCK_S, STEP_S, SeasonRecord, exclude_after

#: After a hot-water charge the emitter refills: steps left out [s].
DHW_AFTER_S = 3600.0
#: The first hours of each gap-free stretch, while the heat store settles [s].
SETTLE_S = 1800.0
#: A row counts as a hot-water charge from this share of its time on [-].
DHW_SHARE = 0.05
#: The record's possible steps: whole parts of the likelihood's block [s].
GRID_STEPS_S = (STEP_S, 600.0, 900.0, BLOCK_S)
#: Labels whose record the model does not read at all.
DROP_LABELS = ("clock stepped",)


def grid_step_s(nights: Sequence[NightSamples]) -> float:
    """The record's step for these rows [s]: :data:`~.record.STEP_S`, or the smallest of
    :data:`GRID_STEPS_S` at or above the rows' median interval."""
    gaps = np.concatenate([np.diff(np.asarray(n.time_s, float)) for n in nights])
    gaps = gaps[gaps > 0]
    if not len(gaps):
        return STEP_S
    row_s = float(np.median(gaps))
    return next((s for s in GRID_STEPS_S if s >= row_s * 0.99), GRID_STEPS_S[-1])


def record_from_nights(nights: Sequence[NightSamples],
                       step_s: float | None = None) -> SeasonRecord:
    """The season record of ``nights`` (module docstring) on a grid of ``step_s`` [s]
    (default: :func:`grid_step_s`); raises ValueError with no samples."""
    if not nights:
        raise ValueError("no nights")
    if step_s is None:
        step_s = grid_step_s(nights)
    tz = nights[0].start.tz
    t_abs = [pd.Timestamp(n.start).timestamp() + np.asarray(n.time_s, float) for n in nights]
    # the grid starts on a block boundary (:00 or :30): the gains switch at whole hours
    t0 = float(np.floor(min(t[0] for t in t_abs) / BLOCK_S) * BLOCK_S)
    t1 = max(t[-1] for t in t_abs)
    n_steps = int((t1 - t0) // step_s) + 1
    # IMP nights last, so where a record and an IMP night overlap the IMP night's rows win.
    ordered = sorted(range(len(nights)), key=lambda i: nights[i].kind != "owner")
    ns = [nights[i] for i in ordered]
    # every night's rows at once, in that order (a night without a series: NaN rows); each
    # sum binned once — per night and field, the record cost a fleet's morning 7 %
    k = ((np.concatenate([t_abs[i] for i in ordered]) - t0) // step_s).astype(int)

    def rows(field: str) -> np.ndarray:
        return np.concatenate([np.full(len(n.time_s), np.nan) if getattr(n, field) is None
                               else np.asarray(getattr(n, field), float) for n in ns])

    t_air_r, t_out_r, q_r = rows("t_air_c"), rows("t_out_c"), rows("q_hc_w")
    ok = np.isfinite(t_air_r) & np.isfinite(t_out_r) & np.isfinite(q_r)

    def flow_and_return(n: NightSamples, sign: float) -> np.ndarray:
        # flow + sign·return, NaN where the heat pump did not report both
        if n.t_flow_c is None or n.t_return_c is None:
            return np.full(len(n.time_s), np.nan)
        return np.asarray(n.t_flow_c, float) + sign * np.asarray(n.t_return_c, float)

    water_r = np.concatenate([flow_and_return(n, 1.0) for n in ns]) / 2.0
    spread_r = np.concatenate([flow_and_return(n, -1.0) for n in ns])
    # the household electricity: the rows' own readings (when in the day its heat falls),
    # else the night's one value on every row
    p_r = np.concatenate([
        (np.asarray(n.p_house_series_w, float) if n.p_house_series_w is not None
         else np.full(len(n.time_s), float(n.p_house_w))) if np.isfinite(n.p_house_w)
        else np.full(len(n.time_s), np.nan) for n in ns])

    def binned(values: np.ndarray | None, where: np.ndarray) -> np.ndarray:
        return np.bincount(k[where], None if values is None else values[where], n_steps) \
            .astype(float, copy=False)

    sums = {"t_air": binned(t_air_r, ok), "t_out": binned(t_out_r, ok),
            "q_hc": binned(q_r, ok), "n": binned(None, ok)}
    for name, count, x in (("defrost", "n_def", rows("defrost_share")),
                           ("dhw", "n_dhw", rows("dhw")), ("water", "n_w", water_r),
                           ("spread", "n_s", spread_r),
                           ("p_house", "n_p", p_r)):
        good = ok & np.isfinite(x)
        sums[name], sums[count] = binned(x, good), binned(None, good)
    # each step's night: the last one in that order to hold a row there
    night_of = np.repeat(np.arange(len(ns)), [len(n.time_s) for n in ns])
    steps, first_from_end = np.unique(k[::-1], return_index=True)
    owner = night_of[len(k) - 1 - first_from_end]
    kind = np.full(n_steps, "", dtype=object)
    night_id = np.full(n_steps, "", dtype=object)
    dropped = np.zeros(n_steps, bool)
    kind[steps] = np.array([n.kind for n in ns], dtype=object)[owner]
    night_id[steps] = np.array([n.night_id for n in ns], dtype=object)[owner]
    dropped[steps] = np.array([any(n.label.startswith(d) for d in DROP_LABELS)
                               for n in ns])[owner]
    with np.errstate(invalid="ignore", divide="ignore"):
        cnt = np.where(sums["n"] > 0, sums["n"], np.nan)
        t_air, t_out, q_hc = (sums[k] / cnt for k in ("t_air", "t_out", "q_hc"))
        defrost = np.where(sums["n_def"] > 0, sums["defrost"] / sums["n_def"], 0.0)
        dhw = np.where(sums["n_dhw"] > 0, sums["dhw"] / sums["n_dhw"], 0.0)
        p_house = np.where(sums["n_p"] > 0, sums["p_house"] / sums["n_p"], np.nan)
        water, spread = ((np.where(sums[c] > 0, sums[x] / sums[c], np.nan)
                          if sums[c].any() else np.zeros(0))
                         for x, c in (("water", "n_w"), ("spread", "n_s")))
    t_air[dropped] = t_out[dropped] = q_hc[dropped] = np.nan
    excluded = np.full(n_steps, "", dtype=object)
    excluded[exclude_after(dhw > DHW_SHARE, int(DHW_AFTER_S // step_s))] = "hot water"
    excluded[dropped] = "clock stepped"
    index = pd.date_range(pd.Timestamp(t0, unit="s", tz="UTC"), periods=n_steps,
                          freq=f"{int(step_s)}s").tz_convert(tz)
    # the local clock's hour and day from its integer seconds (as pandas' fields give them,
    # without building each field: a tenth of the record)
    local_s = index.tz_localize(None).as_unit("s").asi8
    of_day = local_s % 86400
    hour = (of_day // 3600 + (of_day % 3600 // 60) / 60.0) + step_s / 7200.0
    day = local_s // 86400 - local_s[0] // 86400
    if len(water):
        water[dropped] = spread[dropped] = np.nan
    rec = SeasonRecord(t0, step_s, hour, day, t_air, t_out, q_hc, defrost,
                       kind.astype(str), night_id, excluded, p_house, water, spread)
    _settle(rec, int(SETTLE_S // step_s))
    return read_draw(rec)


def _settle(rec: SeasonRecord, steps: int) -> None:
    """Leave out the first ``steps`` of every gap-free stretch (the heat store settles)."""
    seg = rec.segments()
    starts = np.flatnonzero((seg >= 0) & np.r_[True, seg[1:] != seg[:-1]])
    for s in starts:
        part = slice(s, s + steps)
        same = seg[part] == seg[s]
        idx = np.arange(part.start, min(part.stop, rec.n))[same[: min(steps, rec.n - s)]]
        rec.excluded[idx[rec.excluded[idx] == ""]] = "first hours (the heat store settles)"
