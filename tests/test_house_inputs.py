"""``[inputs]``: the house's own sensors (Home Assistant over MQTT) — payloads, configuration,
the latest-value cache on a controlled clock, the rows in a real SQLite store, the export
columns, the outdoor-sensor check, and the Home Assistant entities that come with them.

The broker end to end (mosquitto, the daemon, a night on the simulator) is
``test_house_inputs_daemon.py``.
"""

from __future__ import annotations

import json
import logging
from dataclasses import fields
from datetime import UTC, datetime, timedelta

import pytest
from mqtt_fixtures import check_discovery

from impctl.clock import VirtualClock
from impctl.config import ConfigError, config_from_mapping
from impctl.daemon.house_inputs import HouseInputs
from impctl.heatpump import Snapshot
from impctl.kronoterm.decode import Reading
from impctl.kronoterm.registers import Generation
from impctl.mqtt.config import MqttConfig
from impctl.mqtt.homeassistant.discovery import DeviceIdentity, Limits, discovery_messages
from impctl.mqtt.homeassistant.payloads import LiveState, fit_payloads
from impctl.mqtt.inputs import InputsConfig, parse_payload
from impctl.store import Sample, Store
from impctl.store.export import COLUMNS, nights_rows
from impctl.store.recording.house_inputs import outdoor_offset

T0 = datetime(2026, 1, 12, 21, 0, tzinfo=UTC)
POWER, LIVING, BEDROOM = "ha/sensor/house_power/state", "ha/sensor/living/state", \
    "ha/sensor/bedroom/state"
WEATHER, PEOPLE = "ha/sensor/weather_t/state", "ha/sensor/people_home/state"


# -- payloads ------------------------------------------------------------------------------------
@pytest.mark.parametrize(("name", "payload", "value"), [
    ("house_power_w", b"523.4", 523.4), ("house_power_w", b" 1200\n", 1200.0),
    ("house_power_w", b"1e3", 1000.0), ("room_temperature_c:0", b"-0.5", None),
    ("room_temperature_c:0", b"20.25", 20.25), ("outdoor_temperature_c", b"-12.5", -12.5),
    ("occupants", b"2", 2.0), ("occupants", b"0", 0.0), ("occupants", b"3.0", 3.0)])
def test_plain_numbers_in_range_are_values(name, payload, value):
    got, problem = parse_payload(name, payload)
    assert (got, problem is None) == (value, value is not None)


@pytest.mark.parametrize("payload", [b"unavailable", b"unknown", b"", b"  ", b"None"])
def test_home_assistant_without_a_value_is_missing_without_a_problem(payload):
    assert parse_payload("house_power_w", payload) == (None, None)


@pytest.mark.parametrize(("name", "payload", "says"), [
    ("house_power_w", b"0.52", "looks like kW"), ("house_power_w", b"1.8", "looks like kW"),
    ("house_power_w", b"523 W", "carries a unit"), ("house_power_w", b"0.5kW", "carries a unit"),
    ("house_power_w", b'{"power": 523}', "is JSON"), ("house_power_w", b'"523"', "is JSON"),
    ("house_power_w", b"nan", "not a finite number"), ("house_power_w", b"inf", "finite"),
    ("house_power_w", b"-300", "negative"), ("house_power_w", b"45000", "outside"),
    ("house_power_w", b"on", "not a number"), ("house_power_w", b"\xff\xfe", "UTF-8"),
    ("room_temperature_c:1", b"21,5", "not a number"),
    ("room_temperature_c:1", b"70", "outside"), ("outdoor_temperature_c", b"-80", "outside"),
    ("outdoor_temperature_c", b"21.5 \xc2\xb0C", "carries a unit"),
    ("occupants", b"1.5", "whole number"), ("occupants", b"-1", "outside")])
def test_malformed_payloads_are_missing_with_a_reason(name, payload, says):
    value, problem = parse_payload(name, payload)
    assert value is None and says in problem


# -- configuration -------------------------------------------------------------------------------
def _mapping(inputs: dict, mqtt: bool = True, **heatpump) -> dict:
    m = {"heatpump": {"host": "127.0.0.1", **heatpump}, "inputs": inputs}
    if mqtt:
        m["mqtt"] = {"host": "127.0.0.1", "client_id": "gw1"}
    return m


