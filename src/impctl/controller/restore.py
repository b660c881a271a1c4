"""Put the owner's settings back: the journal → the heat pump, verified by read-back.

Used at a night's end, on every abort, on SIGTERM, by ``impctl restore`` (also systemd's
ExecStopPost) and by the orphan sweep at daemon start. A restore writes the journaled raw
value verbatim: it is the owner's value, so it is not clamped to impctl's experiment limits.

A restore never depends on recording anything: when the store cannot record that an entry
is back (a full disk, a read-only file system), the heat pump is restored and verified all
the same, one line says so, and the entry stays pending in the store until a later start or
``impctl restore`` can close it (this process remembers it, so it does not restore it twice).
The journal can also come from the owner-values file instead of the store
(:class:`impctl.store.restore.owner_file.OwnerValuesJournal`), when the store is unusable.

The owner comes first here too: a register that holds neither what impctl last wrote there
and read back nor the journaled value was set by the owner since, and is kept. What impctl
last left there is the running night's (``held``) or, without one — a restart after the
process died, ``impctl restore`` — the one kept beside the journal entry; when neither is
known (a write not read back, a journal from before it was kept), the owner's value goes
back whatever the register holds.
"""

from __future__ import annotations

import asyncio
import logging
import sqlite3
import weakref
from collections.abc import Callable, Collection, Mapping
from typing import Any

from ..clock import VirtualClock
from ..errors import InputError, sqlite_problem
from ..heatpump import HeatPumpClient, HeatPumpError, ModbusLinkError
from ..store import JournalEntry, Store
from ..store.restore.owner_file import OwnerValuesJournal

_LOG = logging.getLogger(__name__)
#: Per journal (store): entries restored and verified by this process whose record failed
#: (entry id → why), until the record succeeds, a restore of them is tried again, or a night
#: journals them anew.
_UNRECORDED: weakref.WeakKeyDictionary[Any, dict[int, str]] = weakref.WeakKeyDictionary()
#: Per journal: entries whose register the owner set after impctl's last write (kept, not
#: restored), so that no later restore of this process writes over them when the store could
#: not record it.
_OWNER_KEPT: weakref.WeakKeyDictionary[Any, set[int]] = weakref.WeakKeyDictionary()
#: Per journal: told of each entry whose register the owner set (see :func:`on_owner_kept`).
_ON_OWNER_KEPT: weakref.WeakKeyDictionary[Any, list[Callable[[JournalEntry], None]]] = (
    weakref.WeakKeyDictionary())


def owner_kept(store) -> set[int]:
    """Entries of ``store``'s journal whose register the owner set after impctl's last write:
    this process never restores them (their record may have failed)."""
    return _OWNER_KEPT.setdefault(store, set())


def on_owner_kept(store, hook: Callable[[JournalEntry], None]) -> None:
    """Call ``hook(entry)`` whenever a restore from ``store``'s journal keeps the owner's value
    of ``entry``'s register. The restore does not know what else impctl drives that register
    by: the heating curve's watch must not set its curve over the owner's point at its next
    look (:func:`impctl.daemon.curve.intent.owner_kept_point`)."""
    _ON_OWNER_KEPT.setdefault(store, []).append(hook)


def unrecorded(store: Store) -> dict[int, str]:
    """Entries of ``store``'s journal that this process restored and verified but could not
    record (entry id → why, e.g. "disk full")."""
    return _UNRECORDED.setdefault(store, {})


def forget_unrecorded(store: Store, entry_id: int) -> None:
    """A night journaled ``entry_id`` again (it will write the register): its next restore
    must write and verify, not only record."""
    unrecorded(store).pop(entry_id, None)


