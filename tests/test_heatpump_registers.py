"""Register map, MA − 1 rule, decoding of sentinels and signs, encoding, block planning, config."""

from __future__ import annotations

from datetime import UTC, datetime

import pytest
from hypothesis import given
from hypothesis import strategies as st

from impctl.errors import InputError
from impctl.heatpump import (
    FORBIDDEN_WRITES,
    REGISTERS,
    Generation,
    Kind,
    WritePolicy,
    WriteRefused,
    config_from_mapping,
    decode,
    encode,
    register,
    registers_for,
    write_rules,
)
from impctl.heatpump.writes import check_target
from impctl.kronoterm.registers import TEMP_VALID_C
from impctl.kronoterm.snapshot import plan_blocks
from impctl.modbus import uint32, uint32_words

NOW = datetime(2026, 1, 12, 20, tzinfo=UTC)
TEMPS = [r for r in REGISTERS.values() if r.kind is Kind.TEMP]


def test_pdu_address_is_documented_number_minus_one():
    for reg in REGISTERS.values():
        assert reg.address == reg.ma - 1
    # The addresses of the reference's wire trace and of the off-by-one history.
    assert register("t_outdoor").address == 2102
    assert register("loop1_setpoint").address == 2186
    assert register("power_thermal").address == 2328
    assert register("t_return").address == 2100


def test_key_registers_are_where_the_reference_puts_them():
    expected = {"t_return": 2101, "t_dhw": 2102, "t_outdoor": 2103, "t_supply": 2104,
                "loop1_mode": 2042, "loop1_setpoint": 2187, "loop1_target": 2128,
                "room_loop1": 2160, "power_electrical": 2129, "power_thermal": 2329,
                "energy_electrical": 2361, "energy_thermal": 2363, "defrost": 2011,
                "working_function": 2001, "system_on": 2012, "temp_correction": 2014}
    assert {name: register(name).ma for name in expected} == expected
    assert register("temp_correction").scale == 1.0  # ×1 °C, not ×0.1
    assert register("energy_thermal").scale == 0.1 and register("energy_electrical").scale == 1


def test_compact_set_has_no_power_or_energy_registers():
    compact = {r.ma for r in registers_for(Generation.COMPACT)}
    assert not compact & {2129, 2130, 2329, 2361, 2363, 2371, 2372, 2327}
    for ma in compact:
        assert ma == 539 or 2000 <= ma <= 2126 or ma in (2128, *range(2160, 2164),
                                                         *range(2187, 2192))


def test_forbidden_registers_can_never_be_whitelisted():
    policies = [WritePolicy(), WritePolicy(loop2_setpoint_c=(16, 23), correction_k=(-4, 4))]
    for policy in policies:
        assert not set(write_rules(policy)) & FORBIDDEN_WRITES
        for ma in FORBIDDEN_WRITES:
            with pytest.raises(WriteRefused, match="never written"):
                check_target(register(ma), 0, policy)
    assert FORBIDDEN_WRITES == {2017, 2018, 2113, 539, 2197}


def test_optional_registers_need_configuration():
    with pytest.raises(WriteRefused, match="whitelist"):
        check_target(register(2049), 20.0, WritePolicy())
    with pytest.raises(WriteRefused, match="whitelist"):
        check_target(register(2014), 1, WritePolicy())
    assert check_target(register(2049), 30.0, WritePolicy(loop2_setpoint_c=(16, 22))) == 22.0
    assert check_target(register(2014), -4, WritePolicy(correction_k=(-2, 2))) == -2.0


def test_clamping_and_mode_codes():
    policy = WritePolicy(loop1_setpoint_c=(16.0, 23.0))
    assert check_target(register(2187), 12.0, policy) == 16.0
    assert check_target(register(2187), 30.0, policy) == 23.0
    assert check_target(register(2187), 19.5, policy) == 19.5
    for bad in (3, -1, 0.5):
        with pytest.raises(WriteRefused):
            check_target(register(2042), bad, policy)
    with pytest.raises(InputError):
        check_target(register(2187), float("nan"), policy)


