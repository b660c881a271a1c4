"""``[inputs]`` end to end: Home Assistant's ``mqtt_statestream`` → a real mosquitto → the
``impctl daemon`` subprocess → a night on the ``impctl-sim`` subprocess (accelerated clock,
3600×) → the store → ``impctl export`` / ``status`` / ``check-config``.

Published as ``mqtt_statestream`` does: the entity's state as a plain string, retained, QoS 1,
on ``homeassistant/sensor/<id>/state``. Nothing is mocked.
"""

from __future__ import annotations

import csv
import json
from datetime import datetime
from zoneinfo import ZoneInfo

from cli_fixtures import run_impctl
from daemon_fixtures import (
    daemon_mapping,
    sim_process,
    start_daemon,
    stop_process,
    store_query,
    wait_until,
    write_config,
)
from mqtt_fixtures import broker, check_discovery, home_assistant, mqtt_section

TZ = ZoneInfo("Europe/Ljubljana")
# Half an hour per second, and a start hours before the night: a busy machine may deschedule
# the daemon for seconds, and each one is simulated time.
SPEED = 1800.0
BASE = "impctl/gw1"
POWER = "homeassistant/sensor/house_power/state"
LIVING = "homeassistant/sensor/living_t/state"
BEDROOM = "homeassistant/sensor/bedroom_t/state"
WEATHER = "homeassistant/sensor/weather_t/state"
PEOPLE = "homeassistant/sensor/people_home/state"


def _statestream(ha, topic: str, state: str) -> None:
    """What mqtt_statestream sends for an entity's new state."""
    wait_until(ha.client.is_connected, 30, "the publisher's MQTT connection")
    ha.client.publish(topic, state, qos=1, retain=True).wait_for_publish(30)


def _changes(values: list) -> list:
    """The runs of a sequence: [2, 2, None, None] → [2, None]."""
    return [v for i, v in enumerate(values) if i == 0 or v != values[i - 1]]


