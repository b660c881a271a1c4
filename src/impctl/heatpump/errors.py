"""Failures of the heat-pump model and of safe writes (bad configuration raises InputError).

The link's failures (no answer, exception answer) live in :mod:`impctl.modbus.errors`.
"""

from __future__ import annotations

from ..modbus.errors import ModbusError

#: Base class of every heat-pump failure that is not bad input. It is the link's own base
#: class, so ``except HeatPumpError`` also catches a lost link (ModbusLinkError) and an
#: exception answer (ModbusDeviceError) — the device side handles all three alike.
HeatPumpError = ModbusError


class UnsupportedFeature(HeatPumpError):
    """The controller lacks what was asked for (e.g. thermal power on a compact TT3000)."""


class WriteRefused(HeatPumpError):
    """A write that the safety rules do not allow; nothing was sent."""


class WriteBudgetExceeded(WriteRefused):
    """The register's daily write budget is used up; nothing was sent."""


class WriteVerifyError(HeatPumpError):
    """The value read back after a write differs from the value written.

    Attributes
    ----------
    ma : int
        Documented register number.
    written : int
        Raw word sent.
    read_back : int or None
        Raw word read back (``None`` if the read-back itself failed).
    """

    def __init__(self, message: str, ma: int, written: int, read_back: int | None) -> None:
        super().__init__(message)
        self.ma = ma
        self.written = written
        self.read_back = read_back
