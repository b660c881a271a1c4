"""Home Assistant commands in careless hands: the real ``impctl daemon`` subprocess, an
``impctl-sim`` subprocess at noon (60×: the scheduled night is minutes of wall time away), a
real mosquitto, and clients that press buttons as Home Assistant and people do.

* an empty payload (an empty button, or clearing a retained command the standard way,
  ``mosquitto_pub -r -n``) is never a command: one log line, nothing queued;
* a hundred presses of "run tonight" are one waiting request; status shows one;
* a waiting skip shows in ``impctl status`` (text and JSON) and ``trigger --cancel`` takes
  it back;
* ``commands = true`` → ``false``: the command entities are withdrawn from Home Assistant and
  a command sent anyway is logged as dropped, with why;
* another client with impctl's client id: the clash is named, not logged as an outage;
* 5,000 commands in a burst, refused (malformed, or commands off): a handful of log lines, the
  rest counted, the count exact; nothing queued, nothing written;
* a setpoint typed with other digits than ASCII ('２２') is refused, not read as 22.
"""

from __future__ import annotations

import contextlib
import json
import re
from datetime import datetime
from pathlib import Path
from types import SimpleNamespace
from zoneinfo import ZoneInfo

import paho.mqtt.client as paho
import pytest
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
from mqtt_fixtures import broker, home_assistant, mqtt_section, retained

from impctl.mqtt.config import MqttConfig

TZ = ZoneInfo("Europe/Ljubljana")
NOON = datetime(2026, 1, 12, 12, 0, tzinfo=TZ)
BASE = "impctl/gw1"
OWNER = (OWNER_SETPOINT_RAW, OWNER_MODE)
#: The config topics of the buttons, select and number that ``commands = true`` announces.
COMMAND_CONFIGS = [f"homeassistant/{c}/gw1/{k}/config" for c, k in (
    ("button", "abort"), ("button", "skip_tonight"), ("button", "trigger"),
    ("select", "night_kind_setting"), ("number", "night_setpoint_setting"))]


@contextlib.contextmanager
def _rig(work: Path, speed: float = 60.0, broker_conf: tuple[str, ...] = (), **mqtt):
    """A broker, Home Assistant, the simulator and a running daemon (``[mqtt]`` + ``mqtt``)
    on a clock ``speed`` times real time."""
    with broker(work / "broker", extra=broker_conf) as b, home_assistant(b.port) as ha, \
            sim_process(work, NOON, speed, plant="iso") as sim:
        config = write_config(work / "config.toml", daemon_mapping(
            work / "state", sim.port, sim.clock, campaign={"enabled": False},
            night={"window": "22:00-05:00", "preheat_h": 0.5},
            mqtt=mqtt_section(b, **mqtt)))
        rig = SimpleNamespace(b=b, ha=ha, sim=sim, config=config, work=work,
                              db=work / "state" / "impctl.db", d=None)
        rig.d = _start(rig)
        try:
            yield rig
        finally:
            stop_process(rig.d.proc)


def _start(rig, log: str = "daemon.log"):
    d = start_daemon(rig.config, rig.db, rig.work / log)
    wait_until(lambda: "next night job at" in d.output(), 30, "the daemon", proc=d.proc)
    wait_until(lambda: (m := rig.ha.latest(f"{BASE}/availability")) and m.payload == b"online"
               and "MQTT connected" in d.output(), 20, "the daemon online", proc=d.proc)
    return d


def _lines(d, text: str) -> list[str]:
    return [ln for ln in d.output().splitlines() if text in ln]


def _status(config) -> tuple[dict, str]:
    as_json = run_impctl("status", "--json", "--config", str(config))
    as_text = run_impctl("status", "--config", str(config))
    assert as_json.returncode == 0 and as_text.returncode == 0, as_json.stderr + as_text.stderr
    return json.loads(as_json.stdout), as_text.stdout


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """One daemon with commands on, shared by the tests of this module that press buttons."""
    with _rig(tmp_path_factory.mktemp("careless"), commands=True) as r:
        yield r