def test_no_inputs_section_means_none_and_every_input_is_optional():
    assert config_from_mapping({"heatpump": {"host": "h"}}).inputs is None
    cfg = config_from_mapping(_mapping({"occupants": PEOPLE})).inputs
    assert cfg == InputsConfig(occupants=PEOPLE)
    assert cfg.topics() == {PEOPLE: "occupants"}
    one = config_from_mapping(_mapping({"room_temperature_c": LIVING})).inputs
    assert one.room_temperature_c == (LIVING,)


def test_every_problem_of_inputs_at_once(tmp_path):
    bad = {"house_power_w": "ha/+/power", "room_temperature_c": [LIVING, LIVING, 3],
           "outdoor_temperature_c": "impctl/gw1/state", "occupants": 2,
           "max_age_s": 10, "occupants_max_age_s": "a day",
           "house_power_includes_heat_pump": "yes", "kwh": True}
    with pytest.raises(ConfigError) as exc:
        config_from_mapping(_mapping(bad), tmp_path / "config.toml")
    lines = str(exc.value).splitlines()
    for key, says in [("house_power_w", "wildcards"), ("room_temperature_c", "list of topics"),
                      ("outdoor_temperature_c", "impctl's own topic"),
                      ("occupants", "must be a topic"), ("max_age_s", "60–86400 s"),
                      ("occupants_max_age_s", "finite number"),
                      ("house_power_includes_heat_pump", "true or false"), ("kwh", "unknown")]:
        assert any(f"key 'inputs.{key}'" in ln and says in ln for ln in lines), (key, lines)
    assert all(ln.startswith(str(tmp_path / "config.toml")) for ln in lines)
    dup = {"room_temperature_c": [LIVING, BEDROOM], "occupants": LIVING}
    with pytest.raises(ConfigError, match="one topic, one input"):
        config_from_mapping(_mapping(dup))


def test_inputs_need_the_broker_and_the_heat_pumps_own_power():
    with pytest.raises(ConfigError, match=r"key 'inputs': needs \[mqtt\]"):
        config_from_mapping(_mapping({"occupants": PEOPLE}, mqtt=False))
    with pytest.raises(ConfigError, match="needs inputs.house_power_w"):
        config_from_mapping(_mapping({"house_power_includes_heat_pump": True}))
    # A compact controller has no register 2129: the subtraction is refused, not guessed.
    with pytest.raises(ConfigError, match="compact controller does not report its electrical"):
        config_from_mapping(_mapping({"house_power_w": POWER,
                                      "house_power_includes_heat_pump": True},
                                     generation="compact"))
    ok = config_from_mapping(_mapping({"house_power_w": POWER,
                                       "house_power_includes_heat_pump": True},
                                      generation="extended"))
    assert ok.inputs.house_power_includes_heat_pump


# -- the cache on a controlled clock -------------------------------------------------------------
class _Wall:
    def __init__(self):
        self.s = 1_000.0

    def __call__(self) -> float:
        return self.s


def _snapshot(at: datetime, p_el_w: float | None = 400.0, t_out_c: float = 1.0) -> Snapshot:
    """A real Snapshot: every reading missing but the ones the inputs use."""
    readings = {}
    for f in fields(Snapshot):
        if f.name in ("timestamp", "generation"):
            continue
        readings[f.name] = Reading.unavailable(f.name, "", at, "not read in this test")
    readings["t_out_c"] = Reading("t_outdoor", t_out_c, "°C", at)
    readings["p_el_w"] = (Reading("power_electrical", p_el_w, "W", at) if p_el_w is not None
                          else Reading.unavailable("power_electrical", "W", at,
                                                   "not on this controller"))
    return Snapshot(timestamp=at, generation=Generation.EXTENDED, **readings)


def _inputs(store=None, **cfg) -> tuple[HouseInputs, VirtualClock, _Wall]:
    wall = _Wall()
    clock = VirtualClock(T0, 1.0, wall.s, wall=wall)
    base = {"house_power_w": POWER, "room_temperature_c": (LIVING, BEDROOM),
            "outdoor_temperature_c": WEATHER, "occupants": PEOPLE, "max_age_s": 600.0,
            "occupants_max_age_s": 7200.0}
    return HouseInputs(InputsConfig(**{**base, **cfg}), clock, store), clock, wall


