"""The SQLite store: opening it (migrated on open, :mod:`.schema`) and the queries the
daemon and CLI need."""

from __future__ import annotations

import contextlib
import json
import os
import sqlite3
from collections.abc import Iterable, Iterator, Sequence
from datetime import datetime
from pathlib import Path

from ..errors import InputError
from ._times import _dt, _iso, _now
from .campaign_tables import CampaignTables
from .recording.house_inputs import HouseInputTables
from .recording.owner_records import OwnerRecordTables
from .records import IMP_KINDS, SAMPLE_COLUMNS, Command, Night, Sample, TriggerRequest
from .restore.journal import JournalTables
from .restore.owner_file import OWNER_FILE
from .schema import migrate


class Store(CampaignTables, HouseInputTables, JournalTables, OwnerRecordTables):
    """The impctl SQLite database (WAL mode, schema migrated on open).

    Parameters
    ----------
    path : str or Path
        Database file; with ``create`` its directory is created if missing.
    create : bool, default True
        False for readers (status, export, report): a missing file is an error instead of
        a new, empty database.

    Raises
    ------
    InputError
        No such file (``create=False``), not an impctl database, or written by a newer impctl.
    """

    def __init__(self, path: str | Path, *, create: bool = True):
        self.path = Path(path)
        #: The pending journal's copy outside the database (:mod:`.owner_file`).
        self.owner_file = self.path.parent / OWNER_FILE
        if not create and not self.path.exists():
            raise InputError("no impctl store here (has the daemon run? check state_dir)",
                             self.path)
        if self.path.is_dir():
            raise InputError("is a directory, not an impctl store", self.path)
        if self.path.parent.exists() and not self.path.parent.is_dir():
            raise InputError("is a file, not a state directory", self.path.parent)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:  # state_dir under /proc, a file on the way, no permission
            raise InputError(f"cannot create the state directory: {exc.strerror}",
                             self.path.parent) from None
        # A new store is not world-accessible whatever the umask (a shell's 022, not only the
        # unit's 0027); SQLite gives its -wal and -shm files the database file's permissions.
        try:
            os.close(os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o640))
        except FileExistsError:
            pass
        except OSError as exc:
            raise InputError(f"cannot create the store: {exc.strerror}", self.path) from None
        try:
            self._db = sqlite3.connect(self.path, isolation_level=None, timeout=10.0)
        except sqlite3.Error as exc:
            raise InputError(f"cannot open the store: {exc}", self.path) from None
        self._db.row_factory = sqlite3.Row
        try:
            self._db.execute("PRAGMA journal_mode=WAL")
            # FULL: a committed sample survives a power cut of the gateway, not only a crash.
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.execute("PRAGMA foreign_keys=ON")
            migrate(self._db, self.path)
        except sqlite3.DatabaseError as exc:
            self._db.close()
            raise InputError(f"not a usable impctl database: {exc}", self.path) from None

    # -- lifecycle -------------------------------------------------------------------------
    def close(self) -> None:
        """Close the connection."""
        self._db.close()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def schema_version(self) -> int:
        """The schema version of the open file."""
        return int(self._db.execute("PRAGMA user_version").fetchone()[0])

    def integrity_check(self) -> str:
        """SQLite's ``PRAGMA integrity_check`` result (``"ok"`` when sound)."""
        return str(self._db.execute("PRAGMA integrity_check").fetchone()[0])

    # -- nights ----------------------------------------------------------------------------
    def create_night(self, kind: str, setpoint_c: float, window_start: datetime,
                     window_end: datetime, *, t_min_c: float | None = None,
                     t_max_c: float | None = None, source: str = "schedule") -> int:
        """Record a new night in state ``planned``; returns its id."""
        cur = self._db.execute(
            "INSERT INTO nights (kind, setpoint_c, t_min_c, t_max_c, window_start, window_end,"
            " state, source) VALUES (?, ?, ?, ?, ?, ?, 'planned', ?)",
            (kind, setpoint_c, t_min_c, t_max_c, _iso(window_start), _iso(window_end), source),
        )
        return int(cur.lastrowid)

    def set_night_state(self, night_id: int, state: str, *, started: datetime | None = None,
                        ended: datetime | None = None) -> None:
        """Move a night to ``state``; ``started``/``ended`` are set when given."""
        self._db.execute(
            "UPDATE nights SET state = ?, started = COALESCE(?, started),"
            " ended = COALESCE(?, ended) WHERE id = ?",
            (state, _iso(started), _iso(ended), night_id),
        )

    def assess_night(self, night_id: int, valid: bool, reasons: Sequence[str]) -> None:
        """Store the validity verdict and its reasons."""
        self._db.execute("UPDATE nights SET valid = ?, reasons = ? WHERE id = ?",
                         (int(valid), json.dumps(list(reasons)), night_id))

    def end_night(self, night_id: int, state: str, ended: datetime, valid: bool,
                  reasons: Sequence[str]) -> None:
        """A night's end state and verdict in one transaction (never one without the other:
        a night left running is swept as interrupted at the next start)."""
        with self._immediate():
            self.set_night_state(night_id, state, ended=ended)
            self.assess_night(night_id, valid, reasons)

    def interrupt_night(self, night_id: int, reason: str) -> None:
        """Mark a night that was running when the process died ``interrupted`` and not valid
        in one transaction: no reader, and no second crash, sees the state without the
        verdict (the next sweep would not look at an interrupted night again)."""
        with self._immediate():
            self.set_night_state(night_id, "interrupted")
            self.assess_night(night_id, False, [reason])

    def night(self, night_id: int) -> Night | None:
        """One night, or None."""
        row = self._db.execute("SELECT * FROM nights WHERE id = ?", (night_id,)).fetchone()
        return None if row is None else _night(row)

    def nights(self, *, states: Iterable[str] | None = None, valid: bool | None = None,
               ids: Iterable[int] | None = None,
               kinds: Iterable[str] = IMP_KINDS) -> list[Night]:
        """Nights in id order, optionally filtered by state, validity or id; the IMP nights
        only unless ``kinds`` says otherwise (the owner records: ``kinds=("owner",)``)."""
        kinds = list(kinds)
        sql = f"SELECT * FROM nights WHERE kind IN ({','.join('?' * len(kinds))})"
        args: list = kinds
        if states is not None:
            states = list(states)
            sql += f" AND state IN ({','.join('?' * len(states))})"
            args += states
        if valid is not None:
            sql += " AND valid = ?"
            args.append(int(valid))
        if ids is not None:
            ids = list(ids)
            sql += f" AND id IN ({','.join('?' * len(ids))})"
            args += ids
        return [_night(r) for r in self._db.execute(sql + " ORDER BY id", args)]

    # -- samples ---------------------------------------------------------------------------
    def add_sample(self, sample: Sample) -> None:
        """Commit one sample at once."""
        values = [getattr(sample, c) for c in SAMPLE_COLUMNS]
        values = [int(v) if isinstance(v, bool) else v for v in values]
        self._db.execute(
            f"INSERT OR REPLACE INTO samples (night_id, ts, {', '.join(SAMPLE_COLUMNS)})"
            f" VALUES (?, ?, {', '.join('?' * len(SAMPLE_COLUMNS))})",
            [sample.night_id, _iso(sample.ts), *values],
        )

    def samples(self, night_id: int) -> list[Sample]:
        """The samples of one night in time order."""
        rows = self._db.execute(
            "SELECT * FROM samples WHERE night_id = ? ORDER BY ts", (night_id,)).fetchall()
        out = []
        for r in rows:
            kw = {c: r[c] for c in SAMPLE_COLUMNS}
            for flag in ("defrost", "dhw_active"):
                kw[flag] = None if kw[flag] is None else bool(kw[flag])
            out.append(Sample(night_id=r["night_id"], ts=_dt(r["ts"]), **kw))
        return out

    def sample_count(self, night_id: int) -> int:
        """Number of samples of one night."""
        return int(self._db.execute(
            "SELECT COUNT(*) FROM samples WHERE night_id = ?", (night_id,)).fetchone()[0])

    @contextlib.contextmanager
    def _immediate(self) -> Iterator[None]:
        """A write transaction that takes the write lock at once (``BEGIN IMMEDIATE``): of two
        processes that check and then insert, only one inserts. Rolled back on any error."""
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield
        except BaseException:
            self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    # -- manual trigger requests -----------------------------------------------------------
    def add_request(self, kind: str, setpoint_c: float | None, when: str, *,
                    expires: datetime | None = None, forced: bool = False) -> int:
        """Queue a manual night for the daemon; returns the request id.

        ``expires`` (aware, on the daemon's clock): the daemon drops the request unstarted
        after it; None = never. ``forced``: a ``now`` night that may run in daytime
        (``--force``).
        """
        cur = self._db.execute(
            "INSERT INTO requests (kind, setpoint_c, run_when, created, expires, extra)"
            " VALUES (?, ?, ?, ?, ?, ?)",
            (kind, setpoint_c, when, _iso(_now()), _iso(expires),
             json.dumps({"forced": True} if forced else {})))
        return int(cur.lastrowid)

    def queue_request(self, kind: str, setpoint_c: float | None, when: str, *,
                      expires: datetime | None = None, forced: bool = False) -> tuple[int, bool]:
        """Queue a manual night unless an identical one (kind, setpoint, when) is waiting.

        Returns (request id, joined): ``joined`` is True when the waiting request was kept
        (its expiry moved to the later of the two; forced if either was) instead of a new one
        being added, so a hundred presses of one button are one request, not a hundred.
        ``forced``: a ``now`` night asked for with ``--force`` (it may run in daytime).
        """
        with self._immediate():
            row = self._db.execute(
                "SELECT id, expires, extra FROM requests WHERE taken IS NULL AND kind = ? AND"
                " run_when = ? AND setpoint_c IS ? ORDER BY id LIMIT 1",
                (kind, when, setpoint_c)).fetchone()
            if row is None:
                cur = self._db.execute(
                    "INSERT INTO requests (kind, setpoint_c, run_when, created, expires, extra)"
                    " VALUES (?, ?, ?, ?, ?, ?)",
                    (kind, setpoint_c, when, _iso(_now()), _iso(expires),
                     json.dumps({"forced": True} if forced else {})))
                out = (int(cur.lastrowid), False)
            else:
                old = _dt(row["expires"])
                if old is not None and (expires is None or expires > old):
                    self._db.execute("UPDATE requests SET expires = ? WHERE id = ?",
                                     (_iso(expires), row["id"]))
                if forced:
                    extra = {**json.loads(row["extra"]), "forced": True}
                    self._db.execute("UPDATE requests SET extra = ? WHERE id = ?",
                                     (json.dumps(extra), row["id"]))
                out = (int(row["id"]), True)
        return out

    def pending_requests(self) -> list[TriggerRequest]:
        """Requests not yet taken, cancelled or expired by the daemon, oldest first."""
        rows = self._db.execute("SELECT * FROM requests WHERE taken IS NULL ORDER BY id")
        return [_request(r) for r in rows]

    def take_request(self, request_id: int) -> bool:
        """Mark a request taken; False if another taker was first (or it was cancelled)."""
        cur = self._db.execute(
            "UPDATE requests SET taken = ?, outcome = 'taken' WHERE id = ? AND taken IS NULL",
            (_iso(_now()), request_id))
        return cur.rowcount == 1

    def close_request(self, request_id: int, outcome: str) -> bool:
        """End a pending request without running it (``outcome``: "cancelled", "expired");
        False when it was no longer pending."""
        cur = self._db.execute(
            "UPDATE requests SET taken = ?, outcome = ? WHERE id = ? AND taken IS NULL",
            (_iso(_now()), outcome, request_id))
        return cur.rowcount == 1

    # -- household commands (abort, skip_tonight) ------------------------------------------
    def add_command(self, name: str, source: str) -> int:
        """Queue a command for the daemon (``abort`` or ``skip_tonight``); returns its id."""
        cur = self._db.execute(
            "INSERT INTO commands (name, source, created) VALUES (?, ?, ?)",
            (name, source, _iso(_now())))
        return int(cur.lastrowid)

    def queue_command(self, name: str, source: str, *,
                      join_since: datetime | None = None) -> tuple[int, bool]:
        """Queue a command, or keep a waiting one of the same name created at or after
        ``join_since`` (None: always a new one). Returns (command id, joined)."""
        with self._immediate():
            row = None
            if join_since is not None:  # (ISO text does not compare as instants: in Python)
                row = next((r for r in self._db.execute(
                    "SELECT id, created FROM commands WHERE taken IS NULL AND name = ?"
                    " ORDER BY id", (name,)) if _dt(r["created"]) >= join_since), None)
            if row is None:
                cur = self._db.execute(
                    "INSERT INTO commands (name, source, created) VALUES (?, ?, ?)",
                    (name, source, _iso(_now())))
                out = (int(cur.lastrowid), False)
            else:
                out = (int(row["id"]), True)
        return out

    def pending_commands(self, name: str | None = None) -> list[Command]:
        """Commands not yet taken, oldest first (only ``name`` when given)."""
        sql, args = "SELECT * FROM commands WHERE taken IS NULL", []
        if name is not None:
            sql += " AND name = ?"
            args.append(name)
        return [Command(id=r["id"], name=r["name"], source=r["source"],
                        created=_dt(r["created"]), taken=_dt(r["taken"]))
                for r in self._db.execute(sql + " ORDER BY id", args)]

    def take_command(self, command_id: int) -> bool:
        """Mark a command taken; False if another taker was first."""
        cur = self._db.execute("UPDATE commands SET taken = ? WHERE id = ? AND taken IS NULL",
                               (_iso(_now()), command_id))
        return cur.rowcount == 1

    # -- events ----------------------------------------------------------------------------
    def add_event(self, level: str, message: str) -> None:
        """Keep a notable event (link lost, restore done, abort) for ``impctl status``."""
        self._db.execute("INSERT INTO events (ts, level, message) VALUES (?, ?, ?)",
                         (_iso(_now()), level, message))

    def events(self, limit: int = 20) -> list[tuple[datetime, str, str]]:
        """The newest events first."""
        rows = self._db.execute("SELECT ts, level, message FROM events ORDER BY id DESC LIMIT ?",
                                (limit,))
        return [(_dt(r[0]), r[1], r[2]) for r in rows]


def _night(row: sqlite3.Row) -> Night:
    return Night(
        id=row["id"], kind=row["kind"], setpoint_c=row["setpoint_c"], t_min_c=row["t_min_c"],
        t_max_c=row["t_max_c"], window_start=_dt(row["window_start"]),
        window_end=_dt(row["window_end"]), state=row["state"], source=row["source"],
        valid=None if row["valid"] is None else bool(row["valid"]),
        reasons=tuple(json.loads(row["reasons"])), started=_dt(row["started"]),
        ended=_dt(row["ended"]),
    )


def _request(row: sqlite3.Row) -> TriggerRequest:
    return TriggerRequest(id=row["id"], kind=row["kind"], setpoint_c=row["setpoint_c"],
                          when=row["run_when"], created=_dt(row["created"]),
                          taken=_dt(row["taken"]), extra=json.loads(row["extra"]),
                          expires=_dt(row["expires"]), outcome=row["outcome"])
