"""The simulator's holding-register image: plant state → documented encodings, per generation.

Address space (documented numbers; PDU address = MA − 1, as in the client):

* extended: MA 2000–2372, contiguous (undocumented numbers in between read 0);
* compact (TT3000): MA 539, 2000–2126, 2128, 2160–2163, 2187–2191; anything else is an
  illegal address, so a client that touches extended registers on a TT3000 gets exception 2.

Temperatures are int16 × 0.1 °C (rounded, so T_air is quantised to 0.1 °C); absent sensors read
−600, absent room thermostats −400, DHW target 5000 when DHW is off; the energy counters are
uint32, high word first.
"""

from __future__ import annotations

from collections.abc import Mapping

from impctl.kronoterm.registers import REGISTERS, Access, Generation, Kind
from impctl.modbus import to_word, uint32_words

from .realistic import PlantLike

LAYOUT: Mapping[Generation, tuple[tuple[int, int], ...]] = {
    Generation.EXTENDED: ((2000, 373),),
    Generation.COMPACT: ((539, 1), (2000, 127), (2128, 1), (2160, 4), (2187, 5)),
}

#: Registers whose writes drive the plant; other documented RW registers are just stored.
PLANT_INPUTS = {2187: "setpoint", 2042: "loop_mode", 2012: "system_on", 2014: "correction",
                2309: "curve", 2314: "curve"}

#: Raw ranges the simulated controller accepts on write (else exception 3, illegal value).
WRITE_RANGES: Mapping[int, tuple[int, int]] = {
    2187: (50, 600), 2049: (50, 600), 2059: (50, 600), 2069: (50, 600),
    2042: (0, 2), 2052: (0, 2), 2062: (0, 2), 2072: (0, 2), 2026: (0, 2), 2035: (0, 2),
    2081: (0, 2), 2012: (0, 1), 2014: (-4, 4), 2023: (250, 550), 2079: (199, 350),
    # the curve points: the document gives no range; a controller takes flows a heat pump
    # can make [own choice]
    2309: (150, 700), 2314: (150, 700), 2320: (0, 1),
}

_ABSENT_SENSORS = (2107, 2108, 2109, 2110, 2111, 2112)
_UINT32 = frozenset(reg.ma for reg in REGISTERS.values() if reg.kind is Kind.UINT32)


def in_layout(ma: int, generation: Generation) -> bool:
    """Whether documented number ``ma`` is an address of the simulated controller."""
    return any(first <= ma < first + n for first, n in LAYOUT[generation])


def writable(ma: int, generation: Generation) -> bool:
    """Documented RW register present on ``generation``."""
    reg = REGISTERS.get(ma)
    return (reg is not None and reg.access is Access.RW and reg.in_generation(generation)
            and in_layout(ma, generation))


def initial_rw(setpoint_c: float, curve_c: tuple[float, float] = (45.0, 30.0)
               ) -> dict[int, int]:
    """Raw start values of the RW registers (signed); ``curve_c`` the loop-1 curve points
    (2309/2314) [°C]."""
    rw = {reg.ma: 0 for reg in REGISTERS.values() if reg.access is Access.RW}
    rw.update({2012: 1, 2023: 480, 2026: 1, 2035: 1, 2042: 1, 2049: 200, 2059: 200, 2069: 200,
               2079: 280, 2187: round(setpoint_c * 10), 2325: 15, 539: 12,
               2309: _tenths(curve_c[0]), 2314: _tenths(curve_c[1]), 2320: 0})
    return rw


def _tenths(value_c: float) -> int:
    return round(value_c * 10.0)


def kronoterm_values(plant: PlantLike, rw: Mapping[int, int], *, room_thermostat: bool,
                     t_air_c: float, t_out_c: float) -> dict[int, int]:
    """Signed raw value of every modelled register (uint32 counters as one integer).

    ``t_air_c`` and ``t_out_c`` are what the sensors show (the plant's sensors plus any noise).
    Compressor, pumps, supply/return temperatures and the thermal and electrical power follow
    the plant's compressor: on the realistic plant they cycle with it, as a real Kronoterm's do.
    """
    on = bool(plant.system_on)
    running = bool(plant.compressor_on)
    if not on:
        function = 5
    elif plant.dhw_active:
        function = 1
    elif running or plant.defrost_active:
        function = 0
    else:
        function = 5
    protection = int(plant.protection_bits)
    v = {
        2000: int(on), 2001: function,
        2002: (0x2000 if protection & 1 else 0) | (0x4000 if protection & 2 else 0),
        2006: 0, 2007: 1, 2008: 0, 2011: int(plant.defrost_active),
        2024: 5000 if rw.get(2026, 1) == 0 else rw.get(2023, 480),
        2027: 1, 2028: 2 if plant.dhw_active else 0, 2034: _tenths(plant.t_w_target_c),
        2037: 1, 2038: int(plant.pump_on), 2039: 0,
        2044: 1 if plant.loop_mode else 0, 2045: int(plant.loop_pump_on),
        2046: int(plant.heat_demand),
        2090: int(plant.hours_heating), 2091: int(plant.hours_dhw),
        2101: _tenths(plant.t_return_c), 2102: _tenths(plant.t_dhw_c), 2103: _tenths(t_out_c),
        2104: _tenths(plant.t_supply_c),
        2105: _tenths(t_out_c - (3.0 if running else 0.0)),
        2106: _tenths(t_out_c - (6.0 if running else 0.0)),
        2128: _tenths(plant.flow_target_c), 2129: round(plant.p_el_w),
        2130: _tenths(plant.t_supply_c),
        2160: _tenths(t_air_c) if room_thermostat else -400,
        2161: -400, 2162: -400, 2163: -400,
        2191: _tenths(plant.room_setpoint_c),
        2318: int(running), 2319: protection, 2326: 15,
        2327: int(plant.load_pct),
        2329: round(plant.p_th_w),
        2361: int(plant.e_el_kwh), 2363: int(plant.e_th_kwh * 10),
        2371: round(plant.cop * 100),
        2372: round(100 * plant.e_th_kwh / plant.e_el_kwh) if plant.e_el_kwh > 0 else 0,
    }
    v.update(dict.fromkeys(_ABSENT_SENSORS, -600))
    for ma, raw in rw.items():
        v[ma] = raw
    return v


def register_words(values: Mapping[int, int], generation: Generation,
                   missing: set[int] = frozenset()) -> list[tuple[int, list[int]]]:
    """Lay the values out as (first PDU address, words) blocks for ``generation``.

    ``missing`` registers read −600 (the sensor-missing fault). Numbers without a value read 0.
    """
    blocks = []
    for first, count in LAYOUT[generation]:
        words = [0] * count
        for ma, raw in values.items():
            i = ma - first
            if not 0 <= i < count:
                continue
            if ma in _UINT32:
                high, low = uint32_words(raw & 0xFFFFFFFF)
                words[i] = high
                if i + 1 < count:
                    words[i + 1] = low
            else:
                words[i] = to_word(max(-0x8000, min(0x7FFF, raw)))
        for ma in missing:
            if 0 <= ma - first < count and ma not in _UINT32:
                words[ma - first] = to_word(-600)
        blocks.append((first - 1, words))
    return blocks


def heat_meter_words(plant: PlantLike) -> list[int]:
    """Heat-meter device image: address 0–1 = space-heating thermal power [W], uint32."""
    watts = max(0, round(plant.space_heat_metered_w))
    return uint32_words(watts)