def test_latest_values_with_their_age_and_stale_ones_missing():
    inputs, clock, wall = _inputs(house_power_includes_heat_pump=True)
    assert sorted(inputs.topics) == sorted([POWER, LIVING, BEDROOM, WEATHER, PEOPLE])
    for topic, payload in [(POWER, b"1523.4"), (LIVING, b"20.5"), (BEDROOM, b"21.5"),
                           (WEATHER, b"-2.5"), (PEOPLE, b"2")]:
        inputs.receive(topic, payload)
    wall.s += 120
    inputs.receive(LIVING, b"20.7")
    row = inputs.row(7, _snapshot(clock.now(), p_el_w=400.0))
    assert row.house_power_w == 1523.4 and row.house_power_age_s == 120
    assert row.p_house_w == pytest.approx(1123.4)  # the heat pump's own 400 W taken off
    assert row.t_rooms_c == pytest.approx(21.1) and row.rooms == 2
    assert row.t_rooms_age_s == 120  # the oldest room reading
    assert (row.t_out_ref_c, row.t_out_c, row.occupants) == (-2.5, 1.0, 2.0)
    # 10 min later: 720 s > max_age_s for all but the living room and the occupants.
    wall.s += 600
    row = inputs.row(7, _snapshot(clock.now()))
    assert (row.house_power_w, row.p_house_w, row.t_out_ref_c) == (None, None, None)
    assert row.t_rooms_c is None and row.rooms is None  # every room, or no mean
    assert (row.occupants, row.occupants_age_s) == (2.0, 720.0)
    wall.s += 7200
    assert inputs.row(7, _snapshot(clock.now())).occupants is None


def test_a_retained_value_redelivered_at_a_reconnect_keeps_its_age():
    inputs, clock, wall = _inputs()
    inputs.receive(POWER, b"840", retained=True)  # at start-up: counts from its arrival
    wall.s += 500
    inputs.receive(POWER, b"840", retained=True)  # the broker again, after a reconnect
    row = inputs.row(1, _snapshot(clock.now()))
    assert (row.house_power_w, row.house_power_age_s) == (840.0, 500.0)
    wall.s += 200  # Home Assistant said nothing for 700 s > max_age_s = 600 s
    assert inputs.row(1, _snapshot(clock.now())).house_power_w is None
    inputs.receive(POWER, b"840")  # published now (the same value): fresh
    assert inputs.row(1, _snapshot(clock.now())).house_power_age_s == 0.0
    wall.s += 100
    inputs.receive(POWER, b"900", retained=True)  # a different retained value: news
    assert inputs.row(1, _snapshot(clock.now())).house_power_w == 900.0


def test_malformed_payload_is_one_log_line_and_a_missing_value(caplog):
    inputs, clock, wall = _inputs()
    inputs.receive(POWER, b"840")
    caplog.set_level(logging.INFO, "impctl.inputs")
    for _ in range(3):  # a sensor repeating the same bad payload: one line
        inputs.receive(POWER, b"0.84")
    assert inputs.row(1, _snapshot(clock.now())).house_power_w is None  # not the old 840
    warned = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warned) == 1 and "looks like kW" in warned[0].getMessage()
    assert POWER in warned[0].getMessage()
    inputs.receive(PEOPLE, b"unavailable")  # Home Assistant's own "no value": no warning
    assert len([r for r in caplog.records if r.levelno == logging.WARNING]) == 1
    inputs.receive(POWER, b"910")
    assert inputs.row(1, _snapshot(clock.now())).house_power_w == 910
    assert any("back" in r.getMessage() for r in caplog.records)
    inputs.receive("ha/other/state", b"5")  # not an input: ignored
    assert "ha/other/state" not in inputs.topics


