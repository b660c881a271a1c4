"""Gaps inside a night: found, reported, and the night cut so that nothing is bridged.

A *gap* is a step between two consecutive samples longer than :data:`GAP_FACTOR` × the night's
median sampling step and longer than :data:`MIN_GAP_S` (so one lost sample of 5- or 15-minute
data is no gap, two lost hours of hourly data are). Across a gap the heat output and the
temperatures are unknown: bridging it would stretch the power before the gap over the whole
gap (a 3-hour gap in a 7-hour normal night nearly doubles its energy) and let the heating
switch back on unseen on a constrained night. The rule:

* a **constrained** night keeps only the samples before its first gap (after the gap nobody
  knows whether the heating stayed off); gaps that end within the emission lag (samples the
  fit drops anyway) are ignored;
* a **normal** night keeps its longest gap-free piece;
* the fit then drops the night if that piece is shorter than its minimum night length
  (3 h), as any short night.

Every gap is reported (:class:`Gap`), by ``impctl fit`` in its table and JSON (``gaps``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .night import NightSamples

#: A step longer than this many median steps is a gap …
GAP_FACTOR = 2.0
#: … and longer than this [s].
MIN_GAP_S = 1800.0


@dataclass(frozen=True)
class Gap:
    """One gap of a night and what was kept (times in s since the night's start)."""

    night_id: str
    kind: str
    start_s: float
    end_s: float
    kept_from_s: float
    kept_to_s: float

    @property
    def hours(self) -> float:
        """Length of the gap [h]."""
        return (self.end_s - self.start_s) / 3600.0

    def describe(self) -> str:
        def hm(s: float) -> str:
            return f"{s / 3600.0:.1f} h"

        return (f"{self.kind} night {self.night_id}: no samples for {self.hours:.1f} h "
                f"({hm(self.start_s)}–{hm(self.end_s)} after the window start); kept "
                f"{hm(self.kept_from_s)}–{hm(self.kept_to_s)}")

    def as_dict(self) -> dict:
        return {**dataclasses.asdict(self), "hours": self.hours}


def gap_indices(time_s: np.ndarray) -> np.ndarray:
    """Indices i where the step time_s[i] → time_s[i+1] is a gap (see the module docstring)."""
    t = np.asarray(time_s, float)
    if len(t) < 3:
        return np.array([], dtype=int)
    steps = np.diff(t)
    limit = max(GAP_FACTOR * float(np.median(steps)), MIN_GAP_S)
    return np.flatnonzero(steps > limit)


def cut_at_gaps(nights: Sequence[NightSamples], emission_lag_h: float = 1.0
                ) -> tuple[list[NightSamples], list[Gap]]:
    """Cut every night to one gap-free piece (rule in the module docstring).

    Returns
    -------
    nights : the nights, those with gaps cut (the others unchanged, in the same order)
    gaps : every gap found, with the piece that was kept
    """
    out: list[NightSamples] = []
    found: list[Gap] = []
    for night in nights:
        t = np.asarray(night.time_s, float)
        idx = gap_indices(t)
        if night.kind == "constrained":
            idx = idx[t[np.minimum(idx + 1, len(t) - 1)] > emission_lag_h * 3600.0]
        if not len(idx):
            out.append(night)
            continue
        edges = np.concatenate([[0], idx + 1, [len(t)]])
        pieces = list(zip(edges[:-1], edges[1:], strict=True))
        if night.kind == "constrained":
            lo, hi = pieces[0]
        else:
            lo, hi = max(pieces, key=lambda p: t[p[1] - 1] - t[p[0]])
        for i in idx:
            found.append(Gap(night.night_id, night.kind, float(t[i]), float(t[i + 1]),
                             float(t[lo]), float(t[hi - 1])))
        sl = slice(int(lo), int(hi))
        out.append(dataclasses.replace(
            night, time_s=t[sl], t_air_c=np.asarray(night.t_air_c)[sl],
            t_out_c=np.asarray(night.t_out_c)[sl], q_hc_w=np.asarray(night.q_hc_w)[sl]))
    return out, found
