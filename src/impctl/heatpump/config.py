"""Configuration of the heat pump: its link, external sensors and the write policy.

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
    loop1_setpoint_c = [16.0, 24.0]
    daily_budget = 12
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Literal

from ..errors import InputError
from ..modbus.config import LinkConfig, Problem, link_problems, raise_first

DATATYPES = ("int16", "uint16", "int32", "uint32")


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
        raise_first(_external_problems(self))

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
    with ``loop2_setpoint_c`` set, the ±4 K correction (2014) only with ``correction_k`` set,
    the loop-1 heating-curve points (2309/2314) only with ``loop1_curve_c`` set (the daemon
    sets it while the owner asks for impctl's curve). 2017, 2018, 2113, 539 and 2197 are never
    written.

    Attributes
    ----------
    loop1_setpoint_c : (min, max) clamp for 2187 [°C]; the default top, 24 °C, is the IMP's
        highest normal-night setpoint (:mod:`impctl.imp.protocol`), so the default campaign is
        never clamped.
    loop2_setpoint_c : (min, max) clamp for 2049 [°C]; ``None`` = loop 2 not writable.
    correction_k : (min, max) clamp for 2014 [K], within −4…4; ``None`` = not writable.
    loop1_curve_c : (min, max) clamp for the curve points 2309/2314 [°C], within
        :data:`CURVE_FLOW_BOUNDS_C`; ``None`` = not writable (a restore of the owner's points
        is always allowed).
    loop1_curve_owner_c : the owner's own points 2309/2314 [°C], or ``None``: each point's
        clamp reaches up to its own where that lies above ``loop1_curve_c``'s top (a value the
        controller already runs). Set by the daemon from its journal, not configured.
    daily_budget : writes per register per day (UTC day of the client's clock); build the
        budget with ``WriteBudget(path, policy.daily_budget)``.
    verify_attempts : read-backs after a write before it counts as failed.
    verify_delay_s : pause before each read-back [s] (the first answer may be stale).
    restore_reserve : writes per register per day beyond ``daily_budget`` that only restoring
        the owner's settings may use, so a spent budget never keeps the heating off.
    """

    loop1_setpoint_c: tuple[float, float] = (16.0, 24.0)
    loop2_setpoint_c: tuple[float, float] | None = None
    correction_k: tuple[int, int] | None = None
    loop1_curve_c: tuple[float, float] | None = None
    # set by the daemon at run time, never read from a configuration
    loop1_curve_owner_c: tuple[float, float] | None = field(default=None,
                                                            metadata={"configured": False})
    daily_budget: int = 12
    verify_attempts: int = 3
    verify_delay_s: float = 0.5
    restore_reserve: int = 2

    def __post_init__(self) -> None:
        raise_first(_write_problems(self))


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
        raise_first(_heatpump_problems(self))


#: Room-setpoint limits [°C] a configuration may allow at all: below 10 °C a home risks
#: frost damage and damp, above 30 °C no room is meant to be heated (EN 16798-1 design
#: ranges lie within 16–26 °C); a write outside them is a typo, not an experiment.
ROOM_SETPOINT_BOUNDS_C = (10.0, 30.0)
#: Flow temperatures a heating-curve point may be set to [°C]: below 20 °C no emitter heats a
#: room, above 55 °C an air-source heat pump runs near its limit — higher only up to the
#: owner's own point there (``WritePolicy.loop1_curve_owner_c``), a value it already runs.
CURVE_FLOW_BOUNDS_C = (20.0, 55.0)
#: Highest owner's curve point impctl takes as a ceiling [°C] (``loop1_curve_owner_c``): above
#: 80 °C no heat pump delivers flow, so such a reading is a fault, not a setting.
CURVE_OWNER_MAX_C = 80.0
#: Endurance of the controller's non-volatile memory [writes per register over its life]:
#: assumed — Kronoterm publishes no figure, so the conservative class of the makers that do
#: (Weishaupt 100,000; iDM 300,000; reference kronoterm-modbus.md §4.1).
EEPROM_ENDURANCE_WRITES = 100_000
#: Service life the endurance must last [years]: assumed, the lower end of a heat pump's life.
SERVICE_LIFE_YEARS = 15
#: Most writes per register per day, daily_budget + restore_reserve: the budget spent in full
#: every day of the service life stays within the endurance, 100,000 / (15 × 365) = 18.3 → 18
#: (the default 12 + 2 would use 77 % of it in 15 years of daily spending; a real campaign,
#: ~4 writes on each of a few nights, uses well under 1 %).
WRITES_PER_DAY_MAX = EEPROM_ENDURANCE_WRITES // (SERVICE_LIFE_YEARS * 365)
#: Scale of an external register: from µ-units to mega-units per count; 0 would read nothing.
SCALE_ABS = (1e-6, 1e6)
#: Accepted range of an external register's physical value: the default ±1e9 is "no limit".
VALID_ABS_MAX = 1e9