@pytest.mark.parametrize("word, value", [(0xFFCC, -5.2), (0xFF38, -20.0), (0xFE70, -40.0),
                                         (0x0000, 0.0), (0x0034, 5.2)])
def test_signed_negative_outdoor_temperatures(word, value):
    reading = decode(register("t_outdoor"), [word], NOW)
    assert not reading.missing and reading.value == pytest.approx(value)


@pytest.mark.parametrize("key, raw, reason", [
    ("t_outdoor", -600, "sensor not connected"),
    ("t_supply", -600, "sensor not connected"),
    ("t_outdoor", -550, "sensor error code"),
    ("room_loop1", -400, "no room thermostat"),
    ("room_loop1", 0, "no room thermostat"),
    ("room_loop2", -400, "no room thermostat"),
    ("dhw_target", 5000, "DHW off"),
    ("t_supply", 5000, "sanity range"),  # 500 °C is not a temperature either
    ("t_outdoor", 1501, "sanity range"),
    ("loop1_mode", 7, "undocumented value"),
    ("power_thermal", 32767, "outside the plausible"),
    ("power_thermal", -32768, "outside the plausible"),
    ("power_electrical", -600, "outside the plausible"),
])
def test_sentinels_and_implausible_values_are_missing(key, raw, reason):
    reading = decode(register(key), [raw & 0xFFFF], NOW)
    assert reading.missing and reading.value is None
    assert reason in reading.reason
    assert reading.raw == raw
    with pytest.raises(InputError, match=f"register {register(key).ma}"):
        reading.require()


def test_a_defrost_and_a_full_load_are_heat_outputs():
    """2329 goes negative while the unit defrosts (it takes heat from the water)."""
    assert decode(register("power_thermal"), [(-2500) & 0xFFFF], NOW).value == -2500.0
    assert decode(register("power_thermal"), [25_000], NOW).value == 25_000.0


def test_minus_forty_is_a_real_outdoor_temperature_but_no_thermostat_indoors():
    assert decode(register("t_outdoor"), [(-400) & 0xFFFF], NOW).value == -40.0
    assert decode(register("room_loop1"), [(-400) & 0xFFFF], NOW).missing
    assert decode(register("t_outdoor"), [600], NOW).value == 60.0


@pytest.mark.parametrize(("key", "raw"), [("t_outdoor", 601), ("t_outdoor", 700),
                                          ("room_loop1", 601), ("room_loop1", 850),
                                          ("room_loop1", -401), ("room_loop4", 1500)])
def test_a_room_or_outdoor_temperature_no_night_file_would_take_is_missing(key, raw):
    """A spike the NIGHTS files refuse (their plausible ranges) is missing at the source, never
    a stored sample that makes every later fit refuse its file."""
    reading = decode(register(key), [raw & 0xFFFF], NOW)
    assert reading.missing and "outside" in reading.reason


def test_the_room_and_outdoor_ranges_are_the_night_files_own():
    from impctl.imp.files.values import PLAUSIBLE

    assert register("room_loop1").valid == PLAUSIBLE["t_air"][:2]
    assert register("t_outdoor").valid == PLAUSIBLE["t_out"][:2]


@given(st.sampled_from(TEMPS), st.integers(0, 0xFFFF))
def test_no_raw_word_decodes_to_an_implausible_temperature(reg, word):
    reading = decode(reg, [word], NOW)
    if reading.missing:
        assert reading.value is None and reading.reason
    else:
        assert TEMP_VALID_C[0] <= reading.value <= TEMP_VALID_C[1]
        assert reading.raw not in reg.sentinels and reading.raw > -500


@given(st.integers(-600, 1500))
def test_outdoor_encode_decode_round_trip(tenths):
    value = tenths / 10
    reg = register("t_outdoor")
    word = encode(reg, value)
    reading = decode(reg, [word], NOW)
    if tenths <= -500 or value > 60.0:
        assert reading.missing
    else:
        assert reading.value == pytest.approx(value)


