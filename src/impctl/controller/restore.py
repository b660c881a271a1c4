"""Put the owner's settings back: the journal → the heat pump, verified by read-back.

Used at a night's end, on every abort, on SIGTERM, by ``impctl restore`` (also systemd's
ExecStopPost) and by the orphan sweep at daemon start. A restore writes the journaled raw
value verbatim: it is the owner's value, so it is not clamped to impctl's experiment limits.
"""

from __future__ import annotations

import asyncio
import logging
import sqlite3
from collections.abc import Collection

from ..clock import VirtualClock
from ..heatpump import HeatPumpClient, HeatPumpError, ModbusLinkError
from ..store import JournalEntry, Store

_LOG = logging.getLogger(__name__)


async def restore_entry(client: HeatPumpClient, store: Store, entry: JournalEntry) -> bool:
    """Restore one journal entry; True when the read-back shows the owner's value and the
    journal records it, False when the heat pump is restored but the store could not record
    it (the entry stays pending; restoring it again writes nothing)."""
    await client.restore_raw(entry.address + 1, entry.raw_value)
    _LOG.info("restored %s (register %d) to raw %d, verified by read-back", entry.register,
              entry.address + 1, entry.raw_value)
    try:
        store.journal_mark_restored(entry.id)
        store.add_event("info", f"restored {entry.register} (register {entry.address + 1}) "
                                f"to raw {entry.raw_value}")
    except sqlite3.Error as exc:  # the heat pump comes first; the record can follow later
        _LOG.error("restored %s, but the store cannot record it: %s", entry.register, exc)
        return False
    return True


async def restore_all(client: HeatPumpClient, store: Store, *, clock: VirtualClock,
                      timeout_s: float, retry_s: float = 5.0,
                      keep: Collection[str] = ()) -> list[JournalEntry]:
    """Restore every pending journal entry (but those of the registers in ``keep``: a heating
    curve the owner asked for stays when a night ends), retrying while the link is down.

    Parameters
    ----------
    client : a connected (or reconnectable) HeatPumpClient
    store : the store holding the journal
    clock : for the simulated-time timeout
    timeout_s : give up after this many (simulated) seconds; entries stay pending
    retry_s : pause between attempts [wall s]
    keep : register names whose pending entries are left pending

    Returns
    -------
    The entries still pending (empty when everything was restored and verified).
    """
    deadline = clock.now_s() + timeout_s
    reported = False
    unrecorded: set[int] = set()  # restored on the heat pump, the store could not say so
    while True:
        pending = [e for e in store.journal_pending()
                   if e.id not in unrecorded and e.register not in keep]
        if not pending:
            return []
        for entry in pending:
            try:
                if not await restore_entry(client, store, entry):
                    unrecorded.add(entry.id)
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
        if not [e for e in store.journal_pending()
                if e.id not in unrecorded and e.register not in keep]:
            if reported:
                _LOG.info("restore completed after the heat pump answered again")
            return []
        if clock.now_s() >= deadline:
            left = [e for e in store.journal_pending() if e.register not in keep]
            _LOG.error("restore incomplete after %.0f s: %s still pending", timeout_s,
                       ", ".join(e.register for e in left))
            return left
        await asyncio.sleep(retry_s)
        try:
            if not client.link.connected:
                await client.link.connect(max_wait_s=retry_s)
        except ModbusLinkError:
            pass


def _event(store: Store, level: str, message: str) -> None:
    try:
        store.add_event(level, message)
    except sqlite3.Error as exc:  # never let the bookkeeping stop a restore
        _LOG.error("cannot record event %r: %s", message, exc)
