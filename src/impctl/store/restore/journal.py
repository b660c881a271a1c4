"""The store's restore journal (a mixin of :class:`~impctl.store.Store`), and its copy outside
the database (:mod:`.owner_file`), kept equal to the pending entries after every change.

The journal holds the owner's value of every register impctl writes, recorded before the
first write; an entry is pending until a read-back confirmed its restore (or the owner changed
the register, whose newer value then stands). Beside a pending entry is what impctl last wrote
into the register and read back (:meth:`JournalTables.journal_confirm`): a restore after the
process died keeps a value that is neither, the owner's.
"""

from __future__ import annotations

import contextlib
import sqlite3
from collections.abc import Callable
from pathlib import Path

from ...errors import InputError
from .._times import _dt, _iso, _now
from ..records import JournalEntry
from .owner_file import (
    clear_owner_values,
    read_owner_values,
    remove_owner_values,
    write_owner_values,
)


class JournalTables:
    """Queries on ``journal`` (``self._db``: the connection; ``self.owner_file``: the copy)."""

    _db: sqlite3.Connection
    owner_file: Path
    _immediate: Callable[[], contextlib.AbstractContextManager[None]]  # Store's

    def journal_record(self, night_id: int | None, register: str, address: int,
                       raw_value: int, confirmed_raw: int | None = None) -> JournalEntry:
        """Record the owner's value of ``register`` before the first write.

        If an unrestored entry for the register already exists (an earlier restore did not
        complete), that entry is kept and returned: the owner's value is the one recorded
        before impctl ever touched the register, never a value impctl wrote itself.
        ``confirmed_raw``: what the caller read there now and holds as its own until it
        writes (:meth:`journal_confirm`); None claims nothing, so a restore puts the owner's
        value back whatever it finds.

        The pending journal is then copied to :attr:`owner_file`.

        Raises
        ------
        OSError
            The copy could not be written (the entry is in the database): write nothing.
        """
        with self._immediate():
            row = self._db.execute(
                "SELECT * FROM journal WHERE register = ? AND restored IS NULL",
                (register,)).fetchone()
            if row is None:
                cur = self._db.execute(
                    "INSERT INTO journal (night_id, register, address, raw_value, recorded,"
                    " confirmed_raw) VALUES (?, ?, ?, ?, ?, ?)",
                    (night_id, register, address, raw_value, _iso(_now()), confirmed_raw))
                row_id = cur.lastrowid
            else:  # what the register holds now, not what an earlier night left claimed
                row_id = row["id"]
                self._db.execute("UPDATE journal SET confirmed_raw = ? WHERE id = ?",
                                 (confirmed_raw, row_id))
            row = self._db.execute("SELECT * FROM journal WHERE id = ?", (row_id,)).fetchone()
        write_owner_values(self.owner_file, self.journal_pending())
        return _journal(row)

    def journal_pending(self) -> list[JournalEntry]:
        """Entries whose restore has not been confirmed by read-back."""
        rows = self._db.execute("SELECT * FROM journal WHERE restored IS NULL ORDER BY id")
        return [_journal(r) for r in rows]

    def journal_confirm(self, entry_id: int, raw: int | None) -> None:
        """Keep beside pending entry ``entry_id`` what impctl last wrote into its register and
        read back (``raw``), or None just before a write: until the read-back, what the
        register holds is not known, and a restore after the process died must put the
        owner's value back whatever it finds. One row, and the copy only when the value
        changes (a night calls this twice per write).

        Raises
        ------
        sqlite3.Error
            Not recorded: before a write, do not write (the old value still holds).
        """
        cur = self._db.execute(
            "UPDATE journal SET confirmed_raw = ? WHERE id = ? AND restored IS NULL"
            " AND confirmed_raw IS NOT ?", (raw, entry_id, raw))
        if cur.rowcount:
            self._mirror_journal()

    def journal_confirmed(self, entry_id: int) -> int | None:
        """What impctl last wrote into ``entry_id``'s register and read back (raw), as
        recorded now; None when unknown."""
        row = self._db.execute("SELECT confirmed_raw FROM journal WHERE id = ?",
                               (entry_id,)).fetchone()
        return None if row is None else row["confirmed_raw"]

    def journal_mark_restored(self, entry_id: int) -> None:
        """Mark an entry restored (after the read-back matched)."""
        self._db.execute("UPDATE journal SET restored = ?, outcome = 'restored' WHERE id = ?",
                         (_iso(_now()), entry_id))
        self._mirror_journal()

    def journal_mark_owner_changed(self, entry_id: int, raw_value: int) -> None:
        """Close an entry without restoring it: the owner set the register themselves
        (to ``raw_value``) while impctl held it, and the owner's newer choice wins."""
        self._db.execute(
            "UPDATE journal SET restored = ?, outcome = ? WHERE id = ? AND restored IS NULL",
            (_iso(_now()), f"owner changed it to raw {int(raw_value)}", entry_id))
        self._mirror_journal()

    def recover_journal(self) -> list[JournalEntry]:
        """Take back the entries that :attr:`owner_file` holds and this database lost (a
        store truncated or replaced after a power cut): they are journaled again, pending,
        with the owner's values; entries the database knows (pending or closed) are left as
        they are, and a copy that fails its checks is never used. Returns the entries taken
        back (with their ids in this database)."""
        try:
            kept, _ = read_owner_values(self.owner_file)
        except (FileNotFoundError, InputError):
            return []
        taken = []
        with self._immediate():
            for e in kept:
                if self._db.execute(
                        "SELECT 1 FROM journal WHERE (id = ? AND register = ? AND recorded = ?)"
                        " OR (register = ? AND restored IS NULL)",
                        (e.id, e.register, _iso(e.recorded), e.register)).fetchone():
                    continue  # known here, or a pending entry for the register already
                id_free = not self._db.execute("SELECT 1 FROM journal WHERE id = ?",
                                               (e.id,)).fetchone()
                night_known = e.night_id is not None and self._db.execute(
                    "SELECT 1 FROM nights WHERE id = ?", (e.night_id,)).fetchone()
                cur = self._db.execute(
                    "INSERT INTO journal (id, night_id, register, address, raw_value, recorded,"
                    " confirmed_raw) VALUES (?, ?, ?, ?, ?, ?, ?)",
                    (e.id if id_free else None, e.night_id if night_known else None,
                     e.register, e.address, e.raw_value, _iso(e.recorded), e.confirmed_raw))
                taken.append(_journal(self._db.execute(
                    "SELECT * FROM journal WHERE id = ?", (cur.lastrowid,)).fetchone()))
        if taken or {e.id for e in kept} != {e.id for e in self.journal_pending()}:
            self._mirror_journal()  # the copy names this database's pending entries
        return taken

    def forget_owner_values(self) -> None:
        """Every entry is back on the heat pump, verified, even if this store could not
        record it (a full disk; the next start closes the entries): :attr:`owner_file` says
        nothing is pending (or is removed, when it cannot be rewritten)."""
        clear_owner_values(self.owner_file)

    def _mirror_journal(self) -> None:
        """Bring :attr:`owner_file` up to the pending journal; when it cannot be rewritten
        it is removed, so it never holds a value that is no longer to be restored."""
        try:
            write_owner_values(self.owner_file, self.journal_pending())
        except OSError:
            remove_owner_values(self.owner_file)


def _journal(row: sqlite3.Row) -> JournalEntry:
    return JournalEntry(id=row["id"], night_id=row["night_id"], register=row["register"],
                        address=row["address"], raw_value=row["raw_value"],
                        recorded=_dt(row["recorded"]), restored=_dt(row["restored"]),
                        confirmed_raw=row["confirmed_raw"])