def test_uint32_counters_are_high_word_first():
    reading = decode(register("energy_thermal"), [0x0001, 0x86A0], NOW)
    assert reading.raw == 100_000 and reading.value == pytest.approx(10_000.0)
    reading = decode(register("energy_electrical"), [0xFFFF, 0xFFFF], NOW)
    assert reading.value == 4_294_967_295  # unsigned: never negative
    with pytest.raises(ValueError):
        decode(register("energy_thermal"), [1], NOW)


@given(st.integers(0, 0xFFFFFFFF))
def test_uint32_words_are_the_inverse_of_uint32(value):
    words = uint32_words(value)
    assert all(0 <= w <= 0xFFFF for w in words) and uint32(words) == value


def test_uint32_words_refuse_what_two_registers_cannot_hold():
    assert uint32_words(100_000) == [0x0001, 0x86A0]
    for value in (-1, 1 << 32):
        with pytest.raises(ValueError):
            uint32_words(value)


def test_encode_is_int16_twos_complement():
    assert encode(register("temp_correction"), -4) == 0xFFFC
    assert encode(register("loop1_setpoint"), 21.0) == 210
    assert encode(register("loop1_setpoint"), -0.1) == 0xFFFF
    with pytest.raises(InputError):
        encode(register("loop1_setpoint"), 4000.0)
    with pytest.raises(InputError):
        encode(register("energy_thermal"), 1.0)


def test_unknown_register_is_input_error():
    with pytest.raises(InputError, match="unknown Kronoterm register"):
        register(9999)
    with pytest.raises(InputError):
        register("outdoor")


def test_block_plan_spans_only_documented_registers():
    def documented(ma, gen):
        reg = REGISTERS.get(ma) or REGISTERS.get(ma - 1)
        return reg is not None and reg.in_generation(gen)

    for gen, wanted in ((Generation.EXTENDED, (2101, 2104, 2000, 2006, 2363)),
                        (Generation.COMPACT, (2000, 2006, 2101, 2104, 2160, 2187))):
        plan = plan_blocks([register(m) for m in wanted], gen)
        covered = {ma for first, n in plan for ma in range(first, first + n)}
        assert set(wanted) <= covered
        assert all(documented(ma, gen) for ma in covered), plan
        # 2005 is documented only for the compact set, so no extended block spans it.
        assert gen is Generation.COMPACT or 2005 not in covered
        # Without transaction ids an answer is told from another block's by its length.
        lengths = [n for _, n in plan]
        assert len(set(lengths)) == len(lengths), plan
    # Widened only where needed: two 1-register blocks become lengths 1 and 2 or more.
    single = plan_blocks([register(2160), register(2187)], Generation.COMPACT)
    assert sorted(n for _, n in single)[0] == 1 and len({n for _, n in single}) == 2


def test_config_from_mapping():
    cfg = config_from_mapping({
        "transport": "rtu", "serial_port": "socket://127.0.0.1:5021", "baudrate": 115200,
        "heat_meter": {"device_id": 30, "address": 0, "datatype": "uint32"},
        "writes": {"loop1_setpoint_c": [17.0, 22.0], "daily_budget": 6},
    }, "impctl.toml")
    assert cfg.link.transport == "rtu" and cfg.link.baudrate == 115200
    assert cfg.link.device_id == 20
    assert cfg.heat_meter is not None and cfg.heat_meter.words == 2
    assert cfg.writes.loop1_setpoint_c == (17.0, 22.0) and cfg.writes.daily_budget == 6
    with pytest.raises(InputError, match=r"impctl.toml: \[heatpump\].*baud"):
        config_from_mapping({"transport": "rtu", "serial_port": "/dev/x", "baudrate": 1234},
                            "impctl.toml")
    with pytest.raises(InputError, match="unknown key"):
        config_from_mapping({"hots": "x"}, "impctl.toml")
    with pytest.raises(InputError, match="-4…4"):
        config_from_mapping({"writes": {"correction_k": [-5, 0]}})
    # the owner's curve points are the daemon's to read, never a setting
    with pytest.raises(InputError, match=r"\[heatpump.writes\] key 'loop1_curve_owner_c': "
                                         "set by the daemon, not configured"):
        config_from_mapping({"host": "x", "writes": {"loop1_curve_owner_c": [60.0, 30.0]}},
                            "impctl.toml")
