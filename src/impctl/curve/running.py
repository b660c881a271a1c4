"""The curve the heat pump actually runs, read from its own target over the season.

``t_flow_target_c`` (Kronoterm 2128, the loop-1 calculated flow target) against the outdoor
temperature, hour by hour while the heating is on, at the owner's setpoint: a Theil–Sen line
(robust to the hours a schedule, an offset or a defrost moved the target). Hours at another
setpoint (the campaign's held nights) are used only when the owner's are too few, each moved
back to the owner's setpoint as a curve moves (along and up: Δθ_set·(1 − slope)).

Without the target column the line is read from the measured flow temperature while the heat
pump delivers heat, and labelled so: a flow that cycles around its target reads a little
below it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..imp.features import Q_ON_W
from .data.blocks import heated, hourly
from .need import Line

#: Fewest hours the running curve is read from.
MIN_HOURS = 6
#: Narrowest outdoor range [K] over which the slope is read; narrower: only the level.
MIN_RANGE_K = 3.0
#: Setpoints within this of the owner's count as the owner's [K].
SAME_SETPOINT_K = 0.25
#: A read line rising less than this from +15 to −15 °C is a constant flow, not a curve [K].
FLAT_K = 3.0


@dataclass(frozen=True)
class RunningCurve:
    """The running curve as a :class:`~impctl.curve.need.Line`, where it was read from
    (``"target"``: the heat pump's flow target; ``"flow"``: the measured flow), its hours, the
    outdoor range they span [°C], and whether the slope was read (else the recommended
    slope was assumed through the level)."""

    line: Line
    source: str
    hours: int
    t_out_range_c: tuple[float, float]
    slope_read: bool

    @property
    def constant(self) -> bool:
        """The heat pump holds one flow temperature whatever the weather (its slope read, and
        less than :data:`FLAT_K` over the curve's two points)."""
        return self.slope_read and self.line.flow_a_c - self.line.flow_b_c < FLAT_K

    def to_dict(self) -> dict:
        """The JSON block ``running``."""
        out = self.line.to_dict()
        out.update({"source": self.source, "hours": self.hours,
                    "t_out_range_c": [round(v, 1) for v in self.t_out_range_c],
                    "slope_read": self.slope_read, "constant": self.constant})
        return out


def running_curve(rows: pd.DataFrame, setpoint_c: float,
                  fallback_slope_k_per_k: float) -> RunningCurve | None:
    """The running curve (module docstring), or None when fewer than :data:`MIN_HOURS` hours
    carry a target or a flow temperature. ``fallback_slope_k_per_k``: the slope [K/K] assumed
    when the hours span less than :data:`MIN_RANGE_K`."""
    on = heated(rows)
    source = "target"
    hours = hourly(rows, "t_flow_target_c", on)
    if len(hours) < MIN_HOURS:
        source = "flow"
        running = on & (rows["q_hc"].to_numpy(dtype=float) > Q_ON_W)
        hours = hourly(rows, "t_flow_c", running)
        if len(hours) < MIN_HOURS:
            return None
    sp = hours["setpoint_c"].to_numpy(dtype=float)
    own = ~np.isfinite(sp) | (np.abs(sp - setpoint_c) <= SAME_SETPOINT_K)
    if own.sum() >= MIN_HOURS:
        hours, shift = hours[own], np.zeros(int(own.sum()))
    else:
        shift = np.nan_to_num(sp - setpoint_c)
    t = hours["t_out_c"].to_numpy(dtype=float)
    v = hours["value"].to_numpy(dtype=float)
    lo, hi = float(t.min()), float(t.max())
    slope = _slope(t - shift, v - shift) if hi - lo >= MIN_RANGE_K else None
    slope_read = slope is not None
    if slope is None:
        slope = fallback_slope_k_per_k
    # With the slope, the level: the median of what each hour says the line is at 0 °C,
    # each hour brought back to the owner's setpoint along the curve.
    at0 = float(np.median(v - shift * (1.0 - slope) - slope * t))
    line = Line(at0 + slope * -15.0, at0 + slope * 15.0)
    return RunningCurve(line, source, int(len(hours)), (lo, hi), slope_read)


#: Most points the Theil–Sen slope compares pairwise (evenly thinned beyond).
_MAX_POINTS = 600


def _slope(t: np.ndarray, v: np.ndarray) -> float:
    """Theil–Sen slope [K/K]: the median of the slopes between every two points."""
    keep = np.linspace(0, len(t) - 1, min(len(t), _MAX_POINTS)).astype(int)
    t, v = t[keep], v[keep]
    i, j = np.triu_indices(len(t), k=1)
    dt = t[j] - t[i]
    ok = np.abs(dt) > 1e-9
    return float(np.median((v[j] - v[i])[ok] / dt[ok]))