def _external_problems(c: Any) -> list[Problem]:
    out: list[Problem] = []
    if c.datatype not in DATATYPES:
        out.append(("datatype", f"must be one of {DATATYPES}"))
    if not 0 <= c.address <= 0xFFFF:
        out.append(("address", "must be 0–65535 (the zero-based PDU address)"))
    if not 1 <= c.device_id <= 247:
        out.append(("device_id", "must be 1–247"))
    if not c.valid[0] < c.valid[1]:
        out.append(("valid", "must be [low, high] with low < high"))
    elif max(abs(c.valid[0]), abs(c.valid[1])) > VALID_ABS_MAX:
        out.append(("valid", f"must lie within ±{VALID_ABS_MAX:g}"))
    if not SCALE_ABS[0] <= abs(c.scale) <= SCALE_ABS[1]:
        out.append(("scale", f"|scale| must lie in {SCALE_ABS[0]:g}–{SCALE_ABS[1]:g} "
                             f"(physical value = raw × scale), got {c.scale:g}"))
    return out


def _write_problems(c: Any) -> list[Problem]:
    out: list[Problem] = []
    lo_b, hi_b = ROOM_SETPOINT_BOUNDS_C
    for key in ("loop1_setpoint_c", "loop2_setpoint_c"):
        limits = getattr(c, key)
        if limits is not None and not (lo_b <= limits[0] <= limits[1] <= hi_b):
            out.append((key, f"room-setpoint limits must satisfy {lo_b:g} <= min <= max <= "
                             f"{hi_b:g} °C, got [{limits[0]:g}, {limits[1]:g}]"))
    if c.correction_k is not None and not -4 <= c.correction_k[0] <= c.correction_k[1] <= 4:
        out.append(("correction_k", "limits must lie within -4…4 K"))
    lo_c, hi_c = CURVE_FLOW_BOUNDS_C
    if c.loop1_curve_c is not None and not lo_c <= c.loop1_curve_c[0] <= c.loop1_curve_c[1] \
            <= hi_c:
        out.append(("loop1_curve_c", f"limits must satisfy {lo_c:g} <= min <= max <= "
                                     f"{hi_c:g} °C"))
    own = c.loop1_curve_owner_c
    if own is not None and not all(v <= CURVE_OWNER_MAX_C for v in own):
        out.append(("loop1_curve_owner_c", f"the owner's points must not lie above "
                                           f"{CURVE_OWNER_MAX_C:g} °C"))
    for key, low in (("daily_budget", 0), ("restore_reserve", 0), ("verify_attempts", 1)):
        if getattr(c, key) < low:
            out.append((key, f"must be >= {low}"))
    # A restore writes each register once; four more a day cover repeated failed restores.
    if c.restore_reserve > 4:
        out.append(("restore_reserve", "must be <= 4"))
    elif c.daily_budget >= 0 and c.daily_budget + c.restore_reserve > WRITES_PER_DAY_MAX:
        out.append(("daily_budget", f"daily_budget + restore_reserve = "
                    f"{c.daily_budget + c.restore_reserve} writes per register per day; at "
                    f"most {WRITES_PER_DAY_MAX}, so that spending it every day for "
                    f"{SERVICE_LIFE_YEARS} years stays within the controller's assumed "
                    f"{EEPROM_ENDURANCE_WRITES:,}-write EEPROM endurance"))
    if c.verify_attempts > 10:  # a value not read back after 10 tries is not being written
        out.append(("verify_attempts", "must be <= 10"))
    if not 0 <= c.verify_delay_s <= 10:
        out.append(("verify_delay_s", "must lie in 0–10 s"))
    return out


def _heatpump_problems(c: Any) -> list[Problem]:
    out: list[Problem] = []
    if c.generation not in ("auto", "compact", "extended"):
        out.append(("generation", f"must be auto, compact or extended, got {c.generation!r}"))
    if not isinstance(c.room_sensor, ExternalRegister) and c.room_sensor not in (
            "loop1", "loop2"):
        out.append(("room_sensor", f"must be loop1, loop2 or a table, got {c.room_sensor!r}"))
    return out


_INTS = frozenset({"port", "baudrate", "device_id", "retries", "attempts", "daily_budget",
                   "verify_attempts", "restore_reserve", "address"})
_FLOATS = frozenset({"timeout_s", "retry_delay_s", "drain_s", "request_gap_s", "verify_delay_s",
                     "scale"})
_FLOATS = _FLOATS | {"settle_s"}  # issue 15 (answer attribution)
_STRINGS = frozenset({"transport", "host", "serial_port", "datatype", "generation",
                      "room_sensor"})
