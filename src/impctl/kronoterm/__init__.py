"""What a Kronoterm heat pump's registers mean: the map, their encodings, the controller
generations and one decoded snapshot. No I/O of its own beyond :func:`detect`'s probe reads
through a link of :mod:`impctl.modbus`; :mod:`impctl.heatpump` builds the safe client on it.

Public surface::

    Register, Kind, Access, Generation, REGISTERS, register, registers_for, FORBIDDEN_WRITES
    decode, encode, Reading           raw words ↔ physical values (with sentinels → missing)
    Snapshot                          one read of every polled register, decoded
    GenerationReport                  the evidence of which controller generation answers
"""

from .decode import Reading, decode, encode
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

__all__ = [
    "FORBIDDEN_WRITES",
    "REGISTERS",
    "Access",
    "Generation",
    "GenerationReport",
    "Kind",
    "Reading",
    "Register",
    "Snapshot",
    "decode",
    "encode",
    "register",
    "registers_for",
]
