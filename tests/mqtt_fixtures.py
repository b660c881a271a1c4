"""A real MQTT broker (Debian's mosquitto) for the tests, and a client that listens the way
Home Assistant does.

:class:`Broker` runs ``mosquitto -c FILE`` on a free loopback port, anonymous or with a
password file made by ``mosquitto_passwd``; it can be stopped and started again on the same
port (an outage). :class:`HomeAssistant` is a paho-mqtt client that subscribes to the
discovery prefix and the impctl topics, keeps every message (and the retained ones by topic)
and can press buttons. Nothing is mocked.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import shutil
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import paho.mqtt.client as paho
from daemon_fixtures import free_port, wait_until

MOSQUITTO = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
MOSQUITTO_PASSWD = shutil.which("mosquitto_passwd") or "/usr/bin/mosquitto_passwd"


class Broker:
    """A mosquitto process on 127.0.0.1:``port``; ``users`` = {name: password} or None
    (anonymous); ``extra``: more lines of mosquitto.conf."""

    def __init__(self, work: Path, users: dict[str, str] | None = None,
                 extra: tuple[str, ...] = ()):
        self.work, self.users = work, users
        self.port = free_port()
        self.log = work / "mosquitto.log"
        self.conf = work / "mosquitto.conf"
        lines = [f"listener {self.port} 127.0.0.1", "persistence false",
                 f"log_dest file {self.log}", "log_type error", "log_type warning",
                 "log_type notice",
                 # Started as root (CI), mosquitto would switch to the user "mosquitto", which
                 # cannot read the test's files; stay the user who started it.
                 "user root"]
        if users:
            pw = work / "mosquitto.passwd"
            for i, (name, password) in enumerate(users.items()):
                subprocess.run([MOSQUITTO_PASSWD, "-b", *(["-c"] if i == 0 else []), str(pw),
                                name, password], check=True, capture_output=True)
            lines += ["allow_anonymous false", f"password_file {pw}"]
        else:
            lines += ["allow_anonymous true"]
        lines += list(extra)
        self.conf.write_text("\n".join(lines) + "\n")
        self.proc: subprocess.Popen | None = None

    def start(self) -> None:
        self.proc = subprocess.Popen([MOSQUITTO, "-c", str(self.conf)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

        def listening() -> bool:
            with socket.socket() as s:
                return s.connect_ex(("127.0.0.1", self.port)) == 0
        wait_until(listening, 10, f"mosquitto on port {self.port}", proc=self.proc)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc = None


@contextlib.contextmanager
def broker(work: Path, users: dict[str, str] | None = None,
           extra: tuple[str, ...] = ()) -> Iterator[Broker]:
    """A started :class:`Broker`, stopped at the end."""
    work.mkdir(parents=True, exist_ok=True)
    b = Broker(work, users, extra)
    b.start()
    try:
        yield b
    finally:
        b.stop()


@dataclass
class Received:
    topic: str
    payload: bytes
    retain: bool
    at: float = field(default_factory=time.monotonic)

    def json(self):
        return json.loads(self.payload)


_CLIENT_IDS = itertools.count(1)


class HomeAssistant:
    """A subscriber like Home Assistant's MQTT integration (paho-mqtt, its own thread)."""

    def __init__(self, port: int, *, username: str | None = None, password: str | None = None,
                 topics: tuple[str, ...] = ("homeassistant/#", "impctl/#")):
        self.messages: list[Received] = []
        self._lock = threading.Lock()
        # Its own client id: a second client with the same id (``retained()``) would make
        # the broker drop this one (session takeover), and a press could find it offline.
        self.client = paho.Client(paho.CallbackAPIVersion.VERSION2,
                                  client_id=f"test-ha-{next(_CLIENT_IDS)}")
        if username:
            self.client.username_pw_set(username, password)
        self.client.reconnect_delay_set(0.1, 0.5)

        def on_connect(client, userdata, flags, rc, props=None):
            for t in topics:
                client.subscribe(t, qos=1)

        def on_message(client, userdata, msg):
            r = Received(msg.topic, bytes(msg.payload), bool(msg.retain))
            with self._lock:
                self.messages.append(r)
                self.last[msg.topic] = r
        self.last: dict[str, Received] = {}
        self.client.on_connect = on_connect
        self.client.on_message = on_message
        self.client.connect("127.0.0.1", port, keepalive=5)
        self.client.loop_start()

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()

    def on(self, topic: str) -> list[Received]:
        with self._lock:
            return [m for m in self.messages if m.topic == topic]

    def under(self, prefix: str) -> list[Received]:
        with self._lock:
            return [m for m in self.messages if m.topic.startswith(prefix)]

    def latest(self, topic: str) -> Received | None:
        with self._lock:
            return self.last.get(topic)

    def press(self, topic: str, payload: str) -> None:
        # Connected first (the connect runs in paho's thread): on a loaded machine the
        # CONNACK may come after the test's first press.
        wait_until(self.client.is_connected, 30, "Home Assistant's MQTT connection")
        self.client.publish(topic, payload, qos=1).wait_for_publish(30)