def test_a_night_records_the_houses_sensors_and_exports_them(tmp_path):
    epoch = datetime(2026, 1, 12, 15, 0, tzinfo=TZ)  # the scheduled night acts at 21:30
    inputs = {"house_power_w": POWER, "house_power_includes_heat_pump": True,
              "room_temperature_c": [LIVING, BEDROOM], "outdoor_temperature_c": WEATHER,
              "occupants": PEOPLE,
              # Published once, before the night: 3600× makes an hour a wall second. The
              # occupant count is never republished: stale an hour after it arrived.
              "max_age_s": 86_400.0, "occupants_max_age_s": 3600.0}
    with broker(tmp_path / "broker") as b, home_assistant(b.port) as ha, \
            sim_process(tmp_path, epoch, SPEED, plant="iso") as sim:
        for topic, state in [(POWER, "2523.4"), (LIVING, "20.5"), (BEDROOM, "21.5"),
                             (WEATHER, "2.5"), (PEOPLE, "2")]:
            _statestream(ha, topic, state)
        mapping = daemon_mapping(
            tmp_path / "state", sim.port, sim.clock,
            night={"window": "22:00-05:00", "preheat_h": 0.5, "sample_interval_s": 300},
            campaign={"enabled": True, "mode": "fixed", "constrained_nights": 1,
                      "normal_setpoints_c": [], "fit_when_complete": False},
            mqtt=mqtt_section(b), inputs=inputs)
        config = write_config(tmp_path / "config.toml", mapping)
        db = tmp_path / "state" / "impctl.db"
        d = start_daemon(config, db, tmp_path / "daemon.log")
        try:
            wait_until(lambda: "next night job at" in d.output(), 30, "the daemon", proc=d.proc)
            # Before the night: the next experiment as a timestamp, the energy counters.
            wait_until(lambda: ha.latest(f"{BASE}/state"), 20, "a state", proc=d.proc)
            idle = ha.latest(f"{BASE}/state").json()
            assert datetime.fromisoformat(idle["next_night_at"]) == datetime(
                2026, 1, 12, 21, 30, tzinfo=TZ)
            assert idle["energy_el_kwh"] is not None and idle["energy_heat_kwh"] is not None
            configs = {m.topic: json.loads(m.payload) for m in ha.under("homeassistant/")
                       if m.payload and m.topic.endswith("/config")}
            assert check_discovery(configs) == []
            assert configs["homeassistant/sensor/gw1/energy_el/config"]["state_class"] == (
                "total_increasing")
            # Well into the night, Home Assistant's sensors go bad one way or another.
            wait_until(lambda: store_query(db, lambda s: s.sample_count(1)) >= 30, 40,
                       "the night's samples", proc=d.proc)
            for _ in range(2):  # the same malformed state twice: one log line
                _statestream(ha, LIVING, "21,5")  # a decimal comma
            _statestream(ha, POWER, "0.7")  # the meter switched to kW
            _statestream(ha, BEDROOM, "unavailable")  # a sensor's battery died
            wait_until(lambda: store_query(db, lambda s: s.night(1).valid) is not None, 40,
                       "the night to end", proc=d.proc)
            night = store_query(db, lambda s: s.night(1))
            assert (night.state, night.valid) == ("done", True), night.reasons
            samples = store_query(db, lambda s: s.samples(1))
            rows = store_query(db, lambda s: s.house_inputs(1))
        finally:
            assert stop_process(d.proc) == 0
        log = d.output()

    # One row per sample, at the sample's instant.
    assert [r.ts for r in rows] == [s.ts for s in samples]
    p_el = {s.ts: s.p_el_w for s in samples}
    assert any(p_el[r.ts] > 100 for r in rows)  # the preheat ran the heat pump
    for r in rows:
        assert r.t_out_ref_c == 2.5 and r.t_out_c == 0.0  # the ideal plant's exact sensor
        if r.house_power_w is not None:
            # The meter sees the heat pump too: its own power (register 2129) is taken off;
            # a difference below zero (the meter lagging the heat pump) is no reading.
            assert r.house_power_w == 2523.4
            net = 2523.4 - p_el[r.ts]
            assert r.p_house_w == (net if net >= 0 else None)
    assert any(r.p_house_w is not None and p_el[r.ts] > 100 for r in rows)
    # Good values first, then missing: never the old value, never the malformed one.
    # The occupant count arrived before the night (at the daemon's subscription, retained)
    # and went stale an hour later: the night's last hours have none.
    assert _changes([r.occupants for r in rows]) in ([2.0, None], [None])
    assert rows[-1].occupants is None
    aged = [r.occupants_age_s for r in rows if r.occupants is not None]
    assert all(0 <= a <= 3600.0 for a in aged)
    assert _changes([r.house_power_w for r in rows]) == [2523.4, None]
    assert _changes([r.t_rooms_c for r in rows]) == [21.0, None]
    assert _changes([r.rooms for r in rows]) == [2, None]
    assert log.count("input room_temperature_c") == 1 and "'21,5' is not a number" in log
    assert "input occupants" not in log  # stale is not malformed: no warning
    assert log.count("input house_power_w") == 1 and "0.7 looks like kW" in log
    assert "bedroom_t" not in log  # "unavailable" is Home Assistant's own: no warning
    # The daemon says so itself, once, as soon as the evidence is there.
    assert log.count("a persistent offset over 1.5 K") == 1, log

    # The export carries them as NIGHTS columns, row for row.
    out = tmp_path / "nights.csv"
    done = run_impctl("export", "--config", str(config), "--out", str(out))
    assert done.returncode == 0, done.stderr
    with out.open() as fh:
        table = list(csv.DictReader(fh))
    by_ts = {r.ts.isoformat(): r for r in rows}
    assert len(table) >= 60
    for line in table:
        r = by_ts[line["timestamp"]]
        for col in ("p_house_w", "t_rooms_c", "t_out_ref_c", "occupants"):
            want = getattr(r, col)
            assert (line[col] == "") if want is None else float(line[col]) == want, col
    assert {line["t_out_ref_c"] for line in table} == {"2.5"}
    assert table[-1]["occupants"] == ""

    # The heat pump's outdoor sensor reads 2.5 K below the reference all night: reported.
    check = run_impctl("check-config", "--config", str(config))
    assert check.returncode == 0, check.stderr
    warn = [ln for ln in check.stdout.splitlines() if ln.startswith("WARNING:")]
    assert len(warn) == 1 and "-2.5 K against the reference" in warn[0], check.stdout
    assert "persistent offset over 1.5 K" in warn[0]
    assert "2 room sensors" in check.stdout
    text = run_impctl("status", "--config", str(config)).stdout
    assert "inputs:    household power minus the heat pump's own" in text, text
    assert "outdoor ref 2.5 °C" in text and "persistent offset over 1.5 K" in text, text
    status = json.loads(run_impctl("status", "--json", "--config", str(config)).stdout)
    off = status["inputs"]["t_out_offset"]
    assert off["persistent"] and off["offset_k"] == -2.5 and off["pairs"] >= len(rows)
