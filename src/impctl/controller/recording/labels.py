"""When an owner record's night is not the owner's ordinary night, and why: its labels.

An owner record covers a local day from noon to noon; what it is labelled for is judged on its
night part, the configured window (22:00–05:00: 7 h, 6 h or 8 h on the nights the clocks
change). Each label is ``"key: detail"``; a record without a label is valid. Labelled records
are kept and exported with their labels: the fit decides what to use.

* ``owner changed the setpoint`` — the loop-1 setpoint (2187) or mode (2042) changed;
* ``hot water dominated`` — more than :data:`DHW_DOMINATED_SHARE` of the night charging hot
  water (working function 1);
* ``heating off`` — loop 1 (2042 = 0) or the heating system (2012 = 0) off;
* ``data missing`` — fewer than ``min_coverage`` of the night's rows (outside an IMP night)
  have the indoor and outdoor temperature and the heat;
* ``IMP night`` — an IMP night (pre-heat to restore) took part of the night: it is that
  night's own record;
* ``clock stepped`` — the system clock stepped while the record was open (noted when it
  happened).
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, date, datetime, timedelta
from zoneinfo import ZoneInfo

from ...store import Sample

#: Share of a night's time charging hot water above which the night is labelled: past it the
#: space heating is mostly pauses, and its heat says more of the tank than of the house.
DHW_DOMINATED_SHARE = 0.25


@dataclass(frozen=True)
class Span:
    """An IMP night's span [start, end) and its id."""

    night_id: int
    start: datetime
    end: datetime


def record_day(ts: datetime, tz: ZoneInfo) -> date:
    """The local date D whose owner record [D 12:00, D+1 12:00) holds ``ts``."""
    return (ts.astimezone(tz) - timedelta(hours=12)).date()


def _instant(day: date, minute: int, tz: ZoneInfo) -> datetime:
    # In UTC: Python subtracts and compares two datetimes of the same zone as wall times,
    # which makes a night across a change of the clocks 7 h instead of 6 or 8.
    local = datetime(day.year, day.month, day.day, minute // 60, minute % 60, tzinfo=tz)
    return local.astimezone(UTC)


def record_window(day: date, tz: ZoneInfo) -> tuple[datetime, datetime]:
    """[D 12:00, D+1 12:00) local as UTC instants (23, 24 or 25 h apart)."""
    return _instant(day, 720, tz), _instant(day + timedelta(days=1), 720, tz)


def night_part(day: date, tz: ZoneInfo, window_minutes: tuple[int, int]
               ) -> tuple[datetime, datetime]:
    """The night window that starts on the evening of ``day`` as UTC instants (a 22:00–05:00
    window lasts 6 or 8 h across a change of the clocks)."""
    s_min, e_min = window_minutes
    end_day = day + timedelta(days=1 if e_min <= s_min else 0)
    return _instant(day, s_min, tz), _instant(end_day, e_min, tz)


def _overlap_s(a: tuple[datetime, datetime], b: tuple[datetime, datetime]) -> float:
    return max(0.0, (min(a[1], b[1]) - max(a[0], b[0])).total_seconds())


def _changes(rows: Sequence[Sample], column: str) -> tuple[Sample, Sample] | None:
    """The first pair of rows whose ``column`` differs (missing values skipped), or None."""
    prev = None
    for row in rows:
        value = getattr(row, column)
        if value is None:
            continue
        if prev is not None and value != getattr(prev, column):
            return prev, row
        prev = row
    return None


def judge(rows: Sequence[Sample], part: tuple[datetime, datetime], *, interval_s: float,
          min_coverage: float, imp_spans: Sequence[Span], tz: ZoneInfo) -> list[str]:
    """The labels of a record whose rows are ``rows`` (time order) and whose night part is
    ``part``; [] when its night is the owner's ordinary night."""
    def at(ts: datetime) -> str:
        return f"{ts.astimezone(tz):%H:%M}"

    labels = []
    inside = [r for r in rows if part[0] <= r.ts < part[1]]
    taken = [s for s in imp_spans if _overlap_s((s.start, s.end), part) > 0]
    for s in taken:
        labels.append(f"IMP night: night {s.night_id} ran {at(s.start)}–{at(s.end)}")
    changed = _changes(inside, "setpoint_c")
    if changed is not None:
        a, b = changed
        labels.append(f"owner changed the setpoint: 2187 {a.setpoint_c:.1f} → "
                      f"{b.setpoint_c:.1f} °C at {at(b.ts)}")
    changed = _changes(inside, "loop_mode")
    if changed is not None:
        a, b = changed
        labels.append(f"owner changed the setpoint: loop-1 mode (2042) {a.loop_mode} → "
                      f"{b.loop_mode} at {at(b.ts)}")
    off = next((r for r in inside if r.loop_mode == 0 or r.system_on == 0), None)
    if off is not None:
        what = "loop 1 off (2042 = 0)" if off.loop_mode == 0 else "heating system off (2012 = 0)"
        labels.append(f"heating off: {what} at {at(off.ts)}")
    shares = [r.dhw_share for r in inside if r.dhw_share is not None]
    if shares and statistics.fmean(shares) > DHW_DOMINATED_SHARE:
        labels.append(f"hot water dominated: {100 * statistics.fmean(shares):.0f} % of the night "
                      f"charging hot water (more than {100 * DHW_DOMINATED_SHARE:.0f} %)")
    free_s = (part[1] - part[0]).total_seconds() - sum(
        _overlap_s((s.start, s.end), part) for s in taken)
    expected = free_s / interval_s
    if expected >= 1:
        spans = [(s.start, s.end) for s in taken]
        good = sum(1 for r in inside
                   if r.t_air_c is not None and r.t_out_c is not None and r.q_hc_w is not None
                   and not any(a <= r.ts < b for a, b in spans))
        share = min(1.0, good / expected)
        if share < min_coverage:
            labels.append(f"data missing: {100 * share:.0f} % of the night's rows "
                          f"({at(part[0])}–{at(part[1])}) have T_air, T_out and Q_HC (less "
                          f"than {100 * min_coverage:.0f} %)")
    return labels


def night_setpoint(rows: Sequence[Sample], part: tuple[datetime, datetime]) -> float | None:
    """The owner's loop-1 setpoint at night [°C]: the median of the night part's rows, else of
    the record's, None when never read."""
    inside = [r.setpoint_c for r in rows if part[0] <= r.ts < part[1] and r.setpoint_c is not None]
    values = inside or [r.setpoint_c for r in rows if r.setpoint_c is not None]
    return float(statistics.median(values)) if values else None
