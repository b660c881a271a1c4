"""The owner's hand on the heat pump during a night: what changed behind impctl's back.

impctl remembers what it last put in the loop-1 setpoint (2187) and mode (2042). At a sample,
a value that differs from it was set by someone else — the owner at the controller, a
thermostat app, ``impctl restore`` — and a heating system switched off (2012 = 0) is the
owner's choice too. The night controller ends the night on any of these.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..heatpump import Snapshot

_SETPOINT, _MODE, _SYSTEM_ON = 2187, 2042, 2012
_NAMES = {_SETPOINT: "loop1 setpoint", _MODE: "loop1 mode"}


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
    out = []
    for ma, reading in ((_SETPOINT, snap.loop1_setpoint_c), (_MODE, snap.loop1_mode)):
        value = held.get(ma)
        if value is None or reading.value is None or reading.raw is None:
            continue
        if abs(reading.value - value) > 1e-6:
            out.append(OwnerChange(ma, value, reading.value, int(reading.raw)))
    if snap.system_on.value == 0:
        out.append(OwnerChange(_SYSTEM_ON, None, 0.0, 0))
    return out


def describe_changes(changes: list[OwnerChange]) -> str:
    """E.g. ``loop1 mode (2042) 0 → 1``."""
    return "; ".join(
        "heating system switched off (2012 = 0)" if c.ma == _SYSTEM_ON else
        f"{_NAMES[c.ma]} ({c.ma}) {fmt_register(c.ma, c.held)} → {fmt_register(c.ma, c.value)}"
        for c in changes)
