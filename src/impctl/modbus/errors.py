"""Failures of a Modbus link and of the device behind it (bad configuration raises InputError)."""

from __future__ import annotations

#: Modbus exception codes that say "not now" rather than "never": 5 acknowledge, 6 device
#: busy, 10 gateway path unavailable, 11 gateway target device failed to respond (a collision
#: with a second master or noise on the RS-485 side).
TRANSIENT_EXCEPTIONS = frozenset({5, 6, 10, 11})


class ModbusError(Exception):
    """Base class of every failure to get a good answer from a Modbus device.

    A package that models a device on top of the link derives its own failures from it (see
    :class:`impctl.heatpump.HeatPumpError`), so one ``except`` covers the wire and the device.
    """


class ModbusLinkError(ModbusError):
    """No answer: not connected, connect loop gave up, timeout after retries, dropped link."""


class ModbusDeviceError(ModbusError):
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
