"""impctl daemon ↔ a real mosquitto broker ↔ a client subscribed as Home Assistant is.

Every test runs the real ``impctl daemon`` subprocess against an ``impctl-sim`` subprocess on
the accelerated clock (3600×: a 7 h night lasts 7 s) and a mosquitto process on a free loopback
port, anonymous or with a ``mosquitto_passwd`` file.
"""

from __future__ import annotations

import contextlib
import json
import signal
import time
from datetime import datetime
from pathlib import Path
from zoneinfo import ZoneInfo

from cli_fixtures import run_impctl
from daemon_fixtures import (
    OWNER_MODE,
    OWNER_SETPOINT_RAW,
    daemon_mapping,
    owner_state,
    run_cli,
    sim_process,
    start_daemon,
    stop_process,
    store_query,
    wait_until,
    write_config,
)
from mqtt_fixtures import (
    broker,
    check_discovery,
    home_assistant,
    mqtt_section,
    render,
    retained,
)

from impctl.store import Store

TZ = ZoneInfo("Europe/Ljubljana")
# Half an hour per second: a busy machine may deschedule the daemon for seconds, and each one
# is simulated time a command or a check could miss.
SPEED = 1800.0
OWNER = (OWNER_SETPOINT_RAW, OWNER_MODE)
BASE = "impctl/gw1"
ONE_CONSTRAINED = {"enabled": True, "mode": "fixed", "constrained_nights": 1,
                   "normal_setpoints_c": [], "fit_when_complete": False}
#: 18 sensors/binary sensors of state, 4 fit sensors, the curve's saving; 5 command entities
#: with commands = true.
N_ENTITIES = {False: 23, True: 28}


@contextlib.contextmanager
def rig(tmp_path: Path, epoch: datetime, mqtt: dict, campaign: dict | None = None,
        speed: float = SPEED, window: str = "22:00-05:00"):
    """(sim, config, db) with an ``[mqtt]`` section (the ideal plant: its sensors read the
    outdoor temperature exactly, which the payload checks rely on)."""
    with sim_process(tmp_path, epoch, speed, plant="iso") as sim:
        mapping = daemon_mapping(
            tmp_path / "state", sim.port, sim.clock,
            night={"window": window, "preheat_h": 0.5, "sample_interval_s": 300},
            campaign=campaign or {"enabled": False}, mqtt=mqtt)
        config = write_config(tmp_path / "config.toml", mapping)
        yield sim, config, tmp_path / "state" / "impctl.db"


def _ready(config, db, log):
    d = start_daemon(config, db, log)
    wait_until(lambda: "next night job at" in d.output(), 30, "the daemon", proc=d.proc)
    return d


def _configs(ha) -> dict[str, dict]:
    return {m.topic: json.loads(m.payload) for m in ha.under("homeassistant/")
            if m.payload and m.topic.endswith("/config")}


def _states(ha, since: float = 0.0) -> list[dict]:
    return [m.json() for m in ha.on(f"{BASE}/state") if m.at >= since]


