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
the model is driven by the measured room temperature, whatever moved it. Units: °C, W, s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from ..imp.night import NightSamples
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
    # each sum's steps and values over all nights, binned once at the end (a bin count of the
    # whole grid per night and field cost a season's record most of its time)
    parts: dict[str, tuple[list, list]] = {k: ([], []) for k in (
        "t_air", "t_out", "q_hc", "n", "defrost", "n_def", "dhw", "n_dhw", "water", "n_w",
        "p_house", "n_p")}

    def add(name: str, steps: np.ndarray, values: np.ndarray | None = None) -> None:
        parts[name][0].append(steps)
        parts[name][1].append(np.ones(len(steps)) if values is None else values)

    kind = np.full(n_steps, "", dtype=object)
    night_id = np.full(n_steps, "", dtype=object)
    dropped = np.zeros(n_steps, bool)
    # IMP nights last, so where a record and an IMP night overlap the IMP night's rows win.
    order = sorted(range(len(nights)), key=lambda i: nights[i].kind != "owner")
    for i in order:
        n, t = nights[i], t_abs[i]
        k = ((t - t0) // step_s).astype(int)
        ok = np.isfinite(n.t_air_c) & np.isfinite(n.t_out_c) & np.isfinite(n.q_hc_w)
        kk = k[ok]
        for name, x in (("t_air", n.t_air_c), ("t_out", n.t_out_c), ("q_hc", n.q_hc_w)):
            add(name, kk, np.asarray(x, float)[ok])
        add("n", kk)
        for name, x in (("defrost", n.defrost_share), ("dhw", n.dhw)):
            if x is not None:
                good = ok & np.isfinite(x)
                add(name, k[good], np.asarray(x, float)[good])
                add("n_" + ("def" if name == "defrost" else "dhw"), k[good])
        if n.t_flow_c is not None and n.t_return_c is not None:
            water = (np.asarray(n.t_flow_c, float) + np.asarray(n.t_return_c, float)) / 2.0
            good = ok & np.isfinite(water)
            add("water", k[good], water[good])
            add("n_w", k[good])
        if np.isfinite(n.p_house_w) and n.p_house_series_w is not None:
            # the rows' own readings: when in the day the household's heat falls
            p = np.asarray(n.p_house_series_w, float)
            good = ok & np.isfinite(p)
            add("p_house", k[good], p[good])
            add("n_p", k[good])
        elif np.isfinite(n.p_house_w):
            add("p_house", kk, np.full(len(kk), n.p_house_w))
            add("n_p", kk)
        span = np.unique(k)
        kind[span] = n.kind
        night_id[span] = n.night_id
        dropped[span] = any(n.label.startswith(d) for d in DROP_LABELS)
    sums = {name: (np.bincount(np.concatenate(st), np.concatenate(vs), n_steps) if st
                   else np.zeros(n_steps)) for name, (st, vs) in parts.items()}
    with np.errstate(invalid="ignore", divide="ignore"):
        cnt = np.where(sums["n"] > 0, sums["n"], np.nan)
        t_air, t_out, q_hc = (sums[k] / cnt for k in ("t_air", "t_out", "q_hc"))
        defrost = np.where(sums["n_def"] > 0, sums["defrost"] / sums["n_def"], 0.0)
        dhw = np.where(sums["n_dhw"] > 0, sums["dhw"] / sums["n_dhw"], 0.0)
        p_house = np.where(sums["n_p"] > 0, sums["p_house"] / sums["n_p"], np.nan)
        water = (np.where(sums["n_w"] > 0, sums["water"] / sums["n_w"], np.nan)
                 if sums["n_w"].any() else np.zeros(0))
    t_air[dropped] = t_out[dropped] = q_hc[dropped] = np.nan
    excluded = np.full(n_steps, "", dtype=object)
    excluded[exclude_after(dhw > DHW_SHARE, int(DHW_AFTER_S // step_s))] = "hot water"
    excluded[dropped] = "clock stepped"
    index = pd.date_range(pd.Timestamp(t0, unit="s", tz="UTC"), periods=n_steps,
                          freq=f"{int(step_s)}s").tz_convert(tz)
    hour = (index.hour + index.minute / 60.0).to_numpy() + step_s / 7200.0
    local_day = index.tz_localize(None).normalize()
    day = np.asarray((local_day - local_day[0]).days, dtype=np.int64)
    if len(water):
        water[dropped] = np.nan
    rec = SeasonRecord(t0, step_s, hour, day, t_air, t_out, q_hc, defrost,
                       kind.astype(str), night_id, excluded, p_house, water)
    _settle(rec, int(SETTLE_S // step_s))
    return rec


def _settle(rec: SeasonRecord, steps: int) -> None:
    """Leave out the first ``steps`` of every gap-free stretch (the heat store settles)."""
    seg = rec.segments()
    starts = np.flatnonzero((seg >= 0) & np.r_[True, seg[1:] != seg[:-1]])
    for s in starts:
        part = slice(s, s + steps)
        same = seg[part] == seg[s]
        idx = np.arange(part.start, min(part.stop, rec.n))[same[: min(steps, rec.n - s)]]
        rec.excluded[idx[rec.excluded[idx] == ""]] = "first hours (the heat store settles)"
