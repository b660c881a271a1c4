"""Kronoterm heat pump over Modbus: the safe client (clamped, read-back, budgeted writes),
its configuration and its health record.

Built on the generic link of :mod:`impctl.modbus` (transport, reconnects, answer attribution)
and on :mod:`impctl.kronoterm` (what the registers mean). The link's configuration and
failures, and the register types the client takes and returns, are re-exported here because
the client's configuration holds a ``LinkConfig``, its methods raise the link's errors and
return :class:`Snapshot` / :class:`Reading`.

Public surface::

    HeatPumpClient(config, clock=, budget=)   connect / snapshot / read / write / detect
    HeatPumpConfig, LinkConfig, ExternalRegister, WritePolicy, config_from_mapping
    Snapshot, Reading                          decoded values with timestamp and missing flag
    WriteBudget(path, daily_limit)             persistent per-register daily write budget
    Register, Generation, REGISTERS, register, FORBIDDEN_WRITES   (from impctl.kronoterm)
    errors: HeatPumpError, ModbusLinkError, ModbusDeviceError (from impctl.modbus),
            UnsupportedFeature, WriteRefused, WriteBudgetExceeded, WriteVerifyError
"""

from ..kronoterm import (
    FORBIDDEN_WRITES,
    REGISTERS,
    Access,
    Generation,
    GenerationReport,
    Kind,
    Reading,
    Register,
    Snapshot,
    decode,
    encode,
    register,
    registers_for,
)
from ..modbus import LinkConfig, ModbusDeviceError, ModbusLinkError
from .budget import WriteBudget
from .client import HeatPumpClient
from .config import ExternalRegister, HeatPumpConfig, WritePolicy, config_from_mapping
from .errors import (
    HeatPumpError,
    UnsupportedFeature,
    WriteBudgetExceeded,
    WriteRefused,
    WriteVerifyError,
)
from .writes import WriteResult, write_rules

__all__ = [
    "FORBIDDEN_WRITES",
    "REGISTERS",
    "Access",
    "ExternalRegister",
    "Generation",
    "GenerationReport",
    "HeatPumpClient",
    "HeatPumpConfig",
    "HeatPumpError",
    "Kind",
    "LinkConfig",
    "ModbusDeviceError",
    "ModbusLinkError",
    "Reading",
    "Register",
    "Snapshot",
    "UnsupportedFeature",
    "WriteBudget",
    "WriteBudgetExceeded",
    "WritePolicy",
    "WriteRefused",
    "WriteResult",
    "WriteVerifyError",
    "config_from_mapping",
    "decode",
    "encode",
    "register",
    "registers_for",
    "write_rules",
]
