"""A Modbus master link that survives real gateways: FC 03 reads, FC 06 writes, nothing else.

Knows nothing of any device's register map; :mod:`impctl.heatpump` builds the Kronoterm model
on top of it.

Public surface::

    ModbusLink(config)        connect / read / write / settle / reset, with reconnects
    LinkConfig                TCP gateway or RTU line, timeouts, retries, attribution knobs
    LinkStats                 counters of one link
    to_int16, to_word, uint32, uint32_words   register-word encodings
    errors: ModbusError, ModbusLinkError, ModbusDeviceError, TRANSIENT_EXCEPTIONS
"""

from .config import LinkConfig
from .errors import TRANSIENT_EXCEPTIONS, ModbusDeviceError, ModbusError, ModbusLinkError
from .link import LinkStats, ModbusLink
from .words import to_int16, to_word, uint32, uint32_words

__all__ = [
    "TRANSIENT_EXCEPTIONS",
    "LinkConfig",
    "LinkStats",
    "ModbusDeviceError",
    "ModbusError",
    "ModbusLink",
    "ModbusLinkError",
    "to_int16",
    "to_word",
    "uint32",
    "uint32_words",
]