def test_heat_pump_power_missing_or_larger_leaves_p_house_missing(caplog):
    inputs, clock, _ = _inputs(house_power_includes_heat_pump=True)
    inputs.receive(POWER, b"900")
    caplog.set_level(logging.ERROR, "impctl.inputs")
    for _ in range(2):
        row = inputs.row(1, _snapshot(clock.now(), p_el_w=None))
        assert (row.house_power_w, row.p_house_w) == (900.0, None)
    assert len(caplog.records) == 1 and "register 2129" in caplog.records[0].getMessage()
    # A meter lagging the heat pump's start: house − heat pump < 0 is no reading.
    assert inputs.row(1, _snapshot(clock.now(), p_el_w=1500.0)).p_house_w is None
    plain, clock2, _ = _inputs()  # a meter that excludes the heat pump: taken as it is
    plain.receive(POWER, b"900")
    assert plain.row(1, _snapshot(clock2.now(), p_el_w=1500.0)).p_house_w == 900.0


# -- stored with the samples, exported -----------------------------------------------------------
def test_rows_are_stored_beside_the_samples_and_exported(tmp_path):
    with Store(tmp_path / "impctl.db") as store:
        start = T0 + timedelta(hours=1)
        nid = store.create_night("constrained", 21.0, start, start + timedelta(hours=1))
        store.assess_night(nid, True, [])
        inputs, clock, wall = _inputs(store, house_power_includes_heat_pump=True,
                                      max_age_s=3600.0)
        wall.s += 3600  # the night's window
        inputs.receive(POWER, b"700")
        inputs.receive(LIVING, b"20.0")
        inputs.receive(BEDROOM, b"21.0")
        inputs.receive(PEOPLE, b"3")
        stamps = []
        for i in range(4):
            snap = _snapshot(clock.now(), p_el_w=50.0, t_out_c=0.5)
            store.add_sample(Sample(nid, snap.timestamp, t_air_c=21.0 - 0.1 * i, t_out_c=0.5,
                                    q_hc_w=0.0, p_el_w=50.0))
            inputs.record(nid, snap)
            stamps.append(snap.timestamp)
            if i == 1:
                inputs.receive(PEOPLE, b"two")  # malformed from here on
            wall.s += 300
        inputs.record(None, _snapshot(clock.now()))  # between nights, no reference: no row
        assert store.house_inputs(None) == []
        rows = nights_rows(store)
        assert [r["timestamp"] for r in rows] == [t.isoformat() for t in stamps]
        assert set(COLUMNS) == set(rows[0])
        assert [r["p_house_w"] for r in rows] == [650.0] * 4
        assert [r["t_rooms_c"] for r in rows] == [20.5] * 4
        assert [r["occupants"] for r in rows] == [3.0, 3.0, None, None]
        assert [r["t_out_ref_c"] for r in rows] == [None] * 4  # never published
        # Reopened (what `impctl export` sees): the same rows.
    with Store(tmp_path / "impctl.db") as store:
        assert [r.p_house_w for r in store.house_inputs(nid)] == [650.0] * 4


def test_outdoor_offset_needs_evidence_before_it_is_called_persistent():
    def pairs(n, step_min, diff):
        return [(T0 + timedelta(minutes=step_min * i), 2.0 + diff, 2.0) for i in range(n)]

    assert outdoor_offset([]) is None
    short = outdoor_offset(pairs(6, 5, -2.4))  # 25 minutes: not yet
    assert not short.persistent and "too few readings" in short.describe()
    off = outdoor_offset(pairs(30, 10, -2.4))
    assert off.persistent and off.offset_k == pytest.approx(-2.4)
    assert "persistent offset over 1.5 K" in off.describe() and "-2.4 K" in off.describe()
    near = outdoor_offset(pairs(30, 10, 0.9))
    assert not near.persistent and "within 1.5 K" in near.describe()
    # A sign that flips (sun on one sensor in the afternoon): not a persistent offset.
    mixed = [(t, hp + (4.0 if i % 3 else -4.0), ref)
             for i, (t, hp, ref) in enumerate(pairs(30, 10, 0.0))]
    assert not outdoor_offset(mixed).persistent


