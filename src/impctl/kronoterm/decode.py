"""Raw register words ⇄ physical values, with sentinels turned into "missing".

Decoding never hands out a sentinel or an implausible number as a temperature: −600 (sensor not
connected), any raw ≤ −500 (error code), −400 and 0 on room-thermostat registers (no thermostat),
5000 on 2024 (DHW off), and any temperature outside −60…150 °C all come back as a
:class:`Reading` with ``missing=True``, ``value=None`` and the reason.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime

from ..errors import InputError
from ..modbus.words import to_int16, to_word, uint32
from .registers import ERROR_RAW_AT_OR_BELOW, TEMP_VALID_C, Kind, Register


@dataclass(frozen=True)
class Reading:
    """One decoded value with its time and a missing flag.

    Attributes
    ----------
    name : str
        Register or quantity name (e.g. ``"t_outdoor"``).
    value : float or None
        Physical value in ``unit``; ``None`` exactly when ``missing``.
    unit : str
        Unit of ``value``.
    timestamp : datetime
        Time zone-aware time of the read (the client's clock).
    missing : bool
        No valid value (sentinel, out of range, unavailable on this controller, read failed).
    reason : str
        Why the value is missing; empty when it is not.
    raw : int or None
        The raw value as read (signed for int16, unsigned for bitmasks and uint32).
    source : str
        Where it came from, e.g. ``"register 2103"`` or ``"heat meter 30/0"``.
    """

    name: str
    value: float | None
    unit: str
    timestamp: datetime
    missing: bool = False
    reason: str = ""
    raw: int | None = None
    source: str = ""

    def require(self) -> float:
        """The value, or :class:`~impctl.errors.InputError` naming the register and reason."""
        if self.missing or self.value is None:
            raise InputError(f"{self.name} has no valid value: {self.reason}", "heat pump",
                             self.source or None)
        return self.value

    @classmethod
    def unavailable(cls, name: str, unit: str, timestamp: datetime, reason: str,
                    source: str = "") -> Reading:
        """A missing reading that was never read (e.g. not on this controller)."""
        return cls(name, None, unit, timestamp, True, reason, None, source)


def decode(reg: Register, words: Sequence[int], timestamp: datetime) -> Reading:
    """Decode the ``reg.words`` register words read for ``reg``.

    Parameters
    ----------
    reg : Register
    words : sequence of int
        Unsigned 16-bit words exactly as received (``reg.words`` of them).
    timestamp : datetime
        Time of the read.

    Returns
    -------
    Reading
        ``missing=True`` for sentinels, undocumented enum codes and out-of-range temperatures.
    """
    if len(words) != reg.words:
        raise ValueError(f"register {reg.ma} needs {reg.words} word(s), got {len(words)}")
    source = f"register {reg.ma}"
    if reg.kind is Kind.UINT32:
        raw = uint32(words)
        return Reading(reg.name, raw * reg.scale, reg.unit, timestamp, raw=raw, source=source)
    if reg.kind is Kind.BITS:
        return Reading(reg.name, float(words[0]), reg.unit, timestamp, raw=words[0],
                       source=source)
    raw = to_int16(words[0])

    def missing(reason: str) -> Reading:
        return Reading(reg.name, None, reg.unit, timestamp, True, reason, raw, source)

    if raw in reg.sentinels:
        return missing(reg.sentinels[raw])
    if reg.kind is Kind.ENUM:
        if reg.values is not None and raw not in reg.values:
            return missing(f"undocumented value {raw}")
        return Reading(reg.name, float(raw), reg.unit, timestamp, raw=raw, source=source)
    if reg.kind is Kind.TEMP:
        if raw <= ERROR_RAW_AT_OR_BELOW:
            return missing(f"sensor error code (raw {raw})")
        value = raw * reg.scale
        low, high = reg.valid if reg.valid is not None else TEMP_VALID_C
        if not low <= value <= high:
            return missing(f"{value:.1f} °C outside the {low:g}…{high:g} °C sanity range")
        return Reading(reg.name, round(value, 6), reg.unit, timestamp, raw=raw, source=source)
    value = raw * reg.scale
    if reg.valid is not None and not reg.valid[0] <= value <= reg.valid[1]:
        return missing(f"{value:g} {reg.unit} outside the plausible {reg.valid[0]:g}…"
                       f"{reg.valid[1]:g} {reg.unit}")
    return Reading(reg.name, round(value, 6), reg.unit, timestamp, raw=raw, source=source)


def encode(reg: Register, value: float) -> int:
    """Physical value → the register word to write (int16 two's complement).

    Raises
    ------
    InputError
        A multi-word register, or a value that does not fit a signed 16-bit register.
    """
    if reg.words != 1 or reg.kind is Kind.BITS:
        raise InputError("only single int16 registers can be written", place=f"register {reg.ma}")
    raw = round(value / reg.scale)
    try:
        return to_word(raw)
    except ValueError as exc:
        raise InputError(str(exc), place=f"register {reg.ma}") from None


def raw_value(reg: Register, word: int) -> float:
    """The physical value of one written/read-back int16 word (no sentinel handling)."""
    return round(to_int16(word) * reg.scale, 6)
