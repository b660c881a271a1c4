"""Nothing wrong is stored, bad input is one line: timestamps with short UTC offsets, a
sentinel in the electrical power, an external room sensor's error code, a sensor's age across
a wall-clock step back. Real parts: the simulator over loopback Modbus TCP, a real SQLite
store, ``impctl`` through ``main``.
"""

from __future__ import annotations

from dataclasses import fields
from datetime import UTC, datetime, timedelta

import pandas as pd
from cli_fixtures import run_impctl
from impctl_sim import SimConfig, constant_weather, parse_faults
from sim_fixtures import client, clock, run
from sim_fixtures import simulator as started

from impctl.clock import VirtualClock
from impctl.controller.poll import sample_from_snapshot
from impctl.daemon.house_inputs import HouseInputs
from impctl.heatpump import ExternalRegister, Generation, Snapshot
from impctl.kronoterm.decode import Reading
from impctl.mqtt.inputs import InputsConfig
from impctl.store import Store

TZ = "Europe/Ljubljana"


# -- 1. NIGHTS: an ISO 8601 offset of hours only ("+01") ---------------------------------------
def _nights_csv(path, stamps):
    pd.DataFrame({"timestamp": stamps, "t_air": [21.0 - 0.1 * i for i in range(len(stamps))],
                  "t_out": 1.0, "q_hc": 0.0}).to_csv(path, index=False)
    return path


def test_an_hour_only_utc_offset_reads_as_the_same_instant(tmp_path):
    """'2026-01-12T22:00:00+01' is ISO 8601 (±hh): the same instant as '+01:00', not a local
    time."""
    from impctl.imp.tables import parse_timestamps

    base = [datetime(2026, 1, 12, 22) + timedelta(minutes=10 * i) for i in range(3)]
    short = parse_timestamps(pd.Series([t.isoformat() + "+01" for t in base]), "N.csv", TZ)
    full = parse_timestamps(pd.Series([t.isoformat() + "+01:00" for t in base]), "N.csv", TZ)
    assert list(short) == list(full)
    assert short[0].tz_convert("UTC").hour == 21


def test_an_offset_only_pandas_reads_is_one_line_exit_2(tmp_path):
    """'+1' (one digit) is no ISO 8601 offset the reader knows, yet pandas reads it as one:
    one line naming the file, exit status 2, no traceback."""
    stamps = [(datetime(2026, 1, 12, 22) + timedelta(minutes=10 * i)).isoformat() + "+1"
              for i in range(30)]
    path = _nights_csv(tmp_path / "NIGHTS.csv", stamps)
    for command in ("fit", "classify", "season"):
        done = run_impctl(command, "--nights", str(path))
        assert "Traceback" not in done.stderr, (command, done.stderr[-600:])
        assert done.returncode == 2, (command, done.returncode, done.stderr[-300:])
        assert "NIGHTS.csv" in done.stderr and "UTC offset" in done.stderr
        assert len(done.stderr.strip().splitlines()) == 1, done.stderr


# -- 2. a −600 sentinel in the heat pump's electrical power (2129) -----------------------------
def test_electrical_power_sentinel_is_not_stored_nor_subtracted_from_the_house(tmp_path):
    """2129 reads raw −600 (the simulator's 'sensor not connected'). A consumption is never
    negative: the electrical power is missing, and so is the house's own power that would be
    the meter's minus it (house_power_includes_heat_pump) — not 500 + 600 W."""
    async def body():
        cfg = SimConfig(clock=clock(1.0), generation=Generation.EXTENDED,
                        faults=parse_faults("freeze,missing=2129"),
                        weather=constant_weather(-5.0), seed=3)
        async with started(cfg) as sim:
            async with client(sim, generation="extended") as hp:
                snap = await hp.snapshot()
        store = Store(tmp_path / "impctl.db")
        nid = store.create_night("normal", 21.0, snap.timestamp,
                                 snap.timestamp + timedelta(hours=7), source="test")
        store.add_sample(sample_from_snapshot(nid, snap))
        inputs = HouseInputs(InputsConfig(house_power_w="ha/sensor/house_power/state",
                                          house_power_includes_heat_pump=True),
                             sim.clock, store)
        inputs.receive("ha/sensor/house_power/state", b"500")
        inputs.record(nid, snap)
        (sample,) = store.samples(nid)
        (row,) = store.house_inputs(nid)
        store.close()
        return snap, sample, row

    snap, sample, row = run(body(), 60)
    assert snap.p_el_w.raw == -600
    assert (sample.p_el_w, row.p_house_w) == (None, None), (
        f"stored p_el_w = {sample.p_el_w} W, p_house_w = {row.p_house_w} W (meter: 500 W)")


