"""The owner's nights as the change test's rows: one row per usable night.

The change test (:mod:`.glr`) reads the owner records (kind ``owner``, one per local day, noon
to noon), keeps the usable nights (no label: not a night the owner changed the setpoint,
switched the heating off or was away; no hot-water charge from 23:00 to 05:00; the window's
rows recorded) and takes one row per night over :data:`WINDOW_H` (00:00–05:00: no sun, the
household asleep):

* ``q_w`` — the mean heat read by the meter [W];
* ``dt_k`` — the mean T_air − T_out [K];
* ``fall_k`` — how far the room fell over the window [K] (heat the air, furniture and mass give
  back: a setback night);
* ``memory_k`` — the evening's mean T_air − T_out less the night's [K] (the mass still warm from
  a mild day, or cold from a cold one: the turn of a cold spell);
* ``defrost`` — the share of the window the heat pump defrosted [-] (the meter reads a defrost
  as no heat).

Units in the names.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..imp.night import NightSamples

#: The night window: local hours after midnight [h].
WINDOW_H = (0.0, 5.0)
#: Time constants of the house's memory of the days before [h] (module docstring).
MEMORY_H = (12.0, 48.0, 168.0)
#: A night is used with at least this share of its window's 5-min rows recorded [-].
MIN_ROWS_SHARE = 0.9
#: A night is used when its heat is at least this share of the house's median night [-]
#: (below it the heating hardly ran: a deep setback coasting, nothing to compare).
MIN_HEAT_SHARE = 0.25
#: Hot water from this hour of the evening on spoils the night [h before midnight].
DHW_BEFORE_H = 1.0
#: A hot-water row: this share of its interval or more [-].
DHW_SHARE = 0.05


@dataclass(frozen=True)
class NightRows:
    """One row per usable owner night (module docstring), arrays in night order."""

    dates: list[str]
    q_w: np.ndarray
    dt_k: np.ndarray
    fall_k: np.ndarray
    defrost: np.ndarray
    memory_k: np.ndarray
    p_house_w: np.ndarray

    def __len__(self) -> int:
        return len(self.dates)

    @property
    def has_house_electricity(self) -> bool:
        """Every night carries the household electricity (it is then a regressor)."""
        return bool(len(self) and np.isfinite(self.p_house_w).all())

    def design(self) -> np.ndarray:
        """The regressors without the step: 1, dt, fall, defrost, the memories, and the
        household electricity where every night has it (the internal gains as they wander)."""
        cols = [np.ones(len(self)), self.dt_k, self.fall_k, self.defrost, self.memory_k]
        if self.has_house_electricity:
            cols.append(self.p_house_w)
        return np.column_stack(cols)

    def head(self, n: int) -> NightRows:
        """The first ``n`` nights."""
        return NightRows(self.dates[:n], self.q_w[:n], self.dt_k[:n], self.fall_k[:n],
                         self.defrost[:n], self.memory_k[:n], self.p_house_w[:n])


def _hourly(nights: Sequence[NightSamples]) -> tuple[float, np.ndarray]:
    """(epoch seconds of the first hour, hourly mean T_air − T_out [K], NaN where nothing was
    recorded) of every row of ``nights``, whatever their kind."""
    t, d = [], []
    for n in nights:
        ok = np.isfinite(n.t_air_c) & np.isfinite(n.t_out_c)
        t.append(pd.Timestamp(n.start).timestamp() + np.asarray(n.time_s, float)[ok])
        d.append(np.asarray(n.t_air_c, float)[ok] - np.asarray(n.t_out_c, float)[ok])
    ta, da = np.concatenate(t), np.concatenate(d)
    t0 = math.floor(ta.min() / 3600.0) * 3600.0
    k = ((ta - t0) // 3600.0).astype(int)
    cnt = np.bincount(k)
    with np.errstate(invalid="ignore"):
        return t0, np.bincount(k, da) / np.where(cnt > 0, cnt, np.nan)


def _memory(hourly: np.ndarray, tau_h: float) -> np.ndarray:
    """Exponential mean of ``hourly`` with time constant ``tau_h`` [h] at the end of each
    hour, over the hours recorded (a gap carries no weight)."""
    from scipy.signal import lfilter

    a = math.exp(-1.0 / tau_h)
    recorded = np.isfinite(hourly)
    # the recorded hours' weighted sum and their weight, both decaying by a per hour
    s = lfilter([1.0 - a], [1.0, -a], np.where(recorded, hourly, 0.0))
    w = lfilter([1.0 - a], [1.0, -a], recorded.astype(float))
    return np.where(w > 0, s / np.where(w > 0, w, 1.0), math.nan)


def night_rows(nights: Sequence[NightSamples]) -> NightRows:
    """The usable owner nights of ``nights`` as rows (module docstring), in night order."""
    rows: list[tuple] = []
    per_window = int(round((WINDOW_H[1] - WINDOW_H[0]) * 12))
    owner = [n for n in nights if n.kind == "owner" and not n.label and len(n.time_s) >= 2]
    if not owner:
        return _no_rows()
    t0, hourly = _hourly(nights)
    memories = [_memory(hourly, tau) for tau in MEMORY_H]
    # the nights' local days and midnights at once (per night, the timestamps' arithmetic was
    # most of the rows' cost)
    starts = pd.DatetimeIndex([pd.Timestamp(n.start) for n in owner])
    days = (starts - pd.Timedelta(hours=12)).normalize()
    midnights = days + pd.Timedelta(days=1)
    into = (starts - midnights).total_seconds().to_numpy()
    midnight_s = [m.timestamp() for m in midnights]
    dates = [str(d.date()) for d in days]
    for n, into_s, midnight_at, date in zip(owner, into, midnight_s, dates, strict=True):
        h = (into_s + np.asarray(n.time_s, float)) / 3600.0
        ok = np.isfinite(n.t_air_c) & np.isfinite(n.t_out_c) & np.isfinite(n.q_hc_w)
        win = ok & (h >= WINDOW_H[0]) & (h < WINDOW_H[1])
        if win.sum() < MIN_ROWS_SHARE * per_window:
            continue
        ta, to, q = (np.asarray(x, float) for x in (n.t_air_c, n.t_out_c, n.q_hc_w))
        if n.dhw is not None:
            hot = np.asarray(n.dhw, float) > DHW_SHARE
            if WINDOW_H[1] - WINDOW_H[0] < 12:
                if (hot & (h >= WINDOW_H[0] - DHW_BEFORE_H) & (h < WINDOW_H[1])).any():
                    continue
            else:
                # Over a whole day the space heat a charge pauses is made up after it: the
                # meter's reading during the charge (the tank's, or nothing) is no space heat.
                q = np.where(hot, 0.0, q)
        dt = float(np.mean(ta[win] - to[win]))
        first = win & (h < WINDOW_H[0] + 0.5)
        last = win & (h >= WINDOW_H[1] - 0.5)
        if not first.any() or not last.any():
            continue
        fall = float(np.mean(ta[first]) - np.mean(ta[last]))
        # the hour ending at the window's start
        at = int((midnight_at + WINDOW_H[0] * 3600 - t0) // 3600.0) - 1
        if not 0 <= at < len(hourly):
            continue
        mem = [float(m[at]) - dt for m in memories]
        if not all(math.isfinite(x) for x in mem):
            continue
        defrost = (float(np.nanmean(np.asarray(n.defrost_share, float)[win]))
                   if n.defrost_share is not None else 0.0)
        rows.append((date, float(np.mean(q[win])), dt, fall, defrost, mem,
                     float(n.p_house_w)))
    rows.sort(key=lambda r: r[0])
    if rows:
        typical = float(np.median([r[1] for r in rows]))
        rows = [r for r in rows if r[1] > MIN_HEAT_SHARE * typical and r[1] > 0]
    if not rows:
        return _no_rows()
    return NightRows([r[0] for r in rows], *(np.array([r[i] for r in rows], float)
                                             for i in range(1, 7)))


def _no_rows() -> NightRows:
    z = np.zeros(0)
    return NightRows([], z, z, z, z, np.zeros((0, len(MEMORY_H))), z)