def test_discovery_values_abort_and_last_will_with_authentication(tmp_path):
    pw = tmp_path / "mqtt.password"
    pw.write_text("impctl-secret\n")
    users = {"impctl": "impctl-secret", "ha": "ha-secret"}
    epoch = datetime(2026, 1, 12, 18, 0, tzinfo=TZ)  # the scheduled night acts at 21:30
    with broker(tmp_path / "broker", users) as b, \
            home_assistant(b.port, username="ha", password="ha-secret") as ha, \
            rig(tmp_path, epoch, mqtt_section(b, username="impctl", password_file=str(pw),
                                              commands=True),
                campaign=ONE_CONSTRAINED) as (sim, config, db):
        d = _ready(config, db, tmp_path / "daemon.log")
        try:
            wait_until(lambda: len(_configs(ha)) == N_ENTITIES[True], 20, "discovery",
                       proc=d.proc)
            configs = _configs(ha)
            assert check_discovery(configs) == []
            # The fit values follow the configs and availability in the same announcement.
            wait_until(lambda: ha.on(f"{BASE}/fit/hlc"), 10, "the fit values", proc=d.proc)
            # Retained: what Home Assistant gets when it (re)subscribes later.
            kept = retained(b.port, username="ha", password="ha-secret")
            assert set(configs) <= set(kept)
            assert kept[f"{BASE}/availability"].payload == b"online"
            assert f"{BASE}/fit/hlc" in kept and f"{BASE}/state" not in kept
            dev = next(iter(configs.values()))["device"]
            assert dev["name"] == "impctl gw1" and dev["identifiers"] == ["impctl_gw1"]
            assert "extended controller" in dev["model"]
            t_air = configs["homeassistant/sensor/gw1/t_air/config"]
            assert (t_air["device_class"], t_air["unit_of_measurement"],
                    t_air["state_class"]) == ("temperature", "°C", "measurement")
            q = configs["homeassistant/sensor/gw1/q_hc/config"]
            assert (q["device_class"], q["unit_of_measurement"]) == ("power", "W")
            # Home Assistant restarts (birth message): impctl announces itself again.
            t = time.monotonic()
            ha.press("homeassistant/status", "online")
            wait_until(lambda: len({m.topic for m in ha.under("homeassistant/")
                                    if m.at > t and m.topic.endswith("/config")})
                       == N_ENTITIES[True], 10, "discovery again", proc=d.proc)
            # No fit yet: the fit sensors are unknown, the coast time unavailable.
            hlc = ha.latest(f"{BASE}/fit/hlc")
            assert render(configs["homeassistant/sensor/gw1/hlc/config"][
                "value_template"], hlc.payload) == "None"
            coast_conf = configs["homeassistant/sensor/gw1/coast_h/config"]
            coast = ha.latest(f"{BASE}/fit/coast_h")
            assert render(coast_conf["availability"][1]["value_template"],
                          coast.payload) == "offline"

            # The scheduled night: values at the sampling rate, as Home Assistant reads them.
            def switched_off():
                return owner_state(sim.port) == (225, 0) and any(
                    s["night_state"] == "active" for s in _states(ha))
            wait_until(switched_off, 40, "the night to switch off", proc=d.proc)
            wait_until(lambda: store_query(db, lambda s: s.sample_count(1)) >= 8, 20,
                       "samples", proc=d.proc)
            samples = {s.ts.isoformat(): s for s in store_query(db, lambda st: st.samples(1))}
            active = [s for s in _states(ha) if s["night_state"] == "active"]
            assert len(active) >= 5
            # The campaign as Home Assistant shows it (issue 18): a fixed plan of one night.
            camp = configs["homeassistant/sensor/gw1/campaign_status/config"]
            assert render(camp["value_template"], json.dumps(active[-1]).encode()) == (
                "fixed plan: 0/1 valid nights")
            assert (active[-1]["campaign_mode"], active[-1]["nights_run"],
                    active[-1]["hlc_rel_pct"]) == ("fixed", 0, None)
            matched = [s for s in active if s["ts"] in samples]
            assert len(matched) >= 5  # each published value is a stored sample's value
            for s in matched:
                row = samples[s["ts"]]
                assert s["t_air_c"] == round(row.t_air_c, 2)
                assert s["t_out_c"] == round(row.t_out_c, 2)
                assert s["night_kind"] == "constrained" and s["experiment_active"]
            payload = ha.latest(f"{BASE}/state").payload
            assert render(t_air["value_template"], payload) == str(
                json.loads(payload)["t_air_c"])
            active_conf = configs["homeassistant/binary_sensor/gw1/experiment_active/config"]
            assert render(active_conf["value_template"], payload) == "ON"

            # Malformed commands: one log line each, nothing queued, the night goes on.
            ha.press(f"{BASE}/cmd/trigger", "{not json")
            ha.press(f"{BASE}/cmd/trigger", json.dumps({"kind": "normal",
                                                         "setpoint_c": 30}))
            wait_until(lambda: d.output().count("MQTT command") >= 2, 10, "the log lines")
            lines = [ln for ln in d.output().splitlines() if "MQTT command" in ln]
            assert len(lines) == 2 and all("ignored" in ln for ln in lines)
            assert "outside the safety limits" in lines[1]
            assert store_query(db, lambda s: s.pending_requests()) == []

            # The household's stop button: the night ends, the owner's settings come back.
            ha.press(f"{BASE}/cmd/abort", "abort")
            wait_until(lambda: owner_state(sim.port) == OWNER, 20, "the restore", proc=d.proc)
            wait_until(lambda: store_query(db, lambda s: s.night(1).valid) is not None, 20,
                       "the night to be closed", proc=d.proc)
            night = store_query(db, lambda s: s.night(1))
            assert (night.state, night.valid) == ("aborted", False)
            assert night.reasons[0] == "aborted on request (mqtt)"
            assert store_query(db, lambda s: s.journal_pending()) == []
            wait_until(lambda: _states(ha)[-1]["night_state"] == "idle", 20, "idle state")
            assert d.proc.poll() is None  # the daemon keeps running

            # kill -9: the broker publishes the last will, retained.
            d.proc.kill()
            d.proc.wait(10)
            wait_until(lambda: ha.latest(f"{BASE}/availability").payload == b"offline", 20,
                       "the last will")
            kept = retained(b.port, f"{BASE}/availability", username="ha",
                            password="ha-secret")
            assert kept[f"{BASE}/availability"].payload == b"offline"
        finally:
            stop_process(d.proc)