# -- 3. an external room sensor without 'valid' --------------------------------------------------
def test_external_room_sensor_sentinel_is_not_stored_as_t_air(tmp_path):
    """A room sensor on the heat pump's bus ([heatpump.room_sensor] table, no ``valid``)
    reading raw −600, −60 °C scaled ×0.1: outside any room's range (the NIGHTS reader's
    −40…60 °C), so T_air is missing, never −60 °C."""
    async def body():
        cfg = SimConfig(clock=clock(1.0), generation=Generation.EXTENDED,
                        faults=parse_faults("freeze,missing=2161"),
                        weather=constant_weather(-5.0), seed=3)
        room = ExternalRegister(device_id=20, address=2160, datatype="int16", scale=0.1)
        async with started(cfg) as sim:
            async with client(sim, generation="extended", room_sensor=room) as hp:
                snap = await hp.snapshot()
        store = Store(tmp_path / "impctl.db")
        nid = store.create_night("normal", 21.0, snap.timestamp,
                                 snap.timestamp + timedelta(hours=7), source="test")
        store.add_sample(sample_from_snapshot(nid, snap))
        (sample,) = store.samples(nid)
        store.close()
        return snap, sample

    snap, sample = run(body(), 60)
    assert snap.t_air_c.raw == -600
    assert sample.t_air_c is None, f"stored T_air = {sample.t_air_c} °C"


# -- 4. the house's sensors across a backward clock step ----------------------------------------
class _Source:
    def __init__(self, s: float):
        self.s = s

    def __call__(self) -> float:
        return self.s


def _snapshot(at: datetime) -> Snapshot:
    readings = {f.name: Reading.unavailable(f.name, "", at, "not read in this test")
                for f in fields(Snapshot) if f.name not in ("timestamp", "generation")}
    readings["t_out_c"] = Reading("t_outdoor", 1.0, "°C", at)
    return Snapshot(timestamp=at, generation=Generation.EXTENDED, **readings)


def test_a_value_received_before_a_backward_clock_step_does_not_stay_fresh(tmp_path):
    """The reference outdoor sensor last spoke, then NTP stepped the wall clock back 3 h and
    2 h passed (monotonic) without a message: the value is 2 h old against max_age_s of
    10 min, so it is stale — ages run on the monotonic clock, not the stepped wall clock."""
    wall, mono = _Source(1_000_000.0), _Source(50.0)
    t0 = datetime(2026, 1, 12, 18, 0, tzinfo=UTC)
    vclock = VirtualClock(t0, 1.0, wall.s, wall=wall, monotonic=mono)
    store = Store(tmp_path / "impctl.db")
    inputs = HouseInputs(InputsConfig(outdoor_temperature_c="ha/sensor/weather_t/state",
                                      max_age_s=600.0), vclock, store)
    inputs.receive("ha/sensor/weather_t/state", b"-2.5")
    wall.s -= 3 * 3600            # the step
    wall.s += 2 * 3600            # two hours pass, the sensor silent
    mono.s += 2 * 3600
    inputs.record(None, _snapshot(vclock.now()))
    rows = store.house_inputs(None)
    store.close()
    stored = [(r.ts.isoformat(), r.t_out_ref_c, r.t_out_ref_age_s) for r in rows]
    assert stored == [], f"stale reference stored (ts, value, age s): {stored}"