def test_an_empty_payload_is_never_a_command(rig):
    ha, d = rig.ha, rig.d
    for name in ("abort", "skip_tonight", "trigger"):
        ha.press(f"{BASE}/cmd/{name}", "")
    # Clearing a retained command as mosquitto_pub -r -n does: an empty retained message,
    # which the broker hands to the daemon (subscribed already) as a live one.
    ha.client.publish(f"{BASE}/cmd/skip_tonight", None, qos=1,
                      retain=True).wait_for_publish(10)
    wait_until(lambda: len(_lines(d, "empty payload")) == 4, 20, "four log lines",
               proc=d.proc)
    lines = _lines(d, "MQTT command")
    assert len(lines) == 4, lines  # one line each, all of them refusals
    assert all("ignored: empty payload: not a command" in ln for ln in lines), lines
    assert store_query(rig.db, lambda s: (s.pending_requests(), s.pending_commands())) == (
        [], [])
    assert store_query(rig.db, lambda s: s.nights()) == []
    assert owner_state(rig.sim.port) == OWNER


def test_a_setpoint_in_other_digits_is_refused_not_read(rig):
    ha, d = rig.ha, rig.d
    ha.press(f"{BASE}/cmd/night_setpoint", "２２")  # float() reads it as 22
    wait_until(lambda: _lines(d, "FULLWIDTH DIGIT TWO"), 20, "the refusal", proc=d.proc)
    [line] = _lines(d, f"{BASE}/cmd/night_setpoint")
    assert "ignored: '２２' holds '２' (FULLWIDTH DIGIT TWO): write numbers with the ASCII " \
           "digits 0-9" in line, line
    ha.press(f"{BASE}/cmd/night_setpoint", "21")  # the same path takes ASCII digits
    wait_until(lambda: len(ha.on(f"{BASE}/settings")) == 2, 20, "the setting", proc=d.proc)
    assert [json.loads(m.payload)["setpoint_c"] for m in ha.on(f"{BASE}/settings")] == [
        21.0, 21.0]  # announced, then the ASCII press; never 22


def test_a_hundred_presses_are_one_waiting_request(rig):
    ha, d = rig.ha, rig.d
    before = len(_lines(d, "MQTT command trigger:"))
    for _ in range(100):
        ha.client.publish(f"{BASE}/cmd/trigger", "tonight", qos=1)
    wait_until(lambda: len(_lines(d, "MQTT command trigger:")) - before == 100, 30,
               "a hundred presses handled", proc=d.proc)
    [req] = store_query(rig.db, lambda s: s.pending_requests())
    assert (req.kind, req.when) == ("constrained", "tonight")
    assert len(_lines(d, "already waiting")) == 99
    # The same request from the CLI joins it too.
    again = run_cli("trigger", "--kind", "constrained", "--tonight", "--config",
                    str(rig.config))
    assert again.returncode == 0, again.stderr
    assert f"request {req.id} already waiting" in again.stdout
    st, text = _status(rig.config)
    assert st["pending_requests"] == 1 and st["next_night"]["request"] == req.id
    assert "requests:  1 waiting" in text
    cancel = run_cli("trigger", "--cancel", "--config", str(rig.config))
    assert cancel.stdout.strip() == f"cancelled request {req.id}: constrained night (tonight)"


def test_a_waiting_skip_is_shown_and_cancellable(rig):
    ha, d = rig.ha, rig.d
    before = len(_lines(d, "MQTT command skip_tonight:"))
    ha.press(f"{BASE}/cmd/skip_tonight", "skip_tonight")
    wait_until(lambda: len(_lines(d, "MQTT command skip_tonight:")) == before + 1, 20,
               "the press", proc=d.proc)
    [skip] = store_query(rig.db, lambda s: s.pending_commands("skip_tonight"))
    st, text = _status(rig.config)
    assert [(s["id"], s["source"]) for s in st["skip_tonight"]] == [(skip.id, "mqtt")]
    assert st["next_night"]["skipped_by"] == skip.id
    assert (f"skip:      the next night is skipped on request (skip {skip.id} from mqtt"
            in text), text
    ha.press(f"{BASE}/cmd/skip_tonight", "PRESS")  # pressed again: still one skip
    wait_until(lambda: len(_lines(d, "MQTT command skip_tonight:")) == before + 2, 20,
               "the second press", proc=d.proc)
    assert [c.id for c in store_query(rig.db, lambda s: s.pending_commands())] == [skip.id]
    cancel = run_cli("trigger", "--cancel", "--config", str(rig.config))
    assert cancel.returncode == 0, cancel.stderr
    assert f"cancelled skip {skip.id} (mqtt): the next night runs as planned" in cancel.stdout
    assert store_query(rig.db, lambda s: s.pending_commands()) == []
    st, text = _status(rig.config)
    assert st["skip_tonight"] == [] and st["next_night"]["skipped_by"] is None
    assert "skip:" not in text and "skipped on request" not in text
    nothing = run_cli("trigger", "--cancel", "--config", str(rig.config))
    assert "nothing to cancel" in nothing.stdout