# -- what Home Assistant gets --------------------------------------------------------------------
def test_discovery_has_energy_timestamp_and_enum_entities():
    cfg = MqttConfig(host="b", client_id="gw1")
    msgs = discovery_messages(cfg, DeviceIdentity("Kronoterm", "tcp 1.2.3.4", "1"),
                              Limits(15.0, 26.0, 1.5, 21.0))
    configs = {t: json.loads(p) for t, p in msgs}
    assert check_discovery(configs) == []
    by_key = {t.split("/")[3]: c for t, c in configs.items()}
    for key, field in (("energy_el", "energy_el_kwh"), ("energy_heat", "energy_heat_kwh")):
        c = by_key[key]
        assert (c["device_class"], c["unit_of_measurement"], c["state_class"]) == (
            "energy", "kWh", "total_increasing")
        assert field in c["value_template"]
    assert by_key["next_night"]["device_class"] == "timestamp"
    state = LiveState(night_state="active", night_kind="constrained",
                      next_night_at=T0, energy_el_kwh=1234.56, energy_heat_kwh=4321.0)
    payload = state.as_json()
    assert payload["next_night_at"] == "2026-01-12T21:00:00+00:00"
    assert (payload["energy_el_kwh"], payload["energy_heat_kwh"]) == (1234.6, 4321.0)
    for key in ("night_state", "night_kind"):
        c = by_key[key]
        assert c["device_class"] == "enum" and payload[key] in c["options"]
    assert set(by_key["night_state"]["options"]) == {"idle", "preparing", "active",
                                                     "restoring"}
    assert LiveState().as_json()["night_kind"] in by_key["night_kind"]["options"]


def test_heat_loss_in_plain_words_once_a_fit_exists():
    assert "heat_loss" not in fit_payloads(None)["hlc"]
    fit = {"lumped": {"hlc": {"value": 106.0, "low": 98.0, "high": 114.0, "determined": True}}}
    words = fit_payloads((T0, [1, 2], fit))["hlc"]["heat_loss"]
    assert words.startswith("loses 106 W per °C") and "3.3 kW at −10 °C outside" in words
    undetermined = {"lumped": {"hlc": {"value": 106.0, "determined": False}}}
    assert "heat_loss" not in fit_payloads((T0, [1], undetermined))["hlc"]


def test_example_config_documents_every_input_and_its_block_is_valid(tmp_path):
    import tomllib
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "deploy" / "config.example.toml").read_text()
    lines = text.splitlines()
    start = lines.index(next(ln for ln in lines if ln.startswith("# [inputs]")))
    block = []
    for ln in lines[start:]:
        if not ln.strip():
            break
        block.append(ln[2:])
    section = tomllib.loads("\n".join(block))["inputs"]
    assert set(section) == {f.name for f in fields(InputsConfig)}
    cfg = config_from_mapping({"heatpump": {"host": "h", "generation": "extended"},
                               "mqtt": {"host": "b"}, "inputs": section}).inputs
    assert (cfg.max_age_s, cfg.occupants_max_age_s) == (InputsConfig.max_age_s,
                                                         InputsConfig.occupants_max_age_s)
    assert len(cfg.room_temperature_c) == 2 and cfg.house_power_includes_heat_pump is False


def test_export_without_inputs_has_empty_numeric_columns(tmp_path):
    import pandas as pd

    from impctl.store.export import export_nights

    with Store(tmp_path / "impctl.db") as store:
        nid = store.create_night("normal", 22.0, T0, T0 + timedelta(hours=1))
        store.assess_night(nid, True, [])
        for i in range(3):
            store.add_sample(Sample(nid, T0 + timedelta(minutes=5 * i), t_air_c=22.0,
                                    t_out_c=1.0, q_hc_w=900.0))
        export_nights(store, tmp_path / "n.parquet", "parquet")
        export_nights(store, tmp_path / "n.csv", "csv")
    frame = pd.read_parquet(tmp_path / "n.parquet")
    for col in ("p_house_w", "t_rooms_c", "t_out_ref_c", "occupants"):
        assert frame[col].dtype == float and frame[col].isna().all()
    assert frame["defrost"].isna().all()   # not logged: missing, not "no defrost"
    header = (tmp_path / "n.csv").read_text().splitlines()[0]
    assert ",p_house_w,t_rooms_c,t_out_ref_c,occupants,defrost," in header