def test_broker_outage_mid_night_loses_no_sample(tmp_path):
    # 21:45, long before the window's end: a `now` trigger from Home Assistant is refused
    # in daytime, and at 3600× a start at 03:00 left 2 s for the daemon's start-up, the
    # discovery and three presses — not enough on a loaded machine. A 12 h window: the
    # night (12.5 s) must outlast the outage, the CLI call and both clients' reconnects,
    # which took 6–7 s on a loaded machine (a 7 h night then ended 1.4 s after the daemon
    # was back, before Home Assistant had re-subscribed).
    epoch = datetime(2026, 1, 12, 21, 45, tzinfo=TZ)
    with broker(tmp_path / "broker") as b, home_assistant(b.port) as ha, \
            rig(tmp_path, epoch, mqtt_section(b, commands=True),
                window="22:00-10:00") as (sim, config, db):
        d = _ready(config, db, tmp_path / "daemon.log")
        try:
            wait_until(lambda: len(_configs(ha)) == N_ENTITIES[True], 20, "discovery",
                       proc=d.proc)
            # The trigger button, with the kind and setpoint set through the select/number.
            ha.press(f"{BASE}/cmd/night_kind", "normal")
            ha.press(f"{BASE}/cmd/night_setpoint", "22")
            wait_until(lambda: (ha.latest(f"{BASE}/settings") or None) and ha.latest(
                f"{BASE}/settings").json() == {"kind": "normal", "setpoint_c": 22.0}, 10,
                "the settings")
            ha.press(f"{BASE}/cmd/trigger", "now")
            wait_until(lambda: owner_state(sim.port)[0] == 220, 20, "the triggered night",
                       proc=d.proc)
            wait_until(lambda: store_query(db, lambda s: s.sample_count(1)) >= 5, 20,
                       "samples", proc=d.proc)

            up = json.loads(run_impctl("status", "--json", "--config", str(config)).stdout)
            assert up["mqtt"]["connected"] is True, up["mqtt"]
            b.stop()  # the broker goes away mid-night
            before = store_query(db, lambda s: s.sample_count(1))
            wall = time.monotonic()
            time.sleep(2.0)
            during = store_query(db, lambda s: s.sample_count(1)) - before
            down = run_impctl("status", "--config", str(config)).stdout
            line = next(ln for ln in down.splitlines() if ln.startswith("mqtt:"))
            assert f"127.0.0.1:{b.port} UNAVAILABLE since" in line, down
            b.start()
            restarted = time.monotonic()
            # Retained messages died with the broker: impctl announces itself again.
            wait_until(lambda: any(m.at > restarted for m in ha.under("homeassistant/")), 20,
                       "discovery after the restart", proc=d.proc)
            wait_until(lambda: any(s["night_state"] == "active"
                                   for s in _states(ha, restarted)), 20,
                       "values after the restart", proc=d.proc)
            assert ha.latest(f"{BASE}/availability").payload == b"online"
            again = json.loads(run_impctl("status", "--json", "--config", str(config)).stdout)
            assert again["mqtt"]["connected"] is True and again["mqtt"]["since"] > \
                up["mqtt"]["since"], again["mqtt"]
            wait_until(lambda: store_query(db, lambda s: s.night(1).valid) is not None, 30,
                       "the night to finish", proc=d.proc)
            night = store_query(db, lambda s: s.night(1))
            assert (night.state, night.valid, night.kind, night.setpoint_c) == (
                "done", True, "normal", 22.0), night.reasons
            assert owner_state(sim.port) == OWNER
            # Sampling went on while the broker was down: 2 s = 2 simulated hours at one
            # sample per 300 s is 24 samples; a loaded machine may delay some.
            assert during >= 8, (during, time.monotonic() - wall)
            ts = [s.ts for s in store_query(db, lambda st: st.samples(1))]
            assert all((b_ - a).total_seconds() > 0 for a, b_ in zip(ts, ts[1:], strict=False))
        finally:
            assert stop_process(d.proc) == 0
        log = d.output()
        assert log.count("MQTT broker") == 2, log  # one line when it went, one when back
        assert "unavailable" in log and "back after" in log