def test_commands_switched_off_withdraw_the_buttons_and_say_why(tmp_path):
    with _rig(tmp_path, commands=True) as r:
        wait_until(lambda: all(r.ha.latest(t) for t in COMMAND_CONFIGS), 20,
                   "the buttons", proc=r.d.proc)
        assert stop_process(r.d.proc) == 0
        t_off = len(r.ha.messages)
        r.config.write_text(r.config.read_text().replace("commands = true",
                                                         "commands = false"))
        r.d = _start(r, "daemon-off.log")
        withdrawn = [*COMMAND_CONFIGS, f"{BASE}/settings"]
        wait_until(lambda: all((m := r.ha.latest(t)) and m.payload == b""
                               for t in withdrawn), 20, "the buttons withdrawn",
                   proc=r.d.proc)
        assert all(m.payload == b"" for m in r.ha.messages[t_off:] if m.topic in withdrawn)
        # Home Assistant (re)starting now finds no button config on the broker.
        kept = retained(r.b.port)
        assert not set(withdrawn) & set(kept), sorted(kept)
        assert "homeassistant/sensor/gw1/t_air/config" in kept
        # A command sent anyway: dropped, and the log says why.
        r.ha.press(f"{BASE}/cmd/trigger", "tonight")
        r.ha.press(f"{BASE}/cmd/skip_tonight", "skip_tonight")
        wait_until(lambda: len(_lines(r.d, "commands are off")) == 2, 20, "two log lines",
                   proc=r.d.proc)
        [line] = _lines(r.d, f"{BASE}/cmd/trigger")
        assert "ignored: commands are off (mqtt.commands = false" in line
        assert store_query(r.db, lambda s: (s.pending_requests(), s.pending_commands())) == (
            [], [])


_FULL = re.compile(r"MQTT command (\S+) ignored: (.*)$")
_COUNTED = re.compile(r"MQTT: ([\d,]+) more commands? on (\S+) ignored within 60 s of the "
                      r"first: (.*)$")


@pytest.mark.parametrize(("commands", "payload", "why"), [
    (True, '{"kind": "normal", "setpoint_c": 40}', "outside the safety limits"),
    (False, "tonight", "commands are off (mqtt.commands = false in the configuration)"),
])
def test_a_flood_of_commands_is_counted_not_logged_line_by_line(tmp_path, commands, payload,
                                                                why):
    """1,500 refused commands in a burst: the first few of a minute (the daemon's) are logged
    in full, the rest counted in one line per minute; the lines account for every message."""
    n = 1500
    # speed 6: a minute of the daemon's clock is 10 s; the broker queues the whole burst for
    # the daemon (mosquitto drops above 1,000 queued messages by default)
    with _rig(tmp_path, speed=6.0, broker_conf=("max_queued_messages 0",),
              commands=commands) as r:
        topic = f"{BASE}/cmd/trigger"
        for _ in range(n - 1):
            r.ha.client.publish(topic, payload, qos=1)
        r.ha.client.publish(topic, payload, qos=1).wait_for_publish(60)

        def accounted() -> tuple[int, list[str]]:
            lines = [ln for ln in r.d.output().splitlines()
                     if _FULL.search(ln) or _COUNTED.search(ln)]
            total = sum(1 if _FULL.search(ln) else int(_COUNTED.search(ln)[1].replace(",", ""))
                        for ln in lines)
            return total, lines

        wait_until(lambda: accounted()[0] >= n, 90, "every command accounted for",
                   proc=r.d.proc)
        total, lines = accounted()
        assert total == n, lines
        assert len(lines) <= 60, lines  # 6 per window of 10 s wall: a burst is not 5,000
        full = [_FULL.search(ln) for ln in lines if _FULL.search(ln)]
        counted = [_COUNTED.search(ln) for ln in lines if _COUNTED.search(ln)]
        assert full and counted and all("WARNING" in ln for ln in lines)
        assert {m[1] for m in full} == {m[2] for m in counted} == {topic}
        assert all(why in m[2] for m in full) and all(why in m[3] for m in counted)
        assert int(counted[0][1].replace(",", "")) >= 1
        assert store_query(r.db, lambda s: (s.pending_requests(), s.pending_commands(),
                                            s.nights())) == ([], [], [])
        assert owner_state(r.sim.port) == OWNER


