"""The store's ``house_inputs`` table: what the house's own sensors said at each sample (a mixin
of :class:`~impctl.store.Store`), and the outdoor-sensor check built on it.

A row belongs to a night's sample (same ``night_id`` and ``ts``) or, with ``night_id`` NULL, to
a reading between nights. Each value is stored with its age at that instant [s]; a value that
was stale or malformed is NULL, never a number.
"""

from __future__ import annotations

import sqlite3
import statistics
from dataclasses import asdict, dataclass
from datetime import datetime

from .._times import _dt, _iso

#: Offset between the heat pump's outdoor sensor and the reference that counts as an error [K].
T_OUT_OFFSET_LIMIT_K = 1.5
#: Evidence needed before an offset is called persistent: this many pairs over this span, and
#: this share of them on the offset's side (a passing shower or sun on one sensor is not).
T_OUT_MIN_PAIRS = 12
T_OUT_MIN_SPAN_H = 2.0
T_OUT_SAME_SIGN = 0.8


@dataclass(frozen=True)
class HouseInputRow:
    """One row of ``house_inputs`` (W, °C, persons; ages s; None = missing)."""

    night_id: int | None
    ts: datetime
    house_power_w: float | None = None
    house_power_age_s: float | None = None
    p_house_w: float | None = None
    t_rooms_c: float | None = None
    t_rooms_age_s: float | None = None
    rooms: int | None = None
    t_out_ref_c: float | None = None
    t_out_ref_age_s: float | None = None
    occupants: float | None = None
    occupants_age_s: float | None = None
    t_out_c: float | None = None


_COLUMNS = tuple(k for k in HouseInputRow.__dataclass_fields__ if k not in ("night_id", "ts"))


@dataclass(frozen=True)
class OutdoorOffset:
    """The heat pump's outdoor sensor against ``t_out_ref_c``.

    Attributes
    ----------
    offset_k : median of T_out(heat pump) − T_out(reference) [K]
    pairs : readings compared; span_h : hours they cover
    same_sign : share of the pairs on the side of the median
    persistent : enough evidence and ``|offset_k|`` > :data:`T_OUT_OFFSET_LIMIT_K`
    """

    offset_k: float
    pairs: int
    span_h: float
    same_sign: float
    persistent: bool

    def describe(self) -> str:
        """One line for ``impctl status`` and ``check-config``."""
        text = (f"heat pump's outdoor sensor {self.offset_k:+.1f} K against the reference "
                f"({self.pairs} readings over {self.span_h:.1f} h)")
        if self.persistent:
            return (text + f": a persistent offset over {T_OUT_OFFSET_LIMIT_K:g} K; check where "
                    "the sensor sits (sun, exhaust air, a wall) and the reference")
        if self.pairs < T_OUT_MIN_PAIRS or self.span_h < T_OUT_MIN_SPAN_H:
            return (text + f": too few readings yet to judge (≥ {T_OUT_MIN_PAIRS} over ≥ "
                    f"{T_OUT_MIN_SPAN_H:g} h)")
        return text + f": within {T_OUT_OFFSET_LIMIT_K:g} K"


def outdoor_offset(pairs: list[tuple[datetime, float, float]]) -> OutdoorOffset | None:
    """(ts, heat pump's T_out, reference T_out) pairs → the offset verdict; None without pairs."""
    if not pairs:
        return None
    diffs = [hp - ref for _, hp, ref in pairs]
    offset = statistics.median(diffs)
    side = sum(1 for d in diffs if (d > 0) == (offset > 0) and d != 0) / len(diffs)
    times = [t for t, _, _ in pairs]
    span_h = (max(times) - min(times)).total_seconds() / 3600.0
    persistent = (len(pairs) >= T_OUT_MIN_PAIRS and span_h >= T_OUT_MIN_SPAN_H
                  and abs(offset) > T_OUT_OFFSET_LIMIT_K and side >= T_OUT_SAME_SIGN)
    return OutdoorOffset(offset, len(pairs), span_h, side, persistent)


class HouseInputTables:
    """Queries on ``house_inputs`` (``self._db``: the connection)."""

    _db: sqlite3.Connection

    def add_house_inputs(self, row: HouseInputRow) -> None:
        """Commit one row at once (a second row for the same sample replaces the first)."""
        values = asdict(row)
        self._db.execute(
            f"INSERT OR REPLACE INTO house_inputs (night_id, ts, {', '.join(_COLUMNS)})"
            f" VALUES (?, ?, {', '.join('?' * len(_COLUMNS))})",
            [row.night_id, _iso(row.ts), *(values[c] for c in _COLUMNS)])

    def house_inputs(self, night_id: int | None) -> list[HouseInputRow]:
        """The rows of one night (None: the readings between nights) in time order."""
        where = "night_id IS NULL" if night_id is None else "night_id = ?"
        args = () if night_id is None else (night_id,)
        rows = self._db.execute(
            f"SELECT * FROM house_inputs WHERE {where} ORDER BY ts", args).fetchall()
        return [HouseInputRow(night_id=r["night_id"], ts=_dt(r["ts"]),
                              **{c: r[c] for c in _COLUMNS}) for r in rows]

    def outdoor_pairs(self, limit: int = 2000) -> list[tuple[datetime, float, float]]:
        """The latest (ts, heat pump's T_out, reference T_out) pairs, nights or not."""
        rows = self._db.execute(
            "SELECT ts, t_out_c, t_out_ref_c FROM house_inputs WHERE t_out_c IS NOT NULL AND "
            "t_out_ref_c IS NOT NULL ORDER BY ts DESC LIMIT ?", (limit,)).fetchall()
        return [(_dt(r["ts"]), r["t_out_c"], r["t_out_ref_c"]) for r in reversed(rows)]

    def outdoor_offset(self) -> OutdoorOffset | None:
        """:func:`outdoor_offset` over :meth:`outdoor_pairs`."""
        return outdoor_offset(self.outdoor_pairs())

    def latest_house_inputs(self) -> HouseInputRow | None:
        """The newest row, of a night or between nights."""
        r = self._db.execute("SELECT * FROM house_inputs ORDER BY ts DESC LIMIT 1").fetchone()
        return None if r is None else HouseInputRow(night_id=r["night_id"], ts=_dt(r["ts"]),
                                                    **{c: r[c] for c in _COLUMNS})