async def restore_entry(client: HeatPumpClient, store: Store | OwnerValuesJournal,
                        entry: JournalEntry, held: float | None = None) -> bool:
    """Restore one journal entry; True when the read-back shows the owner's value and the
    journal records it, False when the heat pump is restored but the store could not record
    it (the entry stays pending, see :func:`unrecorded`). ``held``: the value impctl last left
    in the register (physical unit), when this process knows it; else the one kept beside the
    entry is used. A register that holds neither it nor the journaled value was set by the
    owner since, and is kept (the entry closed as theirs)."""
    forget_unrecorded(store, entry.id)
    if held is not None:
        reading = await client.read(entry.address + 1)
        if (reading.raw is not None and reading.value is not None
                and int(reading.raw) != entry.raw_value and abs(reading.value - held) > 1e-6):
            _owner_set(store, entry, int(reading.raw))
            return True
    elif entry.confirmed_raw is not None:
        reading = await client.read(entry.address + 1)
        if (reading.raw is not None and reading.value is not None
                and int(reading.raw) not in (entry.raw_value, entry.confirmed_raw)
                and _confirmed(store, entry) == entry.confirmed_raw):
            _owner_set(store, entry, int(reading.raw))
            return True
    await client.restore_raw(entry.address + 1, entry.raw_value)
    _LOG.info("restored %s (register %d) to raw %d, verified by read-back", entry.register,
              entry.address + 1, entry.raw_value)
    return record_restored(store, entry)


def _confirmed(store: Store | OwnerValuesJournal, entry: JournalEntry) -> int | None:
    """What impctl holds in ``entry``'s register as recorded now, after the register was read:
    a night of another process (the daemon's, while ``impctl restore`` runs) clears it before
    each write, so a value it wrote since reads as not confirmed and the owner's value goes
    back rather than keeping the experiment's. None when it cannot be read."""
    try:
        return store.journal_confirmed(entry.id)
    except sqlite3.Error:
        return None


def _owner_set(store: Store | OwnerValuesJournal, entry: JournalEntry, raw: int) -> None:
    """The owner set ``entry``'s register (to ``raw``) after impctl last wrote it: kept."""
    owner_kept(store).add(entry.id)
    what = (f"{entry.register} (register {entry.address + 1}) set to raw {raw} after "
            f"impctl's last write: the owner's value kept, raw {entry.raw_value} not restored")
    _LOG.warning("%s", what)
    # told before the entry closes: a process dying between the two leaves the entry pending
    # (the next restore keeps the point again), never a closed entry nobody acted on
    for hook in _ON_OWNER_KEPT.get(store, ()):
        hook(entry)
    try:
        store.journal_mark_owner_changed(entry.id, raw)
    except sqlite3.Error as exc:  # kept all the same: this process never restores it
        _LOG.error("cannot record that the owner changed %s: %s", entry.register,
                   sqlite_problem(exc))
        return
    _event(store, "warning", what)


def journal_to_restore(store: Store, log: logging.Logger = _LOG
                       ) -> Store | OwnerValuesJournal | None:
    """The journal a night restores from: the store's, or — when the store cannot even be
    read (an I/O error of the card, a damaged file) — the copy of the owner's values kept
    beside it; None when neither can be read (one line names the registers to check)."""
    try:
        store.journal_pending()
        return store
    except sqlite3.Error as exc:
        problem = sqlite_problem(exc)
    try:
        copy = OwnerValuesJournal(store.owner_file)
    except (OSError, InputError) as exc:
        log.critical("cannot restore: the store cannot be read (%s) and neither can the copy "
                     "of the owner's values (%s); check register 2187 (loop1_setpoint) and "
                     "register 2042 (loop1_mode) on the heat pump", problem, exc)
        return None
    log.error("the store cannot be read (%s): restoring from %s", problem, store.owner_file)
    return copy


def record_restored(store: Store, entry: JournalEntry) -> bool:
    """Record that ``entry`` is back on the heat pump (verified); False when the store
    cannot (remembered in :func:`unrecorded`; the heat pump comes first, the record later)."""
    try:
        store.journal_mark_restored(entry.id)
    except sqlite3.Error as exc:
        unrecorded(store)[entry.id] = sqlite_problem(exc)
        return False
    unrecorded(store).pop(entry.id, None)
    _event(store, "info", f"restored {entry.register} (register {entry.address + 1}) to raw "
                          f"{entry.raw_value}")
    return True