def test_another_client_with_the_same_id_is_named_not_an_outage(tmp_path):
    with _rig(tmp_path) as r:
        # Another gateway (or a copied configuration) connects with impctl's client id; like
        # any MQTT client it reconnects when the broker drops it for the newer session.
        twin = paho.Client(paho.CallbackAPIVersion.VERSION2, client_id="gw1")
        twin.reconnect_delay_set(0.2, 0.5)
        twin.connect("127.0.0.1", r.b.port, keepalive=5)
        twin.loop_start()
        try:
            wait_until(lambda: _lines(r.d, "is in use by another client"), 40,
                       "the clash named", proc=r.d.proc)
        finally:
            twin.loop_stop()
            twin.disconnect()
        [line] = _lines(r.d, "is in use by another client")
        assert "client id 'gw1'" in line and "session taken over" in line, line
        assert "WARNING" in line
        assert not _lines(r.d, "unavailable"), r.d.output()


def test_command_entities_are_the_ones_withdrawn():
    from impctl.mqtt.homeassistant.discovery import (
        COMMAND_ENTITIES,
        Limits,
        entities,
        withdrawn_topics,
    )

    limits = Limits(16.0, 24.0, 1.5, 19.0)
    on = {(c, k) for c, k, _ in entities(MqttConfig(host="h", client_id="x", commands=True),
                                         limits)}
    off = {(c, k) for c, k, _ in entities(MqttConfig(host="h", client_id="x"), limits)}
    assert on - off == set(COMMAND_ENTITIES)
    assert [f"homeassistant/{c}/gw1/{k}/config" for c, k in COMMAND_ENTITIES] == COMMAND_CONFIGS
    assert withdrawn_topics(MqttConfig(host="h", client_id="x", commands=True)) == []


def test_an_mqtt5_session_taken_over_is_a_clash_at_once():
    import aiomqtt
    from paho.mqtt.packettypes import PacketTypes
    from paho.mqtt.reasoncodes import ReasonCode

    from impctl.mqtt.takeover import TakeoverWatch

    watch = TakeoverWatch("gw1")
    watch.started()
    taken = aiomqtt.MqttCodeError(ReasonCode(PacketTypes.DISCONNECT, identifier=0x8E))
    assert watch.ended(taken) == "new" and watch.clash
    lost = aiomqtt.MqttCodeError(7, "Unexpected disconnection")
    watch.started()
    assert watch.ended(lost) == "ongoing"
    # A connect that fails (no session began) is an outage, and ends the clash.
    assert watch.ended(aiomqtt.MqttError("[Errno 111] Connection refused")) is None
    assert not watch.clash


def test_a_session_lost_during_a_publish_is_as_long_as_it_lasted(monkeypatch):
    # The broker drops the session while a QoS 1 publish awaits its PUBACK: aiomqtt raises
    # "Operation timed out" only at the publish's own timeout, 10 s later. The session lasted
    # until the drop, so it is short, and the drop's reason is what is told.
    import asyncio

    import aiomqtt

    from impctl.mqtt import takeover
    from impctl.mqtt.bridge import _on_lost, _why_lost
    from impctl.mqtt.takeover import TakeoverWatch

    now = [1000.0]
    monkeypatch.setattr(takeover.time, "monotonic", lambda: now[0])
    watch = TakeoverWatch("gw1")

    async def session():
        client = aiomqtt.Client("127.0.0.1", 1, identifier="gw1")
        fut = asyncio.get_running_loop().create_future()
        client._disconnected = fut  # what aiomqtt resolves in paho's on_disconnect
        watch.started()
        _on_lost(client, watch.lost)
        now[0] += 0.5
        fut.set_exception(aiomqtt.MqttCodeError(7, "Unexpected disconnection"))
        await asyncio.sleep(0)  # the done-callback runs
        now[0] += 10.0          # the publish's timeout
        timed_out = aiomqtt.MqttError("Operation timed out")
        return _why_lost(client, timed_out)

    why = asyncio.run(session())
    assert isinstance(why, aiomqtt.MqttCodeError) and why.rc == 7, why
    assert watch.lived_s() == 0.5
    assert watch.ended(why) == "short"
