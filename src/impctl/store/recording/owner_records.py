"""The owner records in the store (a mixin of :class:`~impctl.store.Store`): the house recorded
read-only around the clock, one record per local day from noon to noon, kept in ``nights``
with ``kind = 'owner'`` and its rows in ``samples``.

A record is "recording" while its day runs and "done" once closed with its labels
(``reasons``; ``valid`` when it has none). The labels are ``key: detail`` texts; the key (the
part before the first ``:``) is what ``impctl status`` counts them by. Records older than the
configured number of days are deleted with their rows and their house inputs.
"""

from __future__ import annotations

import json
import os
import sqlite3
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

from .._times import _dt, _iso
from ..records import Night, Sample
from .house_inputs import HouseInputRow

OWNER = "owner"


def label_key(label: str) -> str:
    """The reason a label names, without its detail ("data missing: 40 % …" → "data
    missing")."""
    return label.split(":", 1)[0].strip()


@dataclass(frozen=True)
class OwnerSummary:
    """What ``impctl status`` says of the owner records.

    ``count`` records kept (``recording`` of them still open), the local days of the first
    and the last (their noon-to-noon windows' starts), how many are labelled, by label key;
    ``rows`` stored and the newest row's instant.
    """

    count: int = 0
    recording: int = 0
    first: datetime | None = None
    last: datetime | None = None
    labelled: dict[str, int] = field(default_factory=dict)
    rows: int = 0
    last_row: datetime | None = None


class OwnerRecordTables:
    """Queries on the owner records (``self._db``: the connection)."""

    _db: sqlite3.Connection
    path: Path

    def nights(self, **kwargs) -> list[Night]:  # pragma: no cover - Store's own
        raise NotImplementedError

    def night(self, night_id: int) -> Night | None:  # pragma: no cover - Store's own
        raise NotImplementedError

    def owner_records(self, *, states: Iterable[str] | None = None) -> list[Night]:
        """The owner records in id (= time) order, optionally of the given states."""
        return self.nights(kinds=(OWNER,), states=states)

    def owner_record_at(self, window_start: datetime) -> Night | None:
        """The owner record of the day whose window starts at ``window_start``, or None."""
        row = self._db.execute(
            "SELECT id FROM nights WHERE kind = ? AND window_start = ?",
            (OWNER, _iso(window_start))).fetchone()
        return None if row is None else self.night(int(row[0]))

    def open_owner_record(self, window_start: datetime, window_end: datetime) -> int:
        """The id of the owner record of [``window_start``, ``window_end``), created
        ("recording") when there is none yet."""
        with self._immediate():
            row = self._db.execute(
                "SELECT id FROM nights WHERE kind = ? AND window_start = ?",
                (OWNER, _iso(window_start))).fetchone()
            if row is not None:
                return int(row[0])
            cur = self._db.execute(
                "INSERT INTO nights (kind, setpoint_c, window_start, window_end, state, source)"
                " VALUES (?, NULL, ?, ?, 'recording', ?)",
                (OWNER, _iso(window_start), _iso(window_end), OWNER))
            return int(cur.lastrowid)

    def add_owner_row(self, sample: Sample, inputs: HouseInputRow | None = None) -> None:
        """Commit one owner row (and the house's own sensors over it) in one transaction.

        Without waiting for the disk (``synchronous=NORMAL`` for this commit; WAL keeps the
        store consistent through a power cut, which may lose the last rows): an owner row is
        data, not the journal, and the fsync of every row cost as much as the rest of the
        recording. The next commit of the journal or of a night's sample (``FULL``) syncs it
        to disk with its own."""
        self._db.execute("PRAGMA synchronous=NORMAL")
        try:
            with self._immediate():
                self.add_sample(sample)
                if inputs is not None:
                    self.add_house_inputs(inputs)
        finally:
            self._db.execute("PRAGMA synchronous=FULL")

    def note_owner_record(self, record_id: int, note: str) -> None:
        """Add ``note`` to an open record's labels (a clock step while it records); kept
        when the record is closed."""
        row = self._db.execute("SELECT reasons FROM nights WHERE id = ?",
                               (record_id,)).fetchone()
        if row is None:
            return
        reasons = [*json.loads(row[0]), note]
        self._db.execute("UPDATE nights SET reasons = ? WHERE id = ?",
                         (json.dumps(reasons), record_id))

    def close_owner_record(self, record_id: int, labels: Sequence[str],
                           setpoint_c: float | None, started: datetime | None,
                           ended: datetime | None) -> None:
        """Close a record: "done", valid without labels, the owner's setpoint at night [°C],
        its first row's start and its last row's end."""
        self._db.execute(
            "UPDATE nights SET state = 'done', valid = ?, reasons = ?, setpoint_c = ?,"
            " started = ?, ended = ? WHERE id = ?",
            (int(not labels), json.dumps(list(labels)), setpoint_c, _iso(started),
             _iso(ended), record_id))

    def last_owner_row(self) -> datetime | None:
        """The start of the newest owner row, or None."""
        row = self._db.execute(
            "SELECT MAX(s.ts) FROM samples s JOIN nights n ON n.id = s.night_id"
            " WHERE n.kind = ?", (OWNER,)).fetchone()
        return _dt(row[0]) if row is not None else None

    def purge_owner_records(self, before: datetime) -> int:
        """Delete the owner records that ended before ``before``, with their rows and house
        inputs, in one transaction; returns how many."""
        cutoff = _iso(before)
        old = "SELECT id FROM nights WHERE kind = ? AND window_end < ?"
        with self._immediate():
            ids = [r[0] for r in self._db.execute(old, (OWNER, cutoff))]
            if not ids:
                return 0
            self._db.execute(f"DELETE FROM house_inputs WHERE night_id IN ({old})",
                             (OWNER, cutoff))
            self._db.execute(f"DELETE FROM samples WHERE night_id IN ({old})", (OWNER, cutoff))
            self._db.execute("DELETE FROM nights WHERE kind = ? AND window_end < ?",
                             (OWNER, cutoff))
        return len(ids)

    def owner_summary(self) -> OwnerSummary:
        """Counts for ``impctl status`` (:class:`OwnerSummary`)."""
        records = self.owner_records()
        if not records:
            return OwnerSummary()
        labelled = Counter(label_key(r) for n in records if n.state == "done"
                           for r in dict.fromkeys(label_key(x) for x in n.reasons))
        rows, last = self._db.execute(
            "SELECT COUNT(*), MAX(s.ts) FROM samples s JOIN nights n ON n.id = s.night_id"
            " WHERE n.kind = ?", (OWNER,)).fetchone()
        return OwnerSummary(count=len(records),
                            recording=sum(n.state == "recording" for n in records),
                            first=records[0].window_start, last=records[-1].window_start,
                            labelled=dict(sorted(labelled.items())), rows=int(rows),
                            last_row=_dt(last))

    def size_bytes(self) -> int:
        """The store's size on disk [bytes]: the database and its write-ahead log."""
        total = 0
        for suffix in ("", "-wal", "-shm"):
            try:
                total += os.stat(f"{self.path}{suffix}").st_size
            except OSError:
                continue
        return total

    def _immediate(self):  # pragma: no cover - Store's own
        raise NotImplementedError

    def add_sample(self, sample: Sample) -> None:  # pragma: no cover - Store's own
        raise NotImplementedError

    def add_house_inputs(self, row: HouseInputRow) -> None:  # pragma: no cover - mixin's
        raise NotImplementedError
