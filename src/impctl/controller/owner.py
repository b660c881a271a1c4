"""The owner's values and the owner's hand on the heat pump during a night.

Before a night's first write the owner's loop-1 setpoint (2187) and mode (2042) are journaled
(:func:`journal_owner`). impctl remembers what it last put there. At a sample,
a value that differs from it was set by someone else — the owner at the controller, a
thermostat app, ``impctl restore`` — and a heating system switched off (2012 = 0) is the
owner's choice too. The night controller ends the night on any of these.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from datetime import date

from ..heatpump import HeatPumpError, Reading, Snapshot
from .plan import NightRefused
from .restore import forget_unrecorded

_SETPOINT, _MODE, _SYSTEM_ON = 2187, 2042, 2012
_NAMES = {_SETPOINT: "loop1 setpoint", _MODE: "loop1 mode"}
#: The journal's names of the registers a night writes, by register number.
JOURNAL_NAMES = {_SETPOINT: "loop1_setpoint", _MODE: "loop1_mode"}


@dataclass(frozen=True)
class OwnerChange:
    """One register the owner changed: its number, impctl's value, the owner's value and raw
    word (°C for the setpoint, the code for modes)."""

    ma: int
    held: float | None
    value: float | None
    raw: int


def fmt_register(ma: int, value: float | None) -> str:
    """A register value as people write it: modes as integers ("1"), setpoints in °C."""
    if value is None:
        return "—"
    return f"{value:.1f} °C" if ma == _SETPOINT else f"{value:.0f}"


def owner_changes(snap: Snapshot | None, held: dict[int, float]) -> list[OwnerChange]:
    """The registers whose value in ``snap`` differs from ``held`` (what impctl last put
    there), plus the heating system switched off; empty when nothing changed or unknown."""
    if snap is None:
        return []
    out = register_changes({_SETPOINT: snap.loop1_setpoint_c, _MODE: snap.loop1_mode}, held)
    if snap.system_on.value == 0:
        out.append(OwnerChange(_SYSTEM_ON, None, 0.0, 0))
    return out


def register_changes(readings: Mapping[int, Reading], held: dict[int, float]
                     ) -> list[OwnerChange]:
    """The registers (number → reading) whose value differs from ``held``; a register
    without a held value or a reading is not judged."""
    out = []
    for ma, reading in readings.items():
        value = held.get(ma)
        if value is None or reading.value is None or reading.raw is None:
            continue
        if abs(reading.value - value) > 1e-6:
            out.append(OwnerChange(ma, value, reading.value, int(reading.raw)))
    return out


def describe_changes(changes: list[OwnerChange]) -> str:
    """E.g. ``loop1 mode (2042) 0 → 1``."""
    return "; ".join(
        "heating system switched off (2012 = 0)" if c.ma == _SYSTEM_ON else
        f"{_NAMES[c.ma]} ({c.ma}) {fmt_register(c.ma, c.held)} → {fmt_register(c.ma, c.value)}"
        for c in changes)


def keep_owner_changes(store, changes: list[OwnerChange]) -> str | None:
    """The owner changed these registers mid-night: their journal entries are closed (the
    restore puts back only what the owner did not touch, never over their new choice) and an
    event says so. Returns the night's abort reason; None when nothing changed."""
    if not changes:
        return None
    for change in changes:
        for entry in store.journal_pending():
            if entry.register == JOURNAL_NAMES.get(change.ma):
                store.journal_mark_owner_changed(entry.id, change.raw)
    what = describe_changes(changes)
    store.add_event("warning", f"owner changed the heat pump mid-night: {what}")
    return f"owner changed the heat pump mid-night: {what}; night ended, the owner's setting kept"


async def taken_back(client, store, entries: Mapping[int, int], held: dict[int, float],
                     log) -> str | None:
    """Before a switch-off, which comes a sample interval after the last look: the night's
    journal entries (register → entry id) must still be pending and the registers must still
    hold what impctl left there (``held``). ``impctl restore`` or the household may have put
    the owner's values back since; switching off then would leave the heating off with
    nothing left to restore. Returns why the night ends instead (an owner's change is kept as
    :func:`keep_owner_changes` keeps it), None to go on; a register that cannot be read now
    is left to the write's own checks and the next sample's."""
    pending = {e.id for e in store.journal_pending()}
    closed = [JOURNAL_NAMES[ma] for ma in (_SETPOINT, _MODE) if entries.get(ma) not in pending]
    if closed:
        return (f"the owner's {' and '.join(closed)} put back from outside (impctl restore) "
                "before the switch-off; night ended without switching off")
    readings = {}
    for ma in (_SETPOINT, _MODE):
        try:
            readings[ma] = await client.read(ma)
        except HeatPumpError as exc:
            log.info("register %d not read before the switch-off: %s", ma, exc)
    return keep_owner_changes(store, register_changes(readings, held))


async def journal_owner(client, store, night_id: int, day: date
                        ) -> tuple[dict[int, int], dict[int, float]]:
    """Journal the owner's loop-1 setpoint and mode before the night's first write (and, by
    the store, in the copy beside it): (journal entry id, the owner's value) by register.

    Raises :class:`~.plan.NightRefused`, nothing written, when the daily write budget of
    ``day`` cannot pay the night and its restore, a register cannot be read, it holds a
    value the restore could not put back (an undocumented mode code, a sentinel: the heating
    would stay as the night left it), or the copy cannot be written."""
    budget = client.budget
    if budget is None:
        raise NightRefused("no write budget configured: writes are refused")
    for ma in (_SETPOINT, _MODE):
        if budget.remaining(ma, day) < 2:
            raise NightRefused(f"daily write budget of register {ma} nearly used up "
                               f"({budget.used(ma, day)}/{budget.limit(ma)})")
    readings = {ma: await client.read(ma) for ma in (_SETPOINT, _MODE)}
    for ma, reading in readings.items():
        name = JOURNAL_NAMES[ma]
        if reading.raw is None:
            raise NightRefused(f"cannot read {name} ({ma}) to journal it: {reading.reason}")
        why = client.unrestorable(ma, int(reading.raw))
        if reading.value is None or why is not None:
            raise NightRefused(f"{name} ({ma}) reads raw {int(reading.raw)}, which impctl "
                               f"could not put back: {why or reading.reason}")
    entries, values = {}, {}
    for ma, reading in readings.items():
        try:  # what it holds now is impctl's to tell the owner's later change by (.held)
            entry = store.journal_record(night_id, JOURNAL_NAMES[ma], ma - 1, int(reading.raw),
                                         confirmed_raw=int(reading.raw))
        except OSError as exc:  # the copy outside the store; nothing written yet
            raise NightRefused(f"cannot keep the owner's values in {store.owner_file}: "
                               f"{exc.strerror or exc}") from None
        forget_unrecorded(store, entry.id)  # this night writes it: restore anew
        entries[ma], values[ma] = entry.id, reading.value
    return entries, values
