"""The ``[mqtt]`` section of the daemon configuration: parsing and validation.

Off unless the section is present. The password is never in the config: ``password_file``
names a file holding it (mode 0600, readable by the service). Durations in s.
"""

from __future__ import annotations

import math
import os
import re
import socket
import stat
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from ..errors import InputError

#: Name of the systemd credential that holds the password when password_file is empty.
CREDENTIAL = "mqtt.password"
_ID = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
# Topic levels: no MQTT wildcards, no empty level, no leading/trailing slash.
_TOPIC = re.compile(r"^[^#+/\s]+(/[^#+/\s]+)*$")


def default_client_id() -> str:
    """``impctl-<hostname>`` reduced to the characters allowed in ids and topics."""
    host = re.sub(r"[^A-Za-z0-9_-]", "-", socket.gethostname())[:50] or "gateway"
    return f"impctl-{host}"


@dataclass(frozen=True)
class MqttConfig:
    """Where and how impctl talks to an MQTT broker (Home Assistant's, usually).

    Attributes
    ----------
    host, port : the broker (port 1883, or 8883 with TLS by convention)
    tls : bool, connect with TLS; ``ca_file`` is the CA bundle (empty = the system's)
    cert_file, key_file : impctl's client certificate and its private key (PEM, the key
        without a passphrase), for a broker that requires client certificates; ``key_file``
        empty: the key is in ``cert_file``
    username, password_file : credentials; the password is read from the file at each
        connect (empty: the systemd credential ``mqtt.password``, if the unit loads one)
    client_id : MQTT client id, also the device id in Home Assistant
    base_topic : prefix of impctl's own topics (default ``impctl/<client_id>``)
    discovery_prefix : Home Assistant's discovery prefix
    commands : accept abort / skip_tonight / trigger commands from the broker
    idle_interval_s : how often values are read and published outside a night [s]
    keepalive_s : MQTT keep-alive [s]; a dead daemon shows unavailable after ~1.5× this
    reconnect_max_s : longest pause between reconnect attempts (doubling from 1 s) [s]
    """

    host: str = ""
    port: int = 1883
    tls: bool = False
    ca_file: str = ""
    cert_file: str = ""
    key_file: str = ""
    username: str = ""
    password_file: str = ""
    client_id: str = ""
    base_topic: str = ""
    discovery_prefix: str = "homeassistant"
    commands: bool = False
    idle_interval_s: float = 300.0
    keepalive_s: int = 60
    reconnect_max_s: float = 300.0

    @property
    def topic(self) -> str:
        """The base topic, ``impctl/<client_id>`` unless configured."""
        return self.base_topic or f"impctl/{self.client_id}"

    def password(self) -> str | None:
        """The password: first line of ``password_file``, else of the systemd credential
        ``mqtt.password`` (``LoadCredential=``, see README), else None."""
        path = self.password_file
        if not path:
            creds = os.environ.get("CREDENTIALS_DIRECTORY")
            if not creds or not (Path(creds) / CREDENTIAL).is_file():
                return None
            path = str(Path(creds) / CREDENTIAL)
        try:
            lines = Path(path).read_text(encoding="utf-8").splitlines()
        except UnicodeDecodeError as exc:
            raise InputError(f"not UTF-8 text (byte {exc.start + 1}): write the password as "
                             "plain text on the first line", path, "password file") from None
        return lines[0] if lines else ""

    def warnings(self) -> list[str]:
        """What a valid ``[mqtt]`` allows but should not, one line each: a password file or
        a client key other users can read, a password sent in clear text over the network."""
        from .tls import cleartext_warning, key_file_warning

        # A user name means a password: from password_file, or from the systemd credential
        # the unit loads (which check-config, run from a shell, cannot see).
        found = [self.password_file_warning(), key_file_warning(self.cert_file, self.key_file),
                 cleartext_warning(self.host, self.port, self.tls, self.username)]
        return [w for w in found if w]

    def password_file_warning(self) -> str | None:
        """Why the password file is too open (group- or world-readable), or None."""
        if not self.password_file:
            return None
        try:
            mode = Path(self.password_file).stat().st_mode
        except OSError:
            return None  # the reader names the problem
        if mode & (stat.S_IRGRP | stat.S_IROTH | stat.S_IWGRP | stat.S_IWOTH):
            return (f"{self.password_file}: the MQTT password file is readable by other users "
                    f"(mode {stat.S_IMODE(mode):04o}): chmod 600 {self.password_file}")
        return None


