"""Putting the owner's settings back outside a night: the orphan sweep at start (nights a dead
process left running) and the background restore of a journal still pending (a night's own
restore gave up while the link was down; the link came back later)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import sqlite3

from ..controller.restore import owner_kept, record_restored, restore_entry, unrecorded
from ..heatpump import HeatPumpError, ModbusLinkError
from ..store import Store
from .running import RunningDaemon

_LOG = logging.getLogger("impctl.daemon")
# "planned" too: a night created just before the process died never reached "preparing".
_INTERRUPTED = ("planned", "preparing", "active", "restoring")


def sweep_orphans(store: Store) -> list[int]:
    """Mark nights that were running when the process died as interrupted (not valid)."""
    ids = []
    for night in store.nights(states=_INTERRUPTED):
        store.interrupt_night(night.id, "interrupted: impctl stopped during the night")
        store.add_event("warning", f"night {night.id} was interrupted; restoring")
        ids.append(night.id)
    return ids


def _todo(daemon: RunningDaemon) -> list:
    """The journal entries to put back: pending, but for those the owner set since impctl's
    last write (:func:`~impctl.controller.restore.owner_kept`)."""
    kept = owner_kept(daemon.store)
    return [e for e in daemon._restorable() if e.id not in kept]


async def restore_pending(daemon: RunningDaemon) -> None:
    """Put the owner's settings back whenever the journal holds any and no night runs.

    A night's own restore gives up after ``restore_timeout_s`` (the journal stays
    pending); without this loop a link that comes back later would leave the heating in
    the experiment's state until the next night or restart.
    """
    interval = max(0.5, min(5.0, daemon.clock.wall_seconds(daemon.cfg.night.sample_interval_s)))
    waiting = False
    while True:
        await asyncio.sleep(interval)
        try:
            todo = _todo(daemon)
        except sqlite3.Error as exc:  # a damaged store: look again, never end this loop
            _LOG.error("cannot read the restore journal: %s", exc)
            continue
        if (daemon.stop.is_set() or not daemon._connected.is_set()
                or daemon._heat_pump_lock.locked() or not todo):
            continue
        async with daemon._heat_pump_lock:
            restored = False
            try:
                for entry in _todo(daemon):
                    if entry.id in unrecorded(daemon.store):
                        # Back on the heat pump and verified; only the record failed
                        # (a full disk): try the record alone, quietly, until it works.
                        record_restored(daemon.store, entry)
                        continue
                    await restore_entry(daemon.client, daemon.store, entry)
                    restored = True
            except (ModbusLinkError, HeatPumpError) as exc:
                if not waiting:  # one line per incident, not one per retry
                    _LOG.warning("owner's settings still to restore: %s", exc)
                    with contextlib.suppress(sqlite3.Error):
                        daemon.store.add_event("warning", f"restore pending: {exc}")
                    daemon._status("RESTORE PENDING: waiting for the heat pump")
                    waiting = True
                continue
            except sqlite3.Error as exc:  # a damaged store: look again, never end this loop
                _LOG.error("cannot read the restore journal: %s", exc)
                continue
        if restored:
            _LOG.info("owner's settings restored%s", " after the link came back"
                      if waiting else "")
            waiting = False
            daemon._status(daemon._idle_status())