@contextlib.contextmanager
def home_assistant(port: int, **kw) -> Iterator[HomeAssistant]:
    ha = HomeAssistant(port, **kw)
    try:
        yield ha
    finally:
        ha.close()


@dataclass
class Pki:
    """A CA, a server certificate for 127.0.0.1 and a client certificate it signed (PEM
    files made with the ``openssl`` command line), and a second key that is not the
    client's."""

    ca: Path
    server_cert: Path
    server_key: Path
    client_cert: Path
    client_key: Path
    other_key: Path


def make_pki(work: Path) -> Pki:
    """Generate :class:`Pki` in ``work`` (the keys mode 0600)."""
    work.mkdir(parents=True, exist_ok=True)

    def openssl(*args: str) -> None:
        subprocess.run(["openssl", *args], check=True, capture_output=True, cwd=work)

    openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out",
            "ca.crt", "-days", "2", "-subj", "/CN=impctl test CA")
    (work / "san.ext").write_text("subjectAltName=IP:127.0.0.1,DNS:localhost\n")
    for name, subject, ext in (("server", "/CN=127.0.0.1", ["-extfile", "san.ext"]),
                               ("client", "/CN=impctl-gw1", [])):
        openssl("req", "-newkey", "rsa:2048", "-nodes", "-keyout", f"{name}.key", "-out",
                f"{name}.csr", "-subj", subject)
        openssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.crt", "-CAkey", "ca.key",
                "-CAcreateserial", "-out", f"{name}.crt", "-days", "2", *ext)
    openssl("genpkey", "-algorithm", "RSA", "-pkeyopt", "rsa_keygen_bits:2048", "-out",
            "other.key")
    for key in work.glob("*.key"):
        key.chmod(0o600)
    return Pki(work / "ca.crt", work / "server.crt", work / "server.key", work / "client.crt",
               work / "client.key", work / "other.key")


def tls_listener(port: int, pki: Pki, require_certificate: bool = True) -> tuple[str, ...]:
    """mosquitto.conf lines of a second listener on ``port``: MQTT over TLS with ``pki``'s
    server certificate, asking for a client certificate signed by its CA."""
    return (f"listener {port} 127.0.0.1", f"cafile {pki.ca}", f"certfile {pki.server_cert}",
            f"keyfile {pki.server_key}",
            f"require_certificate {'true' if require_certificate else 'false'}")


def mqtt_section(b: Broker, **extra) -> dict:
    """``[mqtt]`` for the daemon config, pointing at ``b``; test-sized back-off."""
    return {"host": "127.0.0.1", "port": b.port, "client_id": "gw1", "keepalive_s": 5,
            "reconnect_max_s": 1.0, "idle_interval_s": 10.0, **extra}


# -- Home Assistant's MQTT discovery schema (home-assistant.io, "MQTT" integration pages) ------
#: Required keys per entity platform.
REQUIRED = {"sensor": {"state_topic"}, "binary_sensor": {"state_topic"},
            "button": {"command_topic"}, "select": {"command_topic", "options"},
            "number": {"command_topic"}}
_COMMON = {"availability", "availability_mode", "availability_topic", "payload_available",
           "payload_not_available", "availability_template", "device", "origin", "unique_id",
           "name", "icon", "entity_category", "has_entity_name", "qos", "enabled_by_default",
           "json_attributes_topic", "json_attributes_template", "default_entity_id",
           "object_id", "encoding", "entity_picture"}
