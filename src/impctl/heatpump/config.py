"""Configuration of the heat-pump link, external sensors and the write policy.

Bad values raise :class:`~impctl.errors.InputError` naming the key. :func:`config_from_mapping`
reads the same structure from a parsed TOML table::

    [heatpump]
    transport = "tcp"            # or "rtu"
    host = "192.168.1.50"
    port = 502
    # serial_port = "/dev/serial/by-id/usb-…"   (rtu; pyserial URLs such as socket:// work too)
    # baudrate = 115200
    device_id = 20
    timeout_s = 3.0
    tolerate_fixed_tid = false
    generation = "auto"          # "compact" | "extended"
    room_sensor = "loop1"        # "loop2" or a [heatpump.room_sensor] table (external)

    [heatpump.heat_meter]        # optional: Q_HC on a compact controller
    device_id = 30
    address = 0                  # zero-based PDU address on that device
    datatype = "uint32"
    scale = 1.0

    [heatpump.writes]
    loop1_setpoint_c = [16.0, 23.0]
    daily_budget = 12
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Literal

from ..errors import InputError

Transport = Literal["tcp", "rtu"]
#: Baud rates accepted for RTU; Kronoterm controllers use 19200 (TT3000, WPG) or 115200 (KSM).
BAUD_RATES = (9600, 19200, 38400, 57600, 115200)
DATATYPES = ("int16", "uint16", "int32", "uint32")


@dataclass(frozen=True)
class LinkConfig:
    """How to reach a Modbus device (TCP through an RS-485 gateway, or RTU, 8N1).

    Attributes
    ----------
    transport : {"tcp", "rtu"}
    host, port : TCP gateway address.
    serial_port : RTU device path or pyserial URL (``socket://host:port`` is RTU over TCP).
    baudrate : RTU baud rate (8 data bits, no parity, 1 stop bit).
    device_id : Modbus unit id (Kronoterm default 20).
    timeout_s : per-request response timeout and connect timeout [s].
    retries : accepted for old configurations and ignored: pymodbus' own resends are off,
        because a resend under the same transaction id lets a late answer complete a later
        request (issue 15); ``attempts`` does the retrying.
    attempts : tries of one read, with doubling back-off and a reconnect after a timeout
        (transient exceptions 5, 6, 10, 11 are retried; other exceptions are final).
    retry_delay_s : pause between tries [s].
    connect_backoff_s : first and maximum pause of the connect loop [s] (doubling).
    drain_s : wait after each connect before discarding unsolicited bytes (gateway greeting)
        [s]; 0 disables the drain.
    tolerate_fixed_tid : accept TCP responses whose transaction id does not match (gateways
        that answer with a fixed id); the connection is reset after any timeout then, so a late
        answer can never be taken for the next request's.
    request_gap_s : idle time between requests [s] (serial lines want ≥ 0.035).
    settle_s : RTU only: wait this long after each answer before accepting it, so that a
        real answer overtaken by a foreign or duplicated frame is seen [s] (issue 15).
    """

    transport: Transport = "tcp"
    host: str = "127.0.0.1"
    port: int = 502
    serial_port: str = ""
    baudrate: int = 19200
    device_id: int = 20
    timeout_s: float = 3.0
    retries: int = 1
    attempts: int = 3
    retry_delay_s: float = 1.0
    connect_backoff_s: tuple[float, float] = (0.5, 30.0)
    drain_s: float = 0.2
    tolerate_fixed_tid: bool = False
    request_gap_s: float = 0.0
    # -- issue 15: answer attribution (kept apart from the keys above) --
    settle_s: float = 0.05

    def __post_init__(self) -> None:
        if self.transport not in ("tcp", "rtu"):
            raise InputError(f"transport must be 'tcp' or 'rtu', got {self.transport!r}",
                             place="key 'transport'")
        if self.transport == "rtu" and not self.serial_port:
            raise InputError("rtu needs serial_port", place="key 'serial_port'")
        if self.transport == "rtu" and self.baudrate not in BAUD_RATES:
            raise InputError(f"baudrate must be one of {BAUD_RATES}", place="key 'baudrate'")
        if not 1 <= self.device_id <= 247:
            raise InputError("device_id must be 1–247", place="key 'device_id'")
        if not 0 < self.port < 65536:
            raise InputError("port must be 1–65535", place="key 'port'")
        if not self.timeout_s > 0 or self.retries < 0 or self.attempts < 1:
            raise InputError("need timeout_s > 0, retries >= 0, attempts >= 1",
                             place="key 'timeout_s'")
        lo, hi = self.connect_backoff_s
        if not 0 < lo <= hi:
            raise InputError("connect_backoff_s must be (first, max) with 0 < first <= max",
                             place="key 'connect_backoff_s'")
        if not 0 <= self.settle_s <= 10:
            raise InputError("settle_s must be 0–10 s", place="key 'settle_s'")
        if self.drain_s < 0 or self.request_gap_s < 0 or self.retry_delay_s < 0:
            raise InputError("drain_s, request_gap_s and retry_delay_s must be >= 0",
                             place="key 'drain_s'")

    def describe(self) -> str:
        """Human-readable endpoint, e.g. ``tcp 127.0.0.1:502 unit 20``."""
        where = (f"{self.host}:{self.port}" if self.transport == "tcp"
                 else f"{self.serial_port} {self.baudrate} 8N1")
        return f"{self.transport} {where} unit {self.device_id}"


@dataclass(frozen=True)
class ExternalRegister:
    """A value from another Modbus device (or another register): room sensor or heat meter.

    Attributes
    ----------
    device_id : unit id of the device.
    address : zero-based PDU address (not a Kronoterm MA number).
    datatype : "int16", "uint16", or "int32"/"uint32" (two registers, high word first).
    scale : physical value = raw × scale.
    valid : accepted range of the physical value; outside it the reading is missing.
    link : a separate link; ``None`` = the heat pump's own bus or gateway.
    """

    device_id: int
    address: int
    datatype: str = "int16"
    scale: float = 1.0
    valid: tuple[float, float] = (-1e9, 1e9)
    link: LinkConfig | None = None

    def __post_init__(self) -> None:
        if self.datatype not in DATATYPES:
            raise InputError(f"datatype must be one of {DATATYPES}", place="key 'datatype'")
        if not 0 <= self.address <= 0xFFFF or not 1 <= self.device_id <= 247:
            raise InputError("need 0 <= address <= 65535 and 1 <= device_id <= 247",
                             place="key 'address'")

    @property
    def words(self) -> int:
        """Registers occupied."""
        return 2 if self.datatype.endswith("32") else 1

    def describe(self) -> str:
        """E.g. ``device 30 address 0``."""
        return f"device {self.device_id} address {self.address}"


@dataclass(frozen=True)
class WritePolicy:
    """Which registers impctl may write, within which limits, how often.

    Loop-1 setpoint (2187) and loop-1 mode (2042) are always allowed; loop 2 (2049/2052) only
    with ``loop2_setpoint_c`` set, the ±4 K correction (2014) only with ``correction_k`` set.
    2017, 2018, 2113, 539 and 2197 are never written.

    Attributes
    ----------
    loop1_setpoint_c : (min, max) clamp for 2187 [°C].
    loop2_setpoint_c : (min, max) clamp for 2049 [°C]; ``None`` = loop 2 not writable.
    correction_k : (min, max) clamp for 2014 [K], within −4…4; ``None`` = not writable.
    daily_budget : writes per register per day (UTC day of the client's clock); build the
        budget with ``WriteBudget(path, policy.daily_budget)``.
    verify_attempts : read-backs after a write before it counts as failed.
    verify_delay_s : pause before each read-back [s] (the first answer may be stale).
    restore_reserve : writes per register per day beyond ``daily_budget`` that only restoring
        the owner's settings may use, so a spent budget never keeps the heating off.
    """

    loop1_setpoint_c: tuple[float, float] = (16.0, 23.0)
    loop2_setpoint_c: tuple[float, float] | None = None
    correction_k: tuple[int, int] | None = None
    daily_budget: int = 12
    verify_attempts: int = 3
    verify_delay_s: float = 0.5
    restore_reserve: int = 2

    def __post_init__(self) -> None:
        for key in ("loop1_setpoint_c", "loop2_setpoint_c"):
            limits = getattr(self, key)
            if limits is not None and not (5.0 <= limits[0] <= limits[1] <= 60.0):
                raise InputError("limits must satisfy 5 <= min <= max <= 60 °C",
                                 place=f"key '{key}'")
        if self.correction_k is not None and not (
            -4 <= self.correction_k[0] <= self.correction_k[1] <= 4
        ):
            raise InputError("limits must lie within -4…4 K", place="key 'correction_k'")
        if (self.daily_budget < 0 or self.restore_reserve < 0 or self.verify_attempts < 1
                or self.verify_delay_s < 0):
            raise InputError("need daily_budget >= 0, restore_reserve >= 0, "
                             "verify_attempts >= 1, verify_delay_s >= 0",
                             place="key 'daily_budget'")


@dataclass(frozen=True)
class HeatPumpConfig:
    """Everything the heat-pump client needs.

    Attributes
    ----------
    link : LinkConfig
    generation : "auto" (probe) | "compact" | "extended"
    room_sensor : "loop1" | "loop2" (Kronoterm thermostat 2160/2161) or an ExternalRegister
    heat_meter : ExternalRegister for Q_HC [W], required on a compact controller when an
        experiment needs the heat output; optional on extended ones (then preferred over 2329).
    writes : WritePolicy
    """

    link: LinkConfig = field(default_factory=LinkConfig)
    generation: Literal["auto", "compact", "extended"] = "auto"
    room_sensor: Literal["loop1", "loop2"] | ExternalRegister = "loop1"
    heat_meter: ExternalRegister | None = None
    writes: WritePolicy = field(default_factory=WritePolicy)

    def __post_init__(self) -> None:
        if self.generation not in ("auto", "compact", "extended"):
            raise InputError("generation must be auto, compact or extended",
                             place="key 'generation'")
        if not isinstance(self.room_sensor, ExternalRegister) and self.room_sensor not in (
            "loop1", "loop2"
        ):
            raise InputError("room_sensor must be loop1, loop2 or a table",
                             place="key 'room_sensor'")


_INTS = frozenset({"port", "baudrate", "device_id", "retries", "attempts", "daily_budget",
                   "verify_attempts", "restore_reserve", "address"})
_FLOATS = frozenset({"timeout_s", "retry_delay_s", "drain_s", "request_gap_s", "verify_delay_s",
                     "scale"})
_FLOATS = _FLOATS | {"settle_s"}  # issue 15 (answer attribution)
_STRINGS = frozenset({"transport", "host", "serial_port", "datatype", "generation"})
_PAIRS = frozenset({"connect_backoff_s", "loop1_setpoint_c", "loop2_setpoint_c", "correction_k",
                    "valid"})


def _type_problem(key: str, value: Any) -> str | None:
    """What is wrong with the TOML type of ``value`` at ``key`` (None when it fits)."""
    def number(v: Any) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

    if key in _INTS and (not isinstance(value, int) or isinstance(value, bool)):
        return "must be an integer"
    if key in _FLOATS and not number(value):
        return "must be a finite number"
    if key in _STRINGS and not isinstance(value, str):
        return "must be a string"
    if key == "tolerate_fixed_tid" and not isinstance(value, bool):
        return "must be true or false"
    if key in _PAIRS and not (isinstance(value, (list, tuple)) and len(value) == 2
                              and all(number(v) for v in value)):
        return "must be a pair of finite numbers [low, high]"
    return None


def _build(cls: type, data: Mapping[str, Any], source: str | Path | None, prefix: str) -> Any:
    if not isinstance(data, Mapping):
        raise InputError(f"must be a table, got {data!r}", source, f"[{prefix}]")
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise InputError(f"unknown key(s) {unknown}", source, f"[{prefix}]")
    for key, value in data.items():
        problem = _type_problem(key, value)
        if problem:
            raise InputError(f"{problem}, got {value!r}", source, f"[{prefix}] key '{key}'")
    kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
    try:
        return cls(**kwargs)
    except InputError as exc:
        place = f"[{prefix}] {exc.place or ''}".strip()
        raise InputError(exc.problem, exc.source or source, place) from None
    except (TypeError, ValueError) as exc:
        raise InputError(f"bad value: {exc}", source, f"[{prefix}]") from None


def config_from_mapping(data: Mapping[str, Any],
                        source: str | Path | None = None) -> HeatPumpConfig:
    """Build a :class:`HeatPumpConfig` from a parsed ``[heatpump]`` TOML table.

    Raises
    ------
    InputError
        Unknown keys or bad values, with the table named.
    """
    data = dict(data)
    writes = _build(WritePolicy, data.pop("writes", {}), source, "heatpump.writes")

    def external(key: str) -> ExternalRegister | None:
        table = data.pop(key, None)
        if table is None or isinstance(table, str):
            return table
        if not isinstance(table, Mapping):
            raise InputError(f"must be a table or a name, got {table!r}", source,
                             f"[heatpump.{key}]")
        table = dict(table)
        link = table.pop("link", None)
        if link is not None:
            table["link"] = _build(LinkConfig, link, source, f"heatpump.{key}.link")
        return _build(ExternalRegister, table, source, f"heatpump.{key}")

    room = external("room_sensor") or "loop1"
    meter = external("heat_meter")
    generation = data.pop("generation", "auto")
    link = _build(LinkConfig, data, source, "heatpump")
    return _build(HeatPumpConfig, {"link": link, "generation": generation, "room_sensor": room,
                                   "heat_meter": meter, "writes": writes}, source, "heatpump")
