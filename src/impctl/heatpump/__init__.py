"""Kronoterm heat pump over Modbus: register map, decoding, safe client, virtual clock.

Built on the generic link of :mod:`impctl.modbus` (transport, reconnects, answer attribution).
The configuration and failures of that link are re-exported here because the client's
configuration holds a ``LinkConfig`` and its methods raise the link's errors.

Public surface::

    HeatPumpClient(config, clock=, budget=)   connect / snapshot / read / write / detect
    HeatPumpConfig, LinkConfig, ExternalRegister, WritePolicy, config_from_mapping
    Snapshot, Reading                          decoded values with timestamp and missing flag
    WriteBudget(path, daily_limit)             persistent per-register daily write budget
    VirtualClock(epoch, factor, wall_epoch_s)  real or accelerated time, shared by processes
    Register, Generation, REGISTERS, register, FORBIDDEN_WRITES
    errors: HeatPumpError, ModbusLinkError, ModbusDeviceError (from impctl.modbus),
            UnsupportedFeature, WriteRefused, WriteBudgetExceeded, WriteVerifyError
"""

from ..modbus import LinkConfig, ModbusDeviceError, ModbusLinkError
from .budget import WriteBudget
from .client import HeatPumpClient
from .clock import VirtualClock
from .config import ExternalRegister, HeatPumpConfig, WritePolicy, config_from_mapping
from .decode import Reading, decode, encode
from .errors import (
    HeatPumpError,
    UnsupportedFeature,
    WriteBudgetExceeded,
    WriteRefused,
    WriteVerifyError,
)
from .generation import GenerationReport
from .registers import (
    FORBIDDEN_WRITES,
    REGISTERS,
    Access,
    Generation,
    Kind,
    Register,
    register,
    registers_for,
)
from .snapshot import Snapshot
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
    "VirtualClock",
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