def _said_unrecorded(store: Store) -> None:
    why = sorted(set(unrecorded(store).values()))
    _LOG.error("the owner's settings are back on the heat pump, verified by read-back, but "
               "the store cannot record it (%s); the next start or impctl restore closes the "
               "journal", ", ".join(why))


async def restore_all(client: HeatPumpClient, store: Store | OwnerValuesJournal, *,
                      clock: VirtualClock, timeout_s: float, retry_s: float = 5.0,
                      keep: Collection[str] = (),
                      held: Mapping[str, float] | None = None) -> list[JournalEntry]:
    """Restore every pending journal entry (but those of the registers in ``keep``: a heating
    curve the owner asked for stays when a night ends), retrying while the link is down.

    Parameters
    ----------
    client : a connected (or reconnectable) HeatPumpClient
    store : the store holding the journal, or the owner-values file's journal
    clock : for the timeout, counted on its monotonic clock (a wall-clock step neither
        shortens nor prolongs it)
    timeout_s : give up after this many (simulated) seconds; entries stay pending
    retry_s : pause between attempts [wall s]
    keep : register names whose pending entries are left pending
    held : register name → the value impctl last left there (physical unit; a night's own
        restore): a register set to anything else since, by the owner, is kept; for a
        register not in it, the value kept beside its journal entry is used

    Returns
    -------
    The entries still pending (empty when everything was restored and verified).
    """
    deadline = clock.monotonic_s() + timeout_s
    reported = False
    skip = unrecorded(store)
    owners = owner_kept(store)
    held = held or {}

    def pending() -> list[JournalEntry]:
        return [e for e in store.journal_pending()
                if e.id not in skip and e.id not in owners and e.register not in keep]
    for entry in store.journal_pending():  # restored earlier by this process: record only
        if entry.id in skip:
            record_restored(store, entry)
    while True:
        todo = pending()
        if not todo:
            return _done(store, keep)
        for entry in todo:
            try:
                await restore_entry(client, store, entry, held.get(entry.register))
            except HeatPumpError as exc:
                if not reported:  # one line per incident, not one per retry
                    if isinstance(exc, ModbusLinkError):
                        _LOG.warning("restore of %s waits for the heat pump link: %s",
                                     entry.register, exc)
                        _event(store, "warning", f"restore waiting for link: {exc}")
                    else:
                        _LOG.error("restore of %s failed (retrying): %s", entry.register, exc)
                        _event(store, "error", f"restore of {entry.register} failed: {exc}")
                    reported = True
                if isinstance(exc, ModbusLinkError):
                    break  # the link is down: the other entries cannot get through either
                # Else try the other entries anyway: heating back on matters most.
        if not pending():
            if reported:
                _LOG.info("restore completed after the heat pump answered again")
            return _done(store, keep)
        if clock.monotonic_s() >= deadline:
            left = pending()
            _LOG.error("restore incomplete after %.0f s: %s still pending", timeout_s,
                       ", ".join(e.register for e in left))
            return left
        await asyncio.sleep(retry_s)
        try:
            if not client.link.connected:
                await client.link.connect(max_wait_s=retry_s)
        except ModbusLinkError:
            pass


def _done(store: Store, keep: Collection[str] = ()) -> list[JournalEntry]:
    """Everything is back and verified: drop the owner-values copy (unless it still holds
    entries left pending on purpose, ``keep``), and say so once when the store could not
    record it."""
    if unrecorded(store):
        _said_unrecorded(store)
        if not any(e.register in keep for e in store.journal_pending()):
            store.forget_owner_values()
    return []


def _event(store: Store, level: str, message: str) -> None:
    try:
        store.add_event(level, message)
    except sqlite3.Error as exc:  # never let the bookkeeping stop a restore
        _LOG.error("cannot record event %r: %s", message, exc)