def test_refused_credentials_and_skip_tonight(tmp_path):
    """Wrong password: one log line however many retries, and nights are unaffected; then
    the right password and a skip_tonight from Home Assistant keep the scheduled night off."""
    pw = tmp_path / "mqtt.password"
    pw.write_text("wrong\n")
    users = {"impctl": "right", "ha": "ha-secret"}
    epoch = datetime(2026, 1, 12, 3, 0, tzinfo=TZ)
    with broker(tmp_path / "broker", users) as b, \
            rig(tmp_path, epoch, mqtt_section(b, username="impctl", password_file=str(pw),
                                              commands=True)) as (sim, config, db):
        d = _ready(config, db, tmp_path / "daemon.log")
        try:
            queued = run_cli("trigger", "--kind", "normal", "--setpoint", "22", "--now",
                             "--force", "--config", str(config))
            assert queued.returncode == 0, queued.stderr
            # The night runs while impctl keeps being refused (a whole valid night with a
            # broker that never answers: test_silent_broker_blocks_neither_nights_nor_shutdown).
            wait_until(lambda: b.log.read_text().count("not authorised") >= 3, 30,
                       "three refused connections", proc=d.proc)
            wait_until(lambda: store_query(db, lambda s: s.sample_count(1)) >= 10, 20,
                       "samples", proc=d.proc)
            assert owner_state(sim.port)[0] == 220
        finally:
            assert stop_process(d.proc) == 0
        assert owner_state(sim.port) == OWNER  # stopped mid-night: restored before exit
        log = d.output()
        refusals = b.log.read_text().count("not authorised")
        assert refusals >= 3, b.log.read_text()  # it kept retrying…
        lines = [ln for ln in log.splitlines() if "MQTT broker" in ln]
        assert len(lines) == 1 and "unavailable" in lines[0], lines  # …and said so once

        # The right password; 17:00, the scheduled night would act at 21:30.
        pw.write_text("right\n")
        evening = datetime(2026, 1, 12, 17, 0, tzinfo=TZ)
        (tmp_path / "evening").mkdir()
    with broker(tmp_path / "broker2", users) as b, \
            home_assistant(b.port, username="ha", password="ha-secret") as ha, \
            rig(tmp_path / "evening", evening,
                mqtt_section(b, username="impctl", password_file=str(pw), commands=True),
                campaign=ONE_CONSTRAINED) as (sim, config, db):
        # A stored fit (the fit JSON's lumped block, with the flexibility block).
        with Store(db) as store:
            fit_id = store.add_fit([1, 2, 3], {"lumped": {
                "hlc": {"value": 182.4, "low": 170.1, "high": 195.0, "determined": True},
                "c_m": {"value": 3.1e7, "low": 2.5e7, "high": 3.9e7, "determined": False},
                "tau": {"value": 49.3, "low": 44.0, "high": 55.2, "determined": True}},
                "flexibility": {"coast_h": 5.5, "coast_h_low": 4.8, "coast_h_high": 6.1,
                                "rebound_kwh": 7.2}})
        # A retained command left on the broker must not act at every (re)connect.
        ha.client.publish(f"{BASE}/cmd/abort", "abort", qos=1, retain=True).wait_for_publish(5)
        d = _ready(config, db, tmp_path / "daemon2.log")
        try:
            wait_until(lambda: ha.latest(f"{BASE}/availability"), 20, "online", proc=d.proc)
            wait_until(lambda: "retained messages are not commands" in d.output(), 10,
                       "the retained command to be refused", proc=d.proc)
            wait_until(lambda: ha.latest(f"{BASE}/fit/coast_h"), 10, "the fit", proc=d.proc)
            # Outside a night the values come from an idle read of the heat pump.
            wait_until(lambda: any(s["night_state"] == "idle" and s["link_ok"]
                                   and s["t_air_c"] is not None and s["t_out_c"] == 0.0
                                   for s in _states(ha)), 10, "idle values", proc=d.proc)
            hlc = ha.latest(f"{BASE}/fit/hlc").json()
            assert (hlc["value"], hlc["low"], hlc["high"], hlc["nights"]) == (
                182.4, 170.1, 195.0, [1, 2, 3])
            c_m = ha.latest(f"{BASE}/fit/c_m").json()  # MJ/K; not determined: no value
            assert (c_m["value"], c_m["low"], c_m["high"]) == (None, 25.0, 39.0)
            coast = ha.latest(f"{BASE}/fit/coast_h")
            assert coast.json()["value"] == 5.5
            conf = _configs(ha)["homeassistant/sensor/gw1/coast_h/config"]
            assert render(conf["availability"][1]["value_template"], coast.payload) == "online"
            ha.press(f"{BASE}/cmd/skip_tonight", "skip_tonight")
            wait_until(lambda: any(s["skip_tonight"] for s in _states(ha)), 10,
                       "the skip to show", proc=d.proc)
            # The night job (21:30) decides: after it, no night starts before tomorrow.
            wait_until(lambda: "night skipped on request" in d.output(), 20, "the night job",
                       proc=d.proc)
            assert store_query(db, lambda s: s.nights()) == []
            assert owner_state(sim.port) == OWNER
            assert d.output().count("retained messages are not commands") == 1
            assert "abort requested" not in d.output()
            # The morning's season refit rewrites the fit in place (same id, same nights):
            # Home Assistant gets its numbers at the next look, not at the next restart.
            with Store(db) as store:
                assert store.refresh_fit_season(fit_id, {
                    "hlc_w_per_k": {"value": 190.0, "low": 180.0, "high": 200.0},
                    "owner_nights": 11})
            wait_until(lambda: ha.latest(f"{BASE}/fit/hlc").json()["value"] == 190.0, 90,
                       "the season refit's HLC", proc=d.proc)
            hlc = ha.latest(f"{BASE}/fit/hlc").json()
            assert (hlc["source"], hlc["owner_nights"]) == ("season model", 11)
        finally:
            assert stop_process(d.proc) == 0
        # A clean stop says offline itself (no last will is sent then).
        assert ha.latest(f"{BASE}/availability").payload == b"offline"


