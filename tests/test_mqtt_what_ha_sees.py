"""What Home Assistant is told: no setpoint read loosely, no night's old sample as now, the
next experiment after a skip. A real mosquitto, the real daemon and simulator."""

from __future__ import annotations

import json
import time
from datetime import datetime
from zoneinfo import ZoneInfo

from daemon_fixtures import (
    daemon_mapping,
    sim_process,
    start_daemon,
    stop_process,
    store_query,
    wait_until,
    write_config,
)
from mqtt_fixtures import broker, home_assistant, mqtt_section

TZ = ZoneInfo("Europe/Ljubljana")
BASE = "impctl/gw1"
ONE_CONSTRAINED = {"enabled": True, "mode": "fixed", "constrained_nights": 1,
                   "normal_setpoints_c": [], "fit_when_complete": False}


def _start(config, db, log, ha):
    d = start_daemon(config, db, log)
    wait_until(lambda: "next night job at" in d.output(), 30, "the daemon", proc=d.proc)
    wait_until(lambda: (m := ha.latest(f"{BASE}/availability")) and m.payload == b"online"
               and "MQTT connected" in d.output(), 20, "the daemon online", proc=d.proc)
    return d


def test_a_setpoint_with_underscores_is_refused(tmp_path):
    """``float()`` reads '2_2' as 22; a mistyped setpoint is refused with one line, not a
    command for another setpoint."""
    noon = datetime(2026, 1, 12, 12, 0, tzinfo=TZ)
    with broker(tmp_path / "broker") as b, home_assistant(b.port) as ha, \
            sim_process(tmp_path, noon, 60.0, plant="iso") as sim:
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            tmp_path / "state", sim.port, sim.clock, campaign={"enabled": False},
            night={"window": "22:00-05:00", "preheat_h": 0.5},
            mqtt=mqtt_section(b, commands=True)))
        db = tmp_path / "state" / "impctl.db"
        d = _start(config, db, tmp_path / "daemon.log", ha)
        try:
            wait_until(lambda: ha.latest(f"{BASE}/settings"), 10, "the settings")
            ha.press(f"{BASE}/cmd/night_setpoint", "2_2")
            ha.press(f"{BASE}/cmd/trigger",
                     json.dumps({"kind": "normal", "setpoint_c": "2_0", "when": "tonight"}))
            wait_until(lambda: d.output().count("MQTT command") + d.output().count(
                "MQTT setting") >= 2, 10, "two log lines", proc=d.proc)
            time.sleep(0.5)
            settings = ha.latest(f"{BASE}/settings").json()
            queued = store_query(db, lambda s: s.pending_requests())
            # Both payloads are not numbers written with the digits 0-9: refused, nothing set.
            assert settings["setpoint_c"] != 22.0, (settings, d.output())
            assert queued == [], queued
        finally:
            stop_process(d.proc)


def test_a_failed_idle_read_after_a_night_publishes_nothing_as_now(tmp_path):
    """After a night, an idle read that fails: the values are missing and the heat-pump link
    is off — not the night's last sample, hours old, shown as now."""
    # An hour before the night's start (21:30): at 1800× the daemon's start-up takes 10–15
    # virtual minutes; from 21:15 a slow start now and then missed the night, and the test
    # waited a day for the next one.
    epoch = datetime(2026, 1, 12, 20, 30, tzinfo=TZ)
    with broker(tmp_path / "broker") as b, home_assistant(b.port) as ha, \
            sim_process(tmp_path, epoch, 1800.0, plant="iso") as sim:
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            tmp_path / "state", sim.port, sim.clock, campaign=ONE_CONSTRAINED,
            night={"window": "22:00-01:00", "preheat_h": 0.5, "sample_interval_s": 300},
            mqtt=mqtt_section(b, commands=True, idle_interval_s=10.0)))
        db = tmp_path / "state" / "impctl.db"
        d = _start(config, db, tmp_path / "daemon.log", ha)
        try:
            wait_until(lambda: store_query(db, lambda s: s.nights()) and store_query(
                db, lambda s: s.night(1).valid) is not None, 60, "the night to end",
                proc=d.proc)
            last_sample = store_query(db, lambda s: s.samples(1))[-1]
            # An idle read after the night (newer than its last sample) shows up first.
            wait_until(lambda: (m := ha.latest(f"{BASE}/state")) and m.json()[
                "night_state"] == "idle" and m.json()["ts"] is not None and m.json()["ts"]
                > last_sample.ts.isoformat(), 30, "an idle read", proc=d.proc)
            t = time.monotonic()
            sim.set_faults("drop")  # the gateway closes every connection: the link is down
            wait_until(lambda: "idle read for MQTT failed" in d.output(), 60,
                       "a failed idle read", proc=d.proc)
            # The state follows the failed read at once; the next is an idle interval later.
            time.sleep(0.5)
            latest = ha.latest(f"{BASE}/state")
            assert latest.at > t, "no state published after the failed read"
            state = latest.json()
            # The heat pump did not answer: no value, the link off; never an old number.
            assert (state["t_air_c"], state["ts"], state["link_ok"]) == (None, None, False), (
                state, last_sample.ts.isoformat(), last_sample.t_air_c)
        finally:
            stop_process(d.proc)


def test_next_experiment_moves_to_the_night_after_a_skip(tmp_path):
    """After 'Skip tonight', Home Assistant's 'Next experiment' shows the night after it, at
    once."""
    noon = datetime(2026, 1, 12, 12, 0, tzinfo=TZ)
    with broker(tmp_path / "broker") as b, home_assistant(b.port) as ha, \
            sim_process(tmp_path, noon, 60.0, plant="iso") as sim:
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            tmp_path / "state", sim.port, sim.clock, campaign=ONE_CONSTRAINED,
            night={"window": "22:00-05:00", "preheat_h": 0.5},
            mqtt=mqtt_section(b, commands=True)))
        db = tmp_path / "state" / "impctl.db"
        d = _start(config, db, tmp_path / "daemon.log", ha)
        try:
            wait_until(lambda: (m := ha.latest(f"{BASE}/state")) and m.json()[
                "next_night_at"], 20, "the next night", proc=d.proc)
            tonight = ha.latest(f"{BASE}/state").json()["next_night_at"]
            assert tonight.startswith("2026-01-12T21:30"), tonight
            ha.press(f"{BASE}/cmd/skip_tonight", "skip_tonight")
            wait_until(lambda: "MQTT command skip_tonight" in d.output(), 10, "the skip",
                       proc=d.proc)
            # at once, not at the bridge's next once-a-minute look
            wait_until(lambda: ha.latest(f"{BASE}/state").json()["skip_tonight"], 20,
                       "the skip in the state", proc=d.proc)
            state = ha.latest(f"{BASE}/state").json()
            assert state["next_night_at"].startswith("2026-01-13T21:30"), state
        finally:
            stop_process(d.proc)
