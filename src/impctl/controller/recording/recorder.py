"""The owner recorder: the house recorded read-only between IMP nights, for the season model.

A snapshot every snapshot interval (the heat meter of a cycling heat pump is read often and
averaged), reduced to rows of ``interval_s`` (:mod:`.rows`); one owner record per local
day from noon to noon, labelled when it is closed (:mod:`.labels`). This module only
reads: it calls :meth:`HeatPumpClient.snapshot` and never a write. The caller decides when it
may poll (no IMP night, pre-heat or restore running; the heat-pump lock held) and ends the
current row when a night begins (:meth:`OwnerRecorder.end_row`).

Time follows the night's rules (:mod:`..timing`): rows are stamped on the wall clock, never
stored out of order (a row not after the newest stored one is dropped), no wait is longer than
one snapshot interval, and a wall-clock step beyond the tolerance ends the current row and is
noted on the open record ("clock stepped: …").

A store that cannot record (a full disk) loses rows, logged once; recording never raises into
the daemon for it.
"""

from __future__ import annotations

import asyncio
import logging
import math
import sqlite3
from collections.abc import Callable
from datetime import UTC, date, datetime, timedelta
from zoneinfo import ZoneInfo

from ...clock import VirtualClock
from ...errors import sqlite_problem
from ...heatpump import HeatPumpClient, HeatPumpError, Snapshot
from ...store import Store
from ...store.recording.house_inputs import HouseInputRow
from ..timing import REACHED_S, NightTime, describe_step
from .labels import Span, judge, night_part, night_setpoint, record_day, record_window
from .rows import RowBuilder, row_start

_LOG = logging.getLogger("impctl.record")