def test_daytime_now_from_home_assistant_is_refused(tmp_path):
    """The CLI runs a daytime ``--now`` night only with ``--force``; a dashboard button has
    no --force, so at noon a ``now`` trigger is refused with one line and nothing is queued,
    while ``tonight`` is queued as usual."""
    noon = datetime(2026, 1, 12, 12, 0, tzinfo=TZ)
    with broker(tmp_path / "broker") as b, home_assistant(b.port) as ha, \
            rig(tmp_path, noon, mqtt_section(b, commands=True), speed=60.0) as (
                sim, config, db):
        d = _ready(config, db, tmp_path / "daemon.log")
        try:
            wait_until(lambda: ha.latest(f"{BASE}/availability"), 20, "online", proc=d.proc)
            ha.press(f"{BASE}/cmd/trigger", json.dumps({"kind": "normal", "when": "now"}))
            wait_until(lambda: "refused" in d.output(), 10, "the refusal", proc=d.proc)
            ha.press(f"{BASE}/cmd/trigger", "tonight")
            wait_until(lambda: "queued request" in d.output(), 10, "the request", proc=d.proc)
            requests = store_query(db, lambda s: s.pending_requests())
            assert [r.when for r in requests] == ["tonight"], requests
            assert owner_state(sim.port) == OWNER
        finally:
            assert stop_process(d.proc) == 0
        refusals = [ln for ln in d.output().splitlines() if "refused" in ln]
        assert len(refusals) == 1 and "outside the night window" in refusals[0] \
            and "daytime" in refusals[0], refusals