def _typed(value: Any, default: Any, where: str, problems: list[str]) -> Any:
    if isinstance(default, bool):
        ok = isinstance(value, bool)
        kind = "true or false"
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
        kind = "an integer"
    elif isinstance(default, float):
        ok = (isinstance(value, (int, float)) and not isinstance(value, bool)
              and math.isfinite(value))
        kind = "a finite number"
        value = float(value) if ok else value
    else:
        ok = isinstance(value, str)
        kind = "a string"
    if ok:
        return value
    problems.append(f"{where}: must be {kind}, got {value!r}")
    return default


def mqtt_from_mapping(data: dict, problems: list[str], prefix: str = "mqtt.") -> MqttConfig:
    """Build :class:`MqttConfig` from the ``[mqtt]`` table; appends one line per problem
    (``key 'mqtt.port': …``) to ``problems`` and returns what could be read."""
    known = {f.name: f.default for f in fields(MqttConfig)}
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        where = f"key '{prefix}{key}'"
        if key not in known:
            problems.append(f"{where}: unknown key")
            continue
        kwargs[key] = _typed(value, known[key], where, problems)
    cfg = MqttConfig(**kwargs)
    if not cfg.client_id:
        cfg = MqttConfig(**{**kwargs, "client_id": default_client_id()})

    def bad(key: str, text: str) -> None:
        problems.append(f"key '{prefix}{key}': {text}")

    if not cfg.host:
        bad("host", "required: the broker's host name or address")
    if not 1 <= cfg.port <= 65535:
        bad("port", "must lie in 1–65535")
    if not _ID.match(cfg.client_id):
        bad("client_id", "only letters, digits, '_' and '-' (1–64 characters): it is used "
                         f"in topics and Home Assistant ids, got {cfg.client_id!r}")
    for key in ("base_topic", "discovery_prefix"):
        text = getattr(cfg, key)
        if text and not _TOPIC.match(text):
            bad(key, f"must be a topic without wildcards (+ #), spaces or empty levels, "
                     f"got {text!r}")
    if not cfg.discovery_prefix:
        bad("discovery_prefix", "must not be empty")
    if cfg.password_file and not cfg.username:
        bad("password_file", "needs mqtt.username")
    # the password file, or the systemd credential the unit loads when there is none
    def unreadable(text: str) -> None:
        if cfg.password_file:
            bad("password_file", text)
        else:
            problems.append(f"systemd credential {CREDENTIAL} (the MQTT password): {text}")

    try:
        cfg.password()
    except OSError as exc:
        unreadable(f"cannot read it: {exc.strerror or exc}")
    except InputError as exc:
        unreadable(f"{exc.source}: {exc.problem}")
    for key in ("ca_file", "cert_file", "key_file"):
        if getattr(cfg, key) and not cfg.tls:
            bad(key, "only used with mqtt.tls = true")
    if cfg.key_file and not cfg.cert_file:
        bad("key_file", "is the key of a client certificate: set mqtt.cert_file too")
    elif cfg.tls:  # loaded as the bridge will load them: a bad file shows now, not at night
        from .tls import problems as tls_problems

        for key, text in tls_problems(cfg.ca_file, cfg.cert_file, cfg.key_file):
            bad(key, text)
    if not 10 <= cfg.idle_interval_s <= 3600:
        bad("idle_interval_s", "must lie in 10–3600 s")
    if not 5 <= cfg.keepalive_s <= 3600:
        bad("keepalive_s", "must lie in 5–3600 s")
    if not 1 <= cfg.reconnect_max_s <= 3600:
        bad("reconnect_max_s", "must lie in 1–3600 s")
    return cfg
