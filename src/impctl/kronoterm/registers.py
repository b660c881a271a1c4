"""The Kronoterm holding-register map as data: one table, looked up by name or documented number.

Source: ``kronoterm-modbus.md`` §2 (TT3000 document, KSM V3.14-1 "CNS sistem" transcription,
kronoterm2mqtt). Every register is a holding register (read FC 03, write FC 06). Kronoterm's
documented numbers ("MA") are one-based; the Modbus PDU address is ``MA − 1`` everywhere, in the
client and in the simulator alike (:attr:`Register.address`).

Encodings: one register = signed int16 (two's complement), physical value = raw × scale;
two-register counters = uint32, high word at the lower address.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum

from ..errors import InputError


class Generation(StrEnum):
    """Controller generation, i.e. which register set the controller has."""

    COMPACT = "compact"  #: TT3000: MA 2000–2126, 539, 2128, 2160–2163, 2187–2191
    EXTENDED = "extended"  #: KSM V3.13/V3.14 "CNS sistem": adds power, energy, COP, 2301–2372


class Access(StrEnum):
    """Documented access: read-only or read/write."""

    R = "R"
    RW = "RW"


class Kind(StrEnum):
    """How a raw value is interpreted (see :mod:`impctl.kronoterm.decode`)."""

    TEMP = "temp"  #: measured/target temperature; sentinels and −60…150 °C sanity range apply
    NUMBER = "number"  #: signed int16 × scale (power, pressure, correction, hours …)
    ENUM = "enum"  #: small integer code; undocumented codes decode as missing
    BITS = "bits"  #: bitmask, read as unsigned 16 bit
    UINT32 = "uint32"  #: two registers, high word first, unsigned


C = frozenset({Generation.COMPACT})
E = frozenset({Generation.EXTENDED})
CE = frozenset({Generation.COMPACT, Generation.EXTENDED})

#: Raw values that mean "sensor not connected" for every temperature register.
SENSOR_MISSING_RAW = -600
#: Any raw temperature at or below this is an error code, not a temperature.
ERROR_RAW_AT_OR_BELOW = -500
#: Room-thermostat registers (2160–2163) read these when no Kronoterm thermostat is fitted.
NO_THERMOSTAT_RAW = (-400, 0)
#: MA 2024 (DHW calculated target) reads 5000 when DHW is off.
DHW_OFF_RAW = 5000
#: Sanity range for temperatures [°C]; outside it a value is dropped as a spike.
TEMP_VALID_C = (-60.0, 150.0)


@dataclass(frozen=True)
class Register:
    """One documented Kronoterm holding register.

    Attributes
    ----------
    name : str
        Snake-case identifier used in code and logs.
    ma : int
        Kronoterm's documented, one-based number (e.g. 2103).
    kind : Kind
        Interpretation of the raw value.
    scale : float
        Physical value = raw × scale (1 for enums and bits).
    unit : str
        Unit of the physical value ("°C", "K", "W", "kWh", "bar", "%", "h", "" …).
    access : Access
        Documented access.
    generations : frozenset of Generation
        Register sets in which the register is documented.
    description : str
        Meaning in English.
    sentinels : Mapping[int, str]
        Raw values (signed) that mean "no value", with the reason.
    values : Mapping[int, str] or None
        Documented codes of an enum register.
    valid : (low, high) or None
        Plausible physical values of a number register; outside, the reading is missing.
    """

    name: str
    ma: int
    kind: Kind
    scale: float
    unit: str
    access: Access
    generations: frozenset[Generation]
    description: str
    sentinels: Mapping[int, str] = field(default_factory=dict)
    values: Mapping[int, str] | None = None
    valid: tuple[float, float] | None = None

    @property
    def address(self) -> int:
        """Zero-based Modbus PDU address: documented number − 1."""
        return self.ma - 1

    @property
    def words(self) -> int:
        """Number of 16-bit registers the value occupies."""
        return 2 if self.kind is Kind.UINT32 else 1

    @property
    def writable(self) -> bool:
        """Documented as read/write (says nothing about whether impctl may write it)."""
        return self.access is Access.RW

    def in_generation(self, generation: Generation) -> bool:
        """Whether the register is documented for ``generation``."""
        return generation in self.generations


_MISSING = {SENSOR_MISSING_RAW: "sensor not connected (raw -600)"}
_THERMOSTAT = {**_MISSING, -400: "no room thermostat (raw -400)", 0: "no room thermostat (raw 0)"}
_ONOFF = {0: "off", 1: "on"}
_MODE = {0: "off", 1: "on", 2: "schedule"}
_SCHEDULE = {0: "off", 1: "normal", 2: "eco", 3: "comfort"}
_WORKING = {0: "heating", 1: "dhw", 2: "cooling", 3: "pool", 4: "dhw overheating",
            5: "standby", 6: "start-up", 7: "remote off", 8: "compressor protection"}
R, RW = Access.R, Access.RW


def _t(name, ma, access, gens, desc, sentinels=_MISSING, valid=None):
    return Register(name, ma, Kind.TEMP, 0.1, "°C", access, gens, desc, sentinels, valid=valid)


#: Plausible room (2160–2163) and outdoor (2103) temperatures [°C]: the NIGHTS files' own
#: ranges (``imp.files.values.PLAUSIBLE``). A word beyond them (a spike, a sensor fault) is
#: missing, never a sample the night files would then refuse whole.
ROOM_VALID_C = (-40.0, 60.0)
OUTDOOR_VALID_C = (-60.0, 60.0)


#: Largest power a residential unit's registers give, electrical or thermal [W] (the largest
#: residential Kronoterm gives 25 kW of heat): beyond it a word is no power.
POWER_MAX_W = 30_000.0


def _n(name, ma, scale, unit, access, gens, desc, valid=None):
    return Register(name, ma, Kind.NUMBER, scale, unit, access, gens, desc, valid=valid)


def _e(name, ma, access, gens, desc, values=_ONOFF):
    return Register(name, ma, Kind.ENUM, 1.0, "", access, gens, desc, values=values)


def _b(name, ma, gens, desc):
    return Register(name, ma, Kind.BITS, 1.0, "", R, gens, desc)


def _u32(name, ma, scale, unit, desc):
    return Register(name, ma, Kind.UINT32, scale, unit, R, E, desc)


_TABLE: tuple[Register, ...] = (
    # §2.1 system status and commands
    _e("system_running", 2000, R, CE, "whole regulation running"),
    _e("working_function", 2001, R, CE, "working function now executing", _WORKING),
    _b("additional_bits", 2002, CE, "b2 antifreeze, b3 PV signal, b13 compressor protection"),
    _e("reserve_source", 2003, R, CE, "reserve source status"),
    _e("alternative_source", 2004, R, CE, "alternative source status"),
    _e("passive_cooling", 2005, R, C, "passive cooling status"),
    _e("error_summary", 2006, R, CE, "error/warning summary",
       {0: "none", 1: "warning", 2: "error", 3: "notice"}),
    _n("regime", 2007, 1.0, "", R, CE, "season/regime status (documents conflict)"),
    _e("program_active", 2008, R, CE, "active program",
       {0: "normal", 1: "eco", 2: "comfort", 4: "screed drying"}),
    _e("service_needed", 2009, R, C, "service needed"),
    _e("dhw_forced_running", 2010, R, CE, "forced DHW heating running"),
    _e("defrost", 2011, R, CE, "defrost running"),
    _e("system_on", 2012, RW, CE, "system on/off (HP and heating loops)"),
    _e("program_select", 2013, RW, CE, "program select", {0: "auto", 1: "eco", 2: "comfort"}),
    _n("temp_correction", 2014, 1.0, "K", RW, CE, "system temperature correction, −4…+4 K"),
    _e("dhw_forced", 2015, RW, CE, "forced DHW heating"),
    _e("additional_source_on", 2016, RW, CE, "additional (electric) source on"),
    _n("regime_switch", 2017, 1.0, "", RW, CE, "regime switch (documents conflict)"),
    _e("reserve_source_on", 2018, RW, CE, "reserve source on: HP off, clears alarms"),
    _e("defrost_enable", 2019, RW, C, "defrost enable"),
    _e("pool_priority", 2020, RW, C, "pool priority heating"),
    _e("vacation", 2022, RW, E, "vacation mode"),
    # §2.5 DHW and buffer
    _t("dhw_setpoint", 2023, RW, CE, "DHW desired temperature (25–55 °C)"),
    _t("dhw_target", 2024, R, CE, "DHW current calculated target",
       {**_MISSING, 5000: "DHW off (raw 5000)"}),
    _e("dhw_mode", 2026, RW, CE, "DHW operating mode", _MODE),
    _e("dhw_schedule", 2027, R, CE, "DHW schedule status", _SCHEDULE),
    _b("dhw_pumps", 2028, CE, "b0 circulation pump, b1 charging pump"),
    _n("dhw_eco_offset", 2030, 0.1, "K", RW, CE, "DHW ECO offset"),
    _n("dhw_comfort_offset", 2031, 0.1, "K", RW, CE, "DHW comfort offset"),
    _t("buffer_setpoint", 2032, RW, C, "buffer desired temperature"),
    _e("buffer_regulation", 2033, R, C, "buffer regulation", {0: "constant", 1: "weather"}),
    _t("buffer_target", 2034, R, CE, "buffer/system current calculated target"),
    _e("buffer_mode", 2035, RW, CE, "buffer/HP operating mode", _MODE),
    _e("buffer_schedule", 2037, R, CE, "buffer schedule status", _SCHEDULE),
    _e("main_pump", 2038, R, CE, "main circulation pump"),
    _e("remote_off_input", 2039, R, CE, "remote-off input (meaning differs C/E)"),
    _n("buffer_eco_offset", 2040, 0.1, "K", RW, CE, "HP/buffer ECO offset"),
    _n("buffer_comfort_offset", 2041, 0.1, "K", RW, CE, "HP/buffer comfort offset"),
    # §2.2 loop 1
    _e("loop1_mode", 2042, RW, CE, "loop-1 operating mode", _MODE),
    _e("loop1_schedule", 2044, R, CE, "loop-1 schedule status", _SCHEDULE),
    _e("loop1_pump", 2045, R, CE, "loop-1 circulation pump"),
    _b("loop1_status_bits", 2046, CE, "b0 thermostat demand, b8 weather-compensated"),
    _n("loop1_eco_offset", 2047, 0.1, "K", RW, CE, "loop-1 ECO offset"),
    _n("loop1_comfort_offset", 2048, 0.1, "K", RW, CE, "loop-1 comfort offset"),
    # §2.3 loops 2–4
    _t("loop2_setpoint", 2049, RW, CE, "loop-2 desired temperature (room if KT)"),
    _e("loop2_regulation", 2050, R, CE, "loop-2 regulation", {0: "constant", 1: "weather"}),
    _t("loop2_target", 2051, R, CE, "loop-2 current desired temperature"),
    _e("loop2_mode", 2052, RW, CE, "loop-2 operating mode", _MODE),
    _e("loop2_schedule", 2054, R, CE, "loop-2 schedule status", _SCHEDULE),
    _e("loop2_pump", 2055, R, CE, "loop-2 circulation pump"),
    _e("loop2_thermostat", 2056, R, CE, "loop-2 thermostat status"),
    _n("loop2_eco_offset", 2057, 0.1, "K", RW, CE, "loop-2 ECO offset"),
    _n("loop2_comfort_offset", 2058, 0.1, "K", RW, CE, "loop-2 comfort offset"),
    _t("loop3_setpoint", 2059, RW, CE, "loop-3 desired temperature"),
    _e("loop3_mode", 2062, RW, CE, "loop-3 operating mode", _MODE),
    _t("loop4_setpoint", 2069, RW, CE, "loop-4 desired temperature"),
    _e("loop4_mode", 2072, RW, CE, "loop-4 operating mode", _MODE),
    # §2.6 pool
    _t("pool_setpoint", 2079, RW, CE, "pool desired temperature (19.9–35.0 °C)"),
    _t("pool_target", 2080, R, CE, "pool current calculated target"),
    _e("pool_mode", 2081, RW, CE, "pool operating mode", _MODE),
    # §2.7 operating hours
    _n("hours_compressor_heating", 2090, 1.0, "h", R, CE, "compressor hours, heating"),
    _n("hours_compressor_dhw", 2091, 1.0, "h", R, CE, "compressor hours, DHW"),
    # §2.4 measured temperatures
    _t("t_return", 2101, R, CE, "return water (or buffer) temperature"),
    _t("t_dhw", 2102, R, CE, "DHW tank temperature"),
    _t("t_outdoor", 2103, R, CE, "outdoor temperature", valid=OUTDOOR_VALID_C),
    _t("t_supply", 2104, R, CE, "supply (flow) water temperature, HP outlet"),
    _t("t_source_in", 2105, R, CE, "source inlet / evaporating"),
    _t("t_source_out", 2106, R, CE, "source outlet / compressor"),
    _t("t_alternative_source", 2107, R, CE, "alternative source"),
    _t("t_passive", 2108, R, C, "passive cooling"),
    _t("t_pool", 2109, R, CE, "pool"),
    _t("t_loop2_water", 2110, R, CE, "loop-2 water"),
    _t("t_loop3_water", 2111, R, CE, "loop-3 water"),
    _t("t_loop4_water", 2112, R, CE, "loop-4 water"),
    # §2.8 errors and alarms
    _e("error_active", 2113, RW, CE, "error display; writing 0 clears (never written)"),
    _b("errors_1", 2114, CE, "errors 1 (b9 no flow …)"),
    _b("errors_2", 2115, CE, "errors 2"),
    _b("sensor_errors", 2116, CE, "sensor failures"),
    _b("warnings_1", 2117, CE, "warnings 1 (b13 remote off)"),
    _b("inverter_errors_1", 2118, E, "inverter errors 1"),
    _b("inverter_errors_2", 2119, E, "inverter errors 2"),
    _b("source_errors", 2127, E, "source errors"),
    # §2.2/2.7 loop targets, power
    _t("loop1_target", 2128, R, CE, "loop-1 current calculated (flow/curve) target"),
    # a consumption is never negative: −600 there is the sentinel of the other registers
    _n("power_electrical", 2129, 1.0, "W", R, E, "current electrical power consumption",
       valid=(0.0, POWER_MAX_W)),
    _t("t_loop1_water", 2130, R, E, "loop-1 water (flow) temperature"),
    _t("room_loop1", 2160, R, CE, "loop-1 room thermostat temperature", _THERMOSTAT,
       valid=ROOM_VALID_C),
    _t("room_loop2", 2161, R, CE, "loop-2 room thermostat temperature", _THERMOSTAT,
       valid=ROOM_VALID_C),
    _t("room_loop3", 2162, R, CE, "loop-3 room thermostat temperature", _THERMOSTAT,
       valid=ROOM_VALID_C),
    _t("room_loop4", 2163, R, CE, "loop-4 room thermostat temperature", _THERMOSTAT,
       valid=ROOM_VALID_C),
    _b("thermostat_failure", 2186, E, "thermostat failure, b0–b3 loops 1–4"),
    _t("loop1_setpoint", 2187, RW, CE, "loop-1 desired temperature (room if KT)"),
    _t("loop2_flow_target", 2188, R, CE, "loop-2 current desired flow temperature"),
    _t("loop3_flow_target", 2189, R, CE, "loop-3 current desired flow temperature"),
    _t("loop4_flow_target", 2190, R, CE, "loop-4 current desired flow temperature"),
    _t("loop1_room_target", 2191, R, CE, "loop-1 calculated room target (or return temp)"),
    _e("remote_function", 2197, RW, E, "remote function control: 1 = remote off"),
    _e("bms_control", 539, RW, C, "BMS control of the HP: 0 = remote off",
       {0: "remote off", 1: "1 compressor", 2: "2 compressors", 12: "automatic"}),
    # §2.2 loop-1 heating curve (extended only; the TT3000 document has no curve register)
    _t("loop1_curve_cold", 2309, RW, E, "loop-1 heating curve: flow at the first point "
       "(−15 °C outdoor)"),
    _t("loop1_curve_mild", 2314, RW, E, "loop-1 heating curve: flow at the second point "
       "(+15 °C outdoor)"),
    _e("loop1_adaptive_curve", 2320, RW, E, "loop-1 adaptive curve"),
    # §2.7 extended: compressor, pressure, power, energy, COP
    _b("compressor_bits", 2318, E, "b0 compressor 1, b1 compressor 2"),
    _b("compressor_protection_bits", 2319, E, "b0 anti-cycling lockout, b1 starting"),
    _n("pressure_setpoint", 2325, 0.1, "bar", RW, E, "heating-system pressure setpoint"),
    _n("pressure_system", 2326, 0.1, "bar", R, E, "heating-system pressure"),
    _n("load", 2327, 1.0, "%", R, E, "current HP load (compressor modulation)"),
    # the unit's own heat output, negative while it defrosts or cools; beyond the bound
    # (0x7FFF, 0x8000 …) the word is no power
    _n("power_thermal", 2329, 1.0, "W", R, E, "current heating/cooling (thermal) power",
       valid=(-POWER_MAX_W, POWER_MAX_W)),
    _u32("energy_electrical", 2361, 1.0, "kWh", "lifetime electrical energy, heating + DHW"),
    _u32("energy_thermal", 2363, 0.1, "kWh", "lifetime thermal energy, heating + DHW"),
    _n("cop", 2371, 0.01, "", R, E, "COP (scale disputed: ×0.01 assumed)"),
    _n("scop", 2372, 0.01, "", R, E, "SCOP (scale disputed: ×0.01 assumed)"),
)

#: Every register by documented number.
REGISTERS: Mapping[int, Register] = {r.ma: r for r in _TABLE}
_BY_NAME: Mapping[str, Register] = {r.name: r for r in _TABLE}

#: Registers impctl never writes, whatever the configuration (see the reference §2.1, §2.9).
FORBIDDEN_WRITES: frozenset[int] = frozenset({2017, 2018, 2113, 539, 2197})


def register(key: str | int | Register) -> Register:
    """Look a register up by name or documented number (MA).

    Raises
    ------
    InputError
        For an unknown name or number.
    """
    if isinstance(key, Register):
        return key
    found = REGISTERS.get(key) if isinstance(key, int) else _BY_NAME.get(key)
    if found is None:
        raise InputError(f"unknown Kronoterm register {key!r}", place="register map")
    return found


def registers_for(generation: Generation) -> tuple[Register, ...]:
    """All registers documented for ``generation``, sorted by number."""
    return tuple(sorted((r for r in _TABLE if r.in_generation(generation)), key=lambda r: r.ma))


def _check_table() -> None:
    # A map that silently holds two entries for one number is how off-by-one bugs hide.
    if len(REGISTERS) != len(_TABLE) or len(_BY_NAME) != len(_TABLE):
        raise RuntimeError("duplicate register number or name in the Kronoterm map")
    words = {r.ma + 1 for r in _TABLE if r.kind is Kind.UINT32}
    if words & set(REGISTERS):
        raise RuntimeError("a uint32 low word overlaps another register")


_check_table()