def test_silent_broker_blocks_neither_nights_nor_shutdown(tmp_path):
    """A "broker" that accepts the TCP connection and never answers (a hung broker, a
    half-open NAT): the night runs and is valid, the outage is one log line, SIGTERM still
    stops the daemon promptly."""
    import socket

    hole = socket.socket()
    hole.bind(("127.0.0.1", 0))
    hole.listen(8)  # the kernel completes the handshakes; nothing ever reads or answers
    try:
        epoch = datetime(2026, 1, 12, 3, 0, tzinfo=TZ)
        mqtt = {"host": "127.0.0.1", "port": hole.getsockname()[1], "client_id": "gw1",
                "reconnect_max_s": 1.0, "commands": True}
        with rig(tmp_path, epoch, mqtt) as (sim, config, db):
            d = _ready(config, db, tmp_path / "daemon.log")
            try:
                queued = run_cli("trigger", "--kind", "normal", "--setpoint", "22", "--now",
                                 "--force", "--config", str(config))
                assert queued.returncode == 0, queued.stderr
                wait_until(lambda: store_query(db, lambda s: s.night(1) and s.night(1).valid)
                           is not None, 40, "the night", proc=d.proc)
                night = store_query(db, lambda s: s.night(1))
                assert (night.state, night.valid) == ("done", True), night.reasons
                assert owner_state(sim.port) == OWNER
                wait_until(lambda: "unavailable" in d.output(), 30, "the outage line",
                           proc=d.proc)
                t0 = time.monotonic()
                d.proc.send_signal(signal.SIGTERM)
                assert d.proc.wait(20) == 0
                assert time.monotonic() - t0 < 10.0
            finally:
                stop_process(d.proc)
        lines = [ln for ln in d.output().splitlines() if "MQTT broker" in ln]
        assert len(lines) == 1 and "unavailable" in lines[0], lines
    finally:
        hole.close()