class OwnerRecorder:
    """Rows and owner records from the snapshots the caller lets it take.

    Parameters
    ----------
    client : HeatPumpClient (read only: :meth:`~HeatPumpClient.snapshot`); None for a
        recorder that only closes records (:meth:`close`)
    store : Store
    clock : VirtualClock (the daemon's)
    tz : the gateway's time zone (records run from local noon to noon)
    window_minutes : the night window (start, end) in minutes after local midnight
    interval_s : a row's length [s]
    sample_interval_s : seconds between snapshots
    min_coverage : share of a row's snapshots a column needs, and of a night's rows a record
    inputs_row : optional, the house's own sensors at a snapshot (``[inputs]``)
    """

    def __init__(self, client: HeatPumpClient | None, store: Store, clock: VirtualClock, *, tz: str,
                 window_minutes: tuple[int, int], interval_s: float, sample_interval_s: float,
                 min_coverage: float,
                 inputs_row: Callable[[Snapshot], HouseInputRow] | None = None):
        self.client, self.store, self.clock = client, store, clock
        self.tz = ZoneInfo(tz)
        self.window_minutes = window_minutes
        self.interval_s = float(interval_s)
        self.sample_interval_s = float(sample_interval_s)
        self.min_coverage = min_coverage
        self.inputs_row = inputs_row
        self.expected = max(1.0, self.interval_s / self.sample_interval_s)
        self.time = NightTime(clock, self.sample_interval_s)
        self._row: RowBuilder | None = None
        self._last_stored: datetime | None = store.last_owner_row()
        self._records: dict[date, int] = {}
        self._link_problem: str | None = None
        self._store_problem: str | None = None
        self._dropped_since: datetime | None = None  # rows not stored: not after the newest
        #: records closed without a label since the start (the daemon refits on a new one)
        self.closed_usable = 0

    # -- time ------------------------------------------------------------------------------
    def next_poll(self) -> datetime:
        """The next snapshot instant on the grid of the snapshot interval that has not come
        (:meth:`NightTime.reached`)."""
        now = self.clock.now_s()
        step = self.sample_interval_s
        nxt = (math.floor(now / step) + 1) * step
        # An instant within the reach tolerance (the clock a rounding error short of it) has
        # come: the next one, else it would be "reached" without waiting, for ever. Not one
        # further: the bounded wait (one interval) after a clock a few milliseconds short of
        # an instant skipped as come lands as short of the next, for ever — no snapshot at all.
        while nxt - now <= REACHED_S:
            nxt += step
        return datetime.fromtimestamp(nxt, UTC)

    async def sleep_until(self, when: datetime, *wake: asyncio.Event) -> None:
        """Sleep until ``when``, one snapshot interval at most, or until an event is set."""
        await self.time.sleep_until(when, *wake)

    # -- polling -----------------------------------------------------------------------------
    async def poll(self) -> Snapshot | None:
        """Take one snapshot (the caller holds the heat-pump lock) and add it to its row;
        the rows and records that are complete are stored. None when the read failed."""
        step = self.time.step_s()
        if step is not None:
            self._clock_stepped(step)
        now = self.clock.now()
        if self._row is not None and now >= self._row.end:
            self.end_row()
        try:
            snap = await self.client.snapshot()
        except HeatPumpError as exc:
            if self._link_problem is None:
                _LOG.warning("owner recording: heat pump not answering (%s); rows stay missing "
                             "until it answers", exc)
            self._link_problem = str(exc)
            return None
        if self._link_problem is not None:
            _LOG.info("owner recording: heat pump answers again")
            self._link_problem = None
        self.add(snap)
        return snap

    def add(self, snap: Snapshot) -> None:
        """One snapshot into its row (a row it leaves behind is stored)."""
        start = row_start(snap.timestamp, self.interval_s)
        if self._row is not None and self._row.start != start:
            self.end_row()
        if self._row is None:
            self._row = RowBuilder(start, self.interval_s, self.expected, self.min_coverage)
        inputs = None
        if self.inputs_row is not None:
            try:
                inputs = self.inputs_row(snap)
            except Exception as exc:  # noqa: BLE001 - a row without the house's inputs
                _LOG.error("owner recording: house inputs not read: %s", exc)
        self._row.add(snap, inputs)

    def end_row(self) -> None:
        """Store the current row (an IMP night begins, the daemon stops, its interval ended)
        and close the records that are over."""
        row, self._row = self._row, None
        try:
            if row is not None and row.snapshots:
                self._store_row(row)
            self.close_due()
        except sqlite3.Error as exc:
            self._store_failed(exc)

    def _store_row(self, row: RowBuilder) -> None:
        if self._last_stored is not None and row.start <= self._last_stored:
            # After the clock stepped back: a row is never stored before (or over) a newer one.
            if self._dropped_since is None:
                _LOG.info("owner rows from %s not stored: not after the newest stored row "
                          "(%s); recording resumes after it", row.start.isoformat(),
                          self._last_stored.isoformat())
                self._dropped_since = row.start
            return
        record_id = self._record_for(row.start)
        self.store.add_owner_row(row.sample(record_id), row.inputs_row(record_id))
        self._last_stored = row.start
        self._dropped_since = None
        if self._store_problem is not None:
            _LOG.info("owner recording: the store records again")
            self._store_problem = None

    def _store_failed(self, exc: sqlite3.Error) -> None:
        problem = sqlite_problem(exc)
        if self._store_problem is None:
            _LOG.error("owner recording: the store cannot record (%s); rows are lost until it "
                       "can", problem)
        self._store_problem = problem

    def _record_for(self, ts: datetime) -> int:
        day = record_day(ts, self.tz)
        if day not in self._records:
            start, end = record_window(day, self.tz)
            self._records = {day: self.store.open_owner_record(start, end)}
        return self._records[day]

    def _clock_stepped(self, step_s: float) -> None:
        """A wall-clock step: the current row ends here (the next snapshot is stamped on the
        stepped clock) and the open record notes it."""
        what = describe_step(step_s)
        _LOG.warning("owner recording: system clock stepped by %s; the current row ends here",
                     what)
        self.end_row()
        try:
            self.store.add_event("warning", f"owner recording: system clock stepped by {what}")
            record = self._records.get(record_day(self.clock.now(), self.tz))
            if record is None and self._records:
                record = next(iter(self._records.values()))
            if record is not None:
                self.store.note_owner_record(
                    record, f"clock stepped: by {what} at "
                    f"{self.clock.now().astimezone(self.tz):%Y-%m-%d %H:%M}")
        except sqlite3.Error as exc:
            self._store_failed(exc)

    # -- records ------------------------------------------------------------------------------
    def close_due(self) -> int:
        """Close (label) the open records whose day has ended and that no current row
        belongs to; returns how many."""
        now = self.clock.now()
        closed = 0
        for record in self.store.owner_records(states=["recording"]):
            if record.window_end > now or (
                    self._row is not None and record.window_start <= self._row.start
                    < record.window_end):
                continue
            self.close(record.id)
            closed += 1
        return closed

    def close(self, record_id: int) -> None:
        """Label a record from its rows and the IMP nights in its span, and close it."""
        record = self.store.night(record_id)
        rows = self.store.samples(record_id)
        day = record_day(record.window_start, self.tz)
        part = night_part(day, self.tz, self.window_minutes)
        spans = [Span(n.id, n.started, n.ended or n.window_end)
                 for n in self.store.nights()
                 if n.started is not None and n.started < record.window_end
                 and (n.ended or n.window_end) > record.window_start]
        labels = judge(rows, part, interval_s=self.interval_s, min_coverage=self.min_coverage,
                       imp_spans=spans, tz=self.tz)
        notes = [r for r in record.reasons if r not in labels]
        end = rows[-1].ts + timedelta(seconds=self.interval_s) if rows else None
        self.store.close_owner_record(record_id, [*labels, *notes],
                                      night_setpoint(rows, part),
                                      rows[0].ts if rows else None, end)
        self._records = {d: i for d, i in self._records.items() if i != record_id}
        verdict = "usable" if not labels and not notes else "labelled: " + "; ".join(
            [*labels, *notes])
        self.closed_usable += not labels and not notes
        _LOG.info("owner record %d (%s, %d rows) closed, %s", record_id, day.isoformat(),
                  len(rows), verdict)

    def purge(self, keep_days: int) -> int:
        """Delete the records that ended more than ``keep_days`` days ago; returns how many."""
        before = self.clock.now() - timedelta(days=keep_days)
        try:
            gone = self.store.purge_owner_records(before)
        except sqlite3.Error as exc:
            self._store_failed(exc)
            return 0
        if gone:
            _LOG.info("owner recording: %d records older than %d days deleted", gone, keep_days)
        return gone
