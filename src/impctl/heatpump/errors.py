"""Failures of the heat-pump link and of safe writes (bad configuration raises InputError)."""

from __future__ import annotations

#: Modbus exception codes that say "not now" rather than "never": 5 acknowledge, 6 device
#: busy, 10 gateway path unavailable, 11 gateway target device failed to respond (a collision
#: with a second master or noise on the RS-485 side).
TRANSIENT_EXCEPTIONS = frozenset({5, 6, 10, 11})


class HeatPumpError(Exception):
    """Base class of every heat-pump failure that is not bad input."""


class ModbusLinkError(HeatPumpError):
    """No answer: not connected, connect loop gave up, timeout after retries, dropped link."""


class ModbusDeviceError(HeatPumpError):
    """The device answered with a Modbus exception response.

    Attributes
    ----------
    exception_code : int
        The Modbus exception code (1 illegal function, 2 illegal address, 3 illegal value,
        4 device failure, 6 busy, 11 gateway target failed to respond …).
    address : int
        Zero-based PDU address of the request.
    """

    def __init__(self, message: str, exception_code: int, address: int) -> None:
        super().__init__(message)
        self.exception_code = exception_code
        self.address = address

    @property
    def transient(self) -> bool:
        """Whether the code means "try again later" (5, 6, 10, 11)."""
        return self.exception_code in TRANSIENT_EXCEPTIONS


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