_PAIRS = frozenset({"connect_backoff_s", "loop1_setpoint_c", "loop2_setpoint_c", "correction_k",
                    "loop1_curve_c", "valid"})


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


class HeatPumpConfigError(InputError):
    """Every problem of a ``[heatpump]`` table at once; ``problems`` holds one error each."""

    def __init__(self, problems: list[InputError]):
        self.problems = problems
        super().__init__("\n".join(str(p) for p in problems))

    def _line(self) -> str:
        return "\n".join(str(p) for p in self.problems)


_CHECKS = {LinkConfig: link_problems, ExternalRegister: _external_problems,
           WritePolicy: _write_problems, HeatPumpConfig: _heatpump_problems}


def _default(f: Any) -> Any:
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:
        return f.default_factory()
    return None


def _build(cls: type, data: Any, source: str | Path | None, prefix: str,
           problems: list[InputError], required: tuple[str, ...] = ()) -> Any:
    """Build ``cls`` from a TOML table, appending every problem found to ``problems``;
    None when there was any (the caller carries on to find the other tables' problems)."""
    def bad(key: str | None, text: str) -> None:
        place = f"[{prefix}]" + (f" key '{key}'" if key else "")
        problems.append(InputError(text, source, place))

    if not isinstance(data, Mapping):
        bad(None, f"must be a table, got {data!r}")
        return None
    before = len(problems)
    spec = {f.name: f for f in fields(cls)}
    kwargs = {}
    for key, value in data.items():
        if key not in spec:
            bad(key, "unknown key")
            continue
        if spec[key].metadata.get("configured") is False:
            bad(key, "set by the daemon, not configured")
            continue
        problem = _type_problem(key, value)
        if problem:
            bad(key, f"{problem}, got {value!r}")
            continue
        kwargs[key] = tuple(value) if isinstance(value, list) else value
    missing = [k for k in required if k not in data] + [
        n for n, f in spec.items()  # fields without a default
        if n not in data and n not in required and f.default is MISSING
        and f.default_factory is MISSING]
    for key in missing:
        bad(key, "missing (required)")
    bad_values = {k for k in data if k in spec and k not in kwargs}
    if not missing and not bad_values:
        # The value checks too, on the keys that could be read, so one run lists everything.
        probe = SimpleNamespace(**{**{n: _default(f) for n, f in spec.items()}, **kwargs})
        for key, text in _CHECKS[cls](probe):
            bad(key, text)
    if len(problems) > before:
        return None
    return cls(**kwargs)


def config_from_mapping(data: Mapping[str, Any],
                        source: str | Path | None = None) -> HeatPumpConfig:
    """Build a :class:`HeatPumpConfig` from a parsed ``[heatpump]`` TOML table.

    With transport "tcp", ``host`` is required (no silent default address).

    Raises
    ------
    HeatPumpConfigError
        Every unknown key, missing key or bad value at once, one line each, with the table
        named.
    """
    problems: list[InputError] = []
    if not isinstance(data, Mapping):
        raise HeatPumpConfigError([InputError(f"must be a table, got {data!r}", source,
                                              "[heatpump]")])
    data = dict(data)
    writes = _build(WritePolicy, data.pop("writes", {}), source, "heatpump.writes", problems)

    def external(key: str) -> ExternalRegister | str | None:
        table = data.pop(key, None)
        if table is None or isinstance(table, str):
            return table
        if not isinstance(table, Mapping):
            problems.append(InputError(f"must be a table or a name, got {table!r}", source,
                                       f"[heatpump.{key}]"))
            return None
        table = dict(table)
        link = table.pop("link", None)
        if link is not None:
            table["link"] = _build(LinkConfig, link, source, f"heatpump.{key}.link", problems,
                                   required=("host",) if _tcp(link) else ())
            if table["link"] is None:
                table.pop("link")
        return _build(ExternalRegister, table, source, f"heatpump.{key}", problems,
                      required=("device_id", "address"))

    room = external("room_sensor") or "loop1"
    meter = external("heat_meter")
    generation = data.pop("generation", "auto")
    link = _build(LinkConfig, data, source, "heatpump", problems,
                  required=("host",) if _tcp(data) else ())
    if problems:
        # The top-level checks too (generation, room sensor name), on what could be read.
        probe = SimpleNamespace(generation=generation, room_sensor=room)
        problems += [InputError(text, source, f"[heatpump] key '{key}'")
                     for key, text in _heatpump_problems(probe)]
        raise HeatPumpConfigError(problems)
    hp = _build(HeatPumpConfig, {"link": link, "generation": generation, "room_sensor": room,
                                 "heat_meter": meter, "writes": writes}, source, "heatpump",
                problems)
    if problems:
        raise HeatPumpConfigError(problems)
    return hp


def _tcp(table: Any) -> bool:
    return isinstance(table, Mapping) and table.get("transport", "tcp") == "tcp"
