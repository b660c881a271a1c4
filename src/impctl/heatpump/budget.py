"""A persistent per-register write counter with a daily budget (SQLite, WAL).

Kronoterm publishes no write-endurance figure for its non-volatile memory, so impctl assumes the
conservative 100 000-writes-per-lifetime class and limits writes per register per day
(reference §4.1). Every write *attempt* is counted before it is sent: a write whose answer was
lost may still have reached the EEPROM.
"""

from __future__ import annotations

import logging
import sqlite3
from collections.abc import Mapping
from datetime import date
from pathlib import Path

from ..errors import InputError, sqlite_problem
from .errors import WriteBudgetExceeded, WriteRefused

_LOG = logging.getLogger(__name__)

_SCHEMA = """
CREATE TABLE IF NOT EXISTS daily (
    day TEXT NOT NULL, ma INTEGER NOT NULL, count INTEGER NOT NULL,
    PRIMARY KEY (day, ma)
);
CREATE TABLE IF NOT EXISTS lifetime (ma INTEGER PRIMARY KEY, count INTEGER NOT NULL);
"""


class WriteBudget:
    """Per-register daily write budget stored in a small SQLite file.

    Parameters
    ----------
    path : str or Path
        SQLite file (created with its parent directory if missing); WAL journal mode, so a
        second process (e.g. a restore watchdog) can read and count concurrently.
    daily_limit : int
        Writes allowed per register per day.
    per_register : Mapping[int, int], optional
        Overrides of ``daily_limit`` by documented register number.
    """

    def __init__(self, path: str | Path, daily_limit: int,
                 per_register: Mapping[int, int] | None = None) -> None:
        limits = {None: daily_limit, **(per_register or {})}
        for ma, limit in limits.items():
            if not isinstance(limit, int) or limit < 0:
                where = "daily_limit" if ma is None else f"register {ma}"
                raise InputError(f"write budget must be an integer >= 0, got {limit!r}",
                                 place=where)
        self.path = Path(path)
        self.daily_limit = daily_limit
        self._per_register = dict(per_register or {})
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(self.path, isolation_level=None, timeout=10.0)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.executescript(_SCHEMA)
        except sqlite3.Error as exc:
            raise InputError(f"cannot open the write-budget database: {exc}", self.path) from None

    def limit(self, ma: int) -> int:
        """Daily budget of register ``ma``."""
        return self._per_register.get(ma, self.daily_limit)

    def used(self, ma: int, day: date) -> int:
        """Writes counted for ``ma`` on ``day``."""
        row = self._db.execute("SELECT count FROM daily WHERE day = ? AND ma = ?",
                               (day.isoformat(), ma)).fetchone()
        return int(row[0]) if row else 0

    def remaining(self, ma: int, day: date) -> int:
        """Writes still allowed for ``ma`` on ``day``."""
        return max(0, self.limit(ma) - self.used(ma, day))

    def lifetime(self, ma: int) -> int:
        """All writes ever counted for ``ma`` in this file."""
        row = self._db.execute("SELECT count FROM lifetime WHERE ma = ?", (ma,)).fetchone()
        return int(row[0]) if row else 0

    def consume(self, ma: int, day: date, *, reserve: int = 0,
                best_effort: bool = False) -> int:
        """Count one write of ``ma`` on ``day``; return the day's count including it.

        Parameters
        ----------
        reserve : int
            Extra writes allowed beyond the budget (restoring the owner's settings); using
            one is logged at ERROR level.
        best_effort : bool
            A restore: when the count cannot be recorded (a full disk, a read-only file
            system, a damaged file), log one line and allow the write anyway — putting the
            owner's settings back never depends on recording anything.

        Raises
        ------
        WriteBudgetExceeded
            When the day's budget (plus ``reserve``) is already used up; nothing is counted
            then. Logged at ERROR level as well, so a refused write is never silent.
        WriteRefused
            When the count cannot be recorded and ``best_effort`` is False (an experiment's
            write is not sent uncounted).
        """
        try:
            return self._consume(ma, day, reserve)
        except sqlite3.Error as exc:
            why = sqlite_problem(exc)
            if not best_effort:
                msg = (f"register {ma}: the write budget cannot count the write ({why}: "
                       f"{self.path}); write refused")
                _LOG.error(msg)
                raise WriteRefused(msg) from None
            _LOG.error("register %d: the write budget cannot count the restore (%s: %s); "
                       "restoring anyway", ma, why, self.path)
            return self.used_or_zero(ma, day) + 1

    def _consume(self, ma: int, day: date, reserve: int) -> int:
        db = self._db
        db.execute("BEGIN IMMEDIATE")  # check-and-increment atomically across processes
        try:
            used = self.used(ma, day)
            if used >= self.limit(ma) + reserve:
                msg = (f"write budget exhausted for register {ma}: {used} of "
                       f"{self.limit(ma)} (+{reserve} reserve) writes used on "
                       f"{day.isoformat()}; write refused")
                _LOG.error(msg)
                raise WriteBudgetExceeded(msg)
            if used >= self.limit(ma):
                _LOG.error("register %d: write %d beyond the daily budget of %d, taken from "
                           "the restore reserve", ma, used + 1, self.limit(ma))
            db.execute(
                "INSERT INTO daily (day, ma, count) VALUES (?, ?, 1) "
                "ON CONFLICT (day, ma) DO UPDATE SET count = count + 1",
                (day.isoformat(), ma),
            )
            db.execute(
                "INSERT INTO lifetime (ma, count) VALUES (?, 1) "
                "ON CONFLICT (ma) DO UPDATE SET count = count + 1",
                (ma,),
            )
            db.execute("COMMIT")
        except BaseException:
            self._rollback()
            raise
        return used + 1

    def _rollback(self) -> None:
        """Roll back what is open; never raise. A COMMIT that failed with SQLITE_FULL or an
        I/O error may already have rolled the transaction back itself, and then ROLLBACK
        would raise "no transaction is active" over the error that matters."""
        if not self._db.in_transaction:
            return
        try:
            self._db.execute("ROLLBACK")
        except sqlite3.Error as exc:
            _LOG.debug("rollback of %s failed: %s", self.path, exc)

    def used_or_zero(self, ma: int, day: date) -> int:
        """:meth:`used`, or 0 when the file cannot be read (for log lines and results only,
        never for a decision)."""
        try:
            return self.used(ma, day)
        except sqlite3.Error:
            return 0

    def refund(self, ma: int, day: date) -> None:
        """Give back one write of ``ma`` on ``day`` that provably never took effect (a restore
        the device refused, or whose read-back shows the register unchanged), so failed
        restore attempts cannot use up the budget and its reserve. Best effort: a refund that
        cannot be recorded is logged, never raised (it only ever follows a failed write)."""
        db = self._db
        try:
            db.execute("BEGIN IMMEDIATE")
            db.execute("UPDATE daily SET count = count - 1 WHERE day = ? AND ma = ? AND count > 0",
                       (day.isoformat(), ma))
            db.execute("UPDATE lifetime SET count = count - 1 WHERE ma = ? AND count > 0", (ma,))
            db.execute("COMMIT")
        except sqlite3.Error as exc:
            self._rollback()
            _LOG.error("register %d: the write budget cannot give back a write that did not "
                       "take effect (%s: %s)", ma, sqlite_problem(exc), self.path)

    def close(self) -> None:
        """Close the database."""
        self._db.close()

    def __enter__(self) -> WriteBudget:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