#: Documented optional keys per platform (beyond the common ones).
OPTIONAL = {
    "sensor": {"state_topic", "value_template", "device_class", "unit_of_measurement",
               "state_class", "suggested_display_precision", "expire_after", "force_update",
               "options", "last_reset_value_template"},
    "binary_sensor": {"state_topic", "value_template", "device_class", "payload_on",
                      "payload_off", "expire_after", "force_update", "off_delay"},
    "button": {"command_topic", "command_template", "payload_press", "device_class",
               "retain"},
    "select": {"command_topic", "command_template", "options", "state_topic",
               "value_template", "retain", "optimistic"},
    "number": {"command_topic", "command_template", "state_topic", "value_template", "min",
               "max", "step", "mode", "unit_of_measurement", "device_class", "retain",
               "optimistic", "payload_reset"},
}
DEVICE_KEYS = {"identifiers", "connections", "name", "manufacturer", "model", "model_id",
               "sw_version", "hw_version", "serial_number", "suggested_area", "via_device",
               "configuration_url"}
#: Units Home Assistant accepts for the device classes used.
UNITS = {"temperature": {"°C", "°F", "K"}, "power": {"W", "kW"},
         "duration": {"d", "h", "min", "s", "ms"}}
ENTITY_CATEGORIES = {"config", "diagnostic"}
STATE_CLASSES = {"measurement", "total", "total_increasing"}


def check_discovery(configs: dict[str, dict], prefix: str = "homeassistant") -> list[str]:
    """Problems of discovery config messages (topic → payload) against the schema."""
    import re

    problems: list[str] = []
    ids: dict[str, str] = {}
    devices = set()
    for topic, conf in configs.items():
        m = re.fullmatch(rf"{prefix}/(\w+)/([A-Za-z0-9_-]+)/([A-Za-z0-9_-]+)/config", topic)
        if not m:
            problems.append(f"{topic}: not <prefix>/<component>/<node_id>/<object_id>/config")
            continue
        comp = m.group(1)
        if comp not in REQUIRED:
            problems.append(f"{topic}: unexpected component {comp}")
            continue
        for key in REQUIRED[comp] - set(conf):
            problems.append(f"{topic}: required key {key} missing")
        for key in set(conf) - _COMMON - OPTIONAL[comp]:
            problems.append(f"{topic}: key {key} not in the {comp} schema")
        uid = conf.get("unique_id")
        if not uid:
            problems.append(f"{topic}: no unique_id")
        elif uid in ids:
            problems.append(f"{topic}: unique_id {uid} also used by {ids[uid]}")
        else:
            ids[uid] = topic
        dev = conf.get("device") or {}
        if not dev.get("identifiers") and not dev.get("connections"):
            problems.append(f"{topic}: device block without identifiers")
        for key in set(dev) - DEVICE_KEYS:
            problems.append(f"{topic}: device key {key} not in the schema")
        devices.add(json.dumps(dev, sort_keys=True))
        if "availability_topic" not in conf and not all(
                "topic" in a for a in conf.get("availability") or [{}]):
            problems.append(f"{topic}: no availability")
        dc = conf.get("device_class")
        if dc in UNITS and conf.get("unit_of_measurement") not in UNITS[dc]:
            problems.append(f"{topic}: unit {conf.get('unit_of_measurement')} not valid for {dc}")
        if "state_class" in conf and conf["state_class"] not in STATE_CLASSES:
            problems.append(f"{topic}: state_class {conf['state_class']}")
        if conf.get("entity_category", "config") not in ENTITY_CATEGORIES:
            problems.append(f"{topic}: entity_category {conf['entity_category']}")
        for key in ("state_topic", "command_topic", "json_attributes_topic",
                    "availability_topic"):
            if key in conf and ("#" in conf[key] or "+" in conf[key]):
                problems.append(f"{topic}: {key} has a wildcard")
        if comp == "select" and not (isinstance(conf.get("options"), list) and conf["options"]):
            problems.append(f"{topic}: options must be a non-empty list")
    if len(devices) != 1:
        problems.append(f"expected one device block, got {len(devices)}")
    return problems


def render(template: str, payload: bytes) -> str:
    """A value template rendered the way Home Assistant does (``value``, ``value_json``)."""
    import jinja2

    env = jinja2.Environment()
    try:
        value_json = json.loads(payload)
    except ValueError:
        value_json = None
    return env.from_string(template).render(value=payload.decode(), value_json=value_json)


def retained(port: int, topic: str = "#", settle_s: float = 1.0, **kw) -> dict[str, Received]:
    """What a client subscribing now gets from the broker's retained store (topic → message;
    live messages arriving meanwhile are left out)."""
    with home_assistant(port, topics=(topic,), **kw) as late:
        time.sleep(settle_s)
        return {m.topic: m for m in late.messages if m.retain}
