"""IMP night plans: what one night of the Identification Measurement Procedure does, and when.

A night is either

* ``constrained`` — the house is held at T_max = T_set + ΔT for ``preheat_h`` before the window,
  then the heating is switched off at the window start and the house cools until T_air reaches
  T_min = T_set − ΔT or the window ends (the paper's "constrained heating", §III-B b). The T_min
  test starts one emitter lag after switch-off: before that the air temperature is dominated by
  the emitters' transient (and, in the 5R1C model, by the massless air node's 2–5 K drop at
  switch-off, identifiability.md §11.2). With ``stop_at_t_min=False`` the house cools for the
  whole window, as in the paper's case study ("a preferred, predefined period of time");
* ``normal`` — the house is held at T_set from ``preheat_h`` before the window to its end and
  the heat output is logged (§III-B c); the early switch keeps the setpoint step out of the window.

Window times are local wall-clock times; the window's start and end are turned into absolute,
time-zone-aware instants, so a night across a DST change lasts 6 or 8 hours instead of 7.

The paper approximates the emitters (radiators, floor loops) as giving no heat from one hour after
the heating is switched off. :data:`EMISSION_LAG_H` is that hour; every consumer that cuts a
constrained night (features, the Neural-ODE fit) uses the same parameter.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

import pandas as pd

from ..errors import InputError
from .night import NightKind
from .protocol import (
    DEFAULT_BAND_K,
    DEFAULT_CONSTRAINED_SETPOINT_C,
    DEFAULT_PREHEAT_H,
    DEFAULT_SETPOINTS_C,
)

#: Emitter lag [h]: emitters give no heat from this long after switch-off (paper §III-A).
EMISSION_LAG_H = 1.0
# DEFAULT_BAND_K, DEFAULT_SETPOINTS_C, DEFAULT_CONSTRAINED_SETPOINT_C, DEFAULT_PREHEAT_H: the
# protocol's defaults live in impctl.imp.protocol (the daemon's config reads them without
# pandas); they are names of this module too.
#: Local window start and end (paper: 22:00–05:00, space heating only, no hot water).
DEFAULT_WINDOW = (dt.time(22, 0), dt.time(5, 0))

NIGHT_KINDS: tuple[NightKind, ...] = ("constrained", "normal")


def _localize(naive: pd.Timestamp, tz: str) -> pd.Timestamp:
    # A wall-clock time inside a DST gap moves forward to the first valid instant; in a fold the
    # first (summer-time) occurrence is taken, so a window never starts twice.
    return naive.tz_localize(tz, ambiguous=True, nonexistent="shift_forward")


@dataclass(frozen=True)
class NightPlan:
    """One IMP night: its kind, temperatures and local window.

    Parameters
    ----------
    kind : {"constrained", "normal"}
        Heating switched off in the window, or held at ``setpoint_c``.
    setpoint_c : float, default 23
        T_set [°C]; for constrained nights the centre of the comfort band.
    band_k : float, default 1.5
        Comfort band ΔT [K]: T_max = T_set + ΔT, T_min = T_set − ΔT.
    window_start, window_end : datetime.time, default 22:00 and 05:00
        Local wall-clock limits of the window; an end at or before the start is on the next day.
    preheat_h : float, default 2
        Time [h] before the window during which the house is held at the pre-window setpoint
        (T_max for constrained nights, T_set for normal nights).
    stop_at_t_min : bool, default True
        Constrained nights end when T_air ≤ T_min (tested from the emitter lag on); False: they
        cool until the window's end.

    Raises
    ------
    InputError
        Unknown kind, non-positive band or negative pre-heat time, equal window limits.
    """

    kind: NightKind
    setpoint_c: float = 23.0
    band_k: float = DEFAULT_BAND_K
    window_start: dt.time = DEFAULT_WINDOW[0]
    window_end: dt.time = DEFAULT_WINDOW[1]
    preheat_h: float = DEFAULT_PREHEAT_H
    stop_at_t_min: bool = True

    def __post_init__(self) -> None:
        if self.kind not in NIGHT_KINDS:
            raise InputError(f"kind must be 'constrained' or 'normal', got {self.kind!r}",
                             place="kind")
        if not self.band_k > 0:
            raise InputError(f"comfort band must be > 0 K, got {self.band_k}", place="band_k")
        if not self.preheat_h >= 0:
            raise InputError(f"pre-heat time must be >= 0 h, got {self.preheat_h}",
                             place="preheat_h")
        if self.window_start == self.window_end:
            raise InputError("window start and end are equal", place="window")

    @property
    def t_max_c(self) -> float:
        """T_max = T_set + ΔT [°C]: where a constrained night starts cooling."""
        return self.setpoint_c + self.band_k

    @property
    def t_min_c(self) -> float:
        """T_min = T_set − ΔT [°C]: where a constrained night ends (heating resumes)."""
        return self.setpoint_c - self.band_k

    @property
    def preheat_setpoint_c(self) -> float:
        """Setpoint [°C] held during the pre-heat before the window."""
        return self.t_max_c if self.kind == "constrained" else self.setpoint_c

    @property
    def window_setpoint_c(self) -> float:
        """Setpoint [°C] of the heating inside the window (after the emitter lag); NaN = off.

        Constrained nights with ``stop_at_t_min``: T_min — the heating stays off while
        T_air > T_min and holds T_min afterwards, which is where the experiment ends.
        """
        if self.kind == "normal":
            return self.setpoint_c
        return self.t_min_c if self.stop_at_t_min else float("nan")

    def window(self, date: dt.date | str, tz: str) -> tuple[pd.Timestamp, pd.Timestamp]:
        """Absolute start and end of the window that starts on local ``date``.

        Parameters
        ----------
        date : date or ISO string
            Local calendar date of the window start.
        tz : str
            IANA time zone of the house.

        Returns
        -------
        (start, end) : time-zone-aware Timestamps
        """
        day = pd.Timestamp(date).normalize()
        if day.tzinfo is not None:
            day = day.tz_localize(None)
        start = _localize(day + _offset(self.window_start), tz)
        end_day = day if self.window_end > self.window_start else day + pd.Timedelta(days=1)
        end = _localize(end_day + _offset(self.window_end), tz)
        return start, end

    def duration_h(self, date: dt.date | str, tz: str) -> float:
        """Window length [h] in absolute time (7 h normally, 6 or 8 h across a DST change)."""
        start, end = self.window(date, tz)
        return (end - start).total_seconds() / 3600.0

    def preheat_start(self, date: dt.date | str, tz: str) -> pd.Timestamp:
        """Absolute instant the pre-heat begins (``preheat_h`` before the window start)."""
        return self.window(date, tz)[0] - pd.Timedelta(hours=self.preheat_h)


def _offset(t: dt.time) -> pd.Timedelta:
    return pd.Timedelta(hours=t.hour, minutes=t.minute, seconds=t.second)


def imp_plans(
    setpoints_c: tuple[float, ...] = DEFAULT_SETPOINTS_C,
    band_k: float = DEFAULT_BAND_K,
    kinds: tuple[NightKind, ...] = NIGHT_KINDS,
    constrained_setpoint_c: float | None = DEFAULT_CONSTRAINED_SETPOINT_C,
    **plan_kw,
) -> list[NightPlan]:
    """The IMP's night plans, as the gateway's ``[campaign]`` runs them: one constrained plan at
    ``constrained_setpoint_c`` [°C] and a normal plan at each of ``setpoints_c`` [°C] (default
    1 + 3 = 4 plans); ``constrained_setpoint_c=None``: every kind at every setpoint.

    ``plan_kw`` (window_start, window_end, preheat_h, stop_at_t_min) go to every plan.
    """
    def at(kind: NightKind) -> tuple[float, ...]:
        if kind == "constrained" and constrained_setpoint_c is not None:
            return (constrained_setpoint_c,)
        return setpoints_c

    return [NightPlan(kind, float(sp), band_k, **plan_kw) for kind in kinds for sp in at(kind)]
