"""The simulator's side of pymodbus' server: which requests are decoded at all, which handler
class a connection gets, and where the server may listen.

Only FC 03 and FC 06 reach the simulated controller; any other function code is decoded as a
request that is refused with exception 1, an FC 03 count outside 1–125 as one refused with
exception 3 (as the Modbus specification says). What the controller answers is
:mod:`.server`'s business.
"""

from __future__ import annotations

import ipaddress

from pymodbus.pdu import DecodePDU, ModbusPDU
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler

from impctl.errors import InputError


class Unsupported(ModbusPDU):
    """Any request other than FC 03/06: answered with "illegal function"."""

    def __init__(self, function_code: int) -> None:
        super().__init__()
        self.function_code = function_code

    def decode(self, data: bytes) -> None:
        """Nothing to decode; the request is refused whatever it holds."""


class BadCount(Unsupported):
    """FC 03 with a register count outside 1–125: answered with exception 3."""


class Fc3Fc6Decoder(DecodePDU):
    """pymodbus' decoder, narrowed to what the simulated controller serves: FC 03 and 06."""

    def decode(self, frame: bytes) -> ModbusPDU | None:
        if frame and frame[0] == 3 and len(frame) >= 5:
            if not 1 <= int.from_bytes(frame[3:5], "big") <= 125:
                return BadCount(3)
        if frame and frame[0] in (3, 6):
            return super().decode(frame)
        return Unsupported(frame[0] & 0x7F) if frame else None


class _HandlerMixin:
    # pymodbus builds its own handler per connection; this lets the simulator choose the class.
    handler_class: type[ServerRequestHandler] = ServerRequestHandler

    def callback_new_connection(self):
        return self.handler_class(self, self.trace_packet, self.trace_pdu, self.trace_connect)


class TcpServer(_HandlerMixin, ModbusTcpServer):
    """Modbus TCP server whose connections use ``handler_class``."""


class SerialServer(_HandlerMixin, ModbusSerialServer):
    """Modbus RTU server whose connection uses ``handler_class``."""


def require_loopback(host: str) -> None:
    """Refuse (InputError) a non-loopback address; callers with allow_remote skip the check."""
    try:
        loopback = host == "localhost" or ipaddress.ip_address(host).is_loopback
    except ValueError:
        loopback = False
    if not loopback:
        raise InputError(f"refusing to listen on {host!r}: the simulator binds to loopback "
                         "unless allow_remote / --allow-remote is given", place="--host")
