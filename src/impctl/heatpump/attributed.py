"""Reads whose words are used only when every answer on the link can be attributed.

On RTU an answer has no transaction id: another master's answer of the right length that
crosses the line first is taken for ours, and only the real answer arriving after it (extra
bytes, counted by :mod:`impctl.modbus.attribution`) shows the mix-up. Every read whose words
decide something — a value stored, the compare before a write, a write's read-back — goes
through :func:`attributed`; a snapshot's blocks do the same as a group.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable

from ..modbus import ModbusLink

#: Reads of one register or group before it is given up as unattributable.
TRIES = 3


def unattributable(link: ModbusLink, outcome: str = "sample marked missing") -> str:
    """Why a read's words were not used (the quirks the link recognised) and what followed."""
    return f"unattributable answers on the link ({', '.join(link.quirks)}); {outcome}"


async def attributed(link: ModbusLink, read: Callable[[], Awaitable[list[int]]]
                     ) -> list[int] | None:
    """The words of ``read()`` (a read on ``link``), or None when an answer on the link could
    not be attributed to its request while it ran, :data:`TRIES` times.

    The settle (RTU only; TCP needs no wait) lets the real answer that a foreign one overtook
    arrive and be counted before the words are used. Such words are never used: the caller
    treats the value as missing. Link failures and exception answers propagate.
    """
    for _ in range(TRIES):
        before = link.anomalies
        words = await read()
        await link.settle()
        if link.anomalies == before:
            return words
        link.reset()
    return None
