"""MQTT over TLS, as installers get it wrong: a CA file that is no certificate, a TLS client on
the broker's plain port, a password sent over plain TCP, a broker that requires client
certificates.

Real parts: a CA, a server and a client certificate made with the ``openssl`` command line,
a mosquitto process with a plain and a TLS listener (the latter asking for a client
certificate), the ``impctl daemon`` and ``impctl check-config`` subprocesses, the simulator.
The MQTT password appears nowhere: not in the log, not in ``impctl status``, not in
``check-config``.
"""

from __future__ import annotations

import json
import subprocess
from datetime import datetime
from pathlib import Path
from zoneinfo import ZoneInfo

import pytest
from cli_fixtures import run_impctl
from daemon_fixtures import (
    daemon_mapping,
    free_port,
    sim_process,
    start_daemon,
    stop_process,
    wait_until,
    write_config,
)
from mqtt_fixtures import broker, home_assistant, make_pki, tls_listener

TZ = ZoneInfo("Europe/Ljubljana")
NOON = datetime(2026, 1, 12, 12, 0, tzinfo=TZ)
BASE = "impctl/gw1"
PASSWORD = "Tr0ub4dor-and-3"
USERS = {"impctl": PASSWORD, "ha": "ha-password"}


@pytest.fixture(scope="module")
def pki(tmp_path_factory):
    return make_pki(tmp_path_factory.mktemp("pki"))


@pytest.fixture(scope="module")
def tls_broker(tmp_path_factory, pki):
    """mosquitto with a plain listener (``b.port``) and a TLS one asking for a client
    certificate (``b.tls_port``), both with passwords."""
    tls_port = free_port()
    with broker(tmp_path_factory.mktemp("broker"), USERS, tls_listener(tls_port, pki)) as b:
        b.tls_port = tls_port
        wait_until(lambda: _listening(tls_port), 10, "the TLS listener")
        yield b


def _listening(port: int) -> bool:
    import socket

    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def _password_file(work: Path) -> Path:
    pw = work / "mqtt.password"
    pw.write_text(PASSWORD + "\n")
    pw.chmod(0o600)
    return pw


def _config(work: Path, mqtt: dict, heatpump_port: int = 502, clock=None) -> Path:
    """config.toml in ``work``: the simulator's clock when given (a daemon run), else only
    what check-config needs; empty ``mqtt`` values are left out."""
    mqtt = {k: v for k, v in mqtt.items() if v != ""}
    if clock is None:
        mapping = {"state_dir": str(work / "state"),
                   "heatpump": {"host": "127.0.0.1", "port": heatpump_port}, "mqtt": mqtt}
    else:
        mapping = daemon_mapping(work / "state", heatpump_port, clock,
                                 campaign={"enabled": False}, mqtt=mqtt)
    return write_config(work / "config.toml", mapping)


def _check(config: Path) -> subprocess.CompletedProcess:
    return run_impctl("check-config", "--config", str(config))


# -- impctl check-config loads what the bridge will load -------------------------------------
def test_check_config_loads_the_ca_and_the_client_certificate(tmp_path, pki):
    garbage = tmp_path / "ca.pem"
    garbage.write_text("this is not a certificate\n")
    encrypted = tmp_path / "encrypted.key"
    subprocess.run(["openssl", "pkey", "-in", str(pki.client_key), "-aes256", "-passout",
                    "pass:secret", "-out", str(encrypted)], check=True, capture_output=True)
    encrypted.chmod(0o600)
    base = {"host": "127.0.0.1", "port": 8883, "tls": True}
    cases = [
        ({"ca_file": str(garbage)},
         f"key 'mqtt.ca_file': {garbage} holds no CA certificate OpenSSL can read (no "
         "certificate or crl found): give the broker's CA certificate in PEM form (a text "
         "file starting '-----BEGIN CERTIFICATE-----')"),
        ({"ca_file": str(pki.ca), "cert_file": str(pki.client_cert),
          "key_file": str(pki.other_key)},
         f"key 'mqtt.key_file': {pki.other_key} is not the key of the certificate "
         f"{pki.client_cert} (key values mismatch)"),
        ({"ca_file": str(pki.ca), "cert_file": str(pki.client_cert),
          "key_file": str(encrypted)},
         f"key 'mqtt.key_file': {encrypted}: the private key is encrypted with a passphrase, "
         "which impctl cannot type in"),
        ({"ca_file": str(pki.ca), "cert_file": str(pki.client_cert)},
         f"key 'mqtt.cert_file': {pki.client_cert} does not load as a PEM certificate with "
         "its private key"),
        ({"key_file": str(pki.client_key)},
         "key 'mqtt.key_file': is the key of a client certificate: set mqtt.cert_file too"),
    ]
    for i, (extra, expected) in enumerate(cases):
        (work := tmp_path / str(i)).mkdir()
        config = _config(work, {**base, **extra})
        result = _check(config)
        assert result.returncode == 2, (extra, result.stdout)
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"impctl: {config}: {expected}"), (
            extra, lines)
    (work := tmp_path / "good").mkdir()
    good = _config(work, {**base, "ca_file": str(pki.ca), "cert_file": str(pki.client_cert),
                          "key_file": str(pki.client_key)})
    result = _check(good)
    assert result.returncode == 0, result.stderr
    assert "warning" not in result.stdout
    pki.client_key.chmod(0o640)
    try:
        result = _check(good)
        assert (f"warning:   {pki.client_key}: the MQTT client's private key is readable by "
                f"other users (mode 0640): chmod 600 {pki.client_key}") in result.stdout
    finally:
        pki.client_key.chmod(0o600)


def test_a_password_over_plain_tcp_to_another_machine_is_a_warning(tmp_path):
    pw = _password_file(tmp_path)
    mqtt = {"host": "192.0.2.10", "username": "impctl", "password_file": str(pw)}
    config = _config(tmp_path, mqtt)
    result = _check(config)
    assert result.returncode == 0, result.stderr
    warning = ("the MQTT password of 'impctl' goes to 192.0.2.10:1883 in clear text "
               "(mqtt.tls = false): anyone on the network path can read it; set mqtt.tls = "
               "true (the broker's TLS port, usually 8883) or run the broker on this machine")
    assert f"warning:   {warning}" in result.stdout
    status = run_impctl("status", "--config", str(config))
    assert f"impctl: warning: {warning}" in status.stderr
    assert PASSWORD not in result.stdout + result.stderr + status.stdout + status.stderr
    # the password from the systemd credential the unit loads (check-config cannot see it)
    result = _check(_config(tmp_path, {**mqtt, "password_file": ""}))
    assert result.returncode == 0 and f"warning:   {warning}" in result.stdout, result
    # the same broker on this machine, or over TLS, or without a password: no warning
    for other in ({"host": "127.0.0.1"}, {"host": "localhost"}, {"tls": True, "port": 8883},
                  {"username": "", "password_file": ""}):
        config = _config(tmp_path, {**mqtt, **other})
        result = _check(config)
        assert result.returncode == 0 and "clear text" not in result.stdout, (other, result)


# -- the daemon against a real TLS broker -------------------------------------------------------
def _daemon(work: Path, mqtt: dict, until: str):
    """Start the daemon against a simulator with ``[mqtt]`` = ``mqtt``; wait for ``until`` in
    its log; return (the daemon, its config)."""
    sim_cm = sim_process(work, NOON, 60.0, plant="iso")
    sim = sim_cm.__enter__()
    config = _config(work, {"client_id": "gw1", "keepalive_s": 5, "reconnect_max_s": 1.0,
                            **mqtt}, sim.port, sim.clock)
    d = start_daemon(config, work / "state" / "impctl.db", work / "daemon.log")
    try:
        wait_until(lambda: until in d.output(), 40, repr(until), proc=d.proc)
    except BaseException:
        stop_process(d.proc)
        sim_cm.__exit__(None, None, None)
        raise
    d.sim_cm = sim_cm
    return d, config


def _stop(d) -> None:
    assert stop_process(d.proc) == 0
    d.sim_cm.__exit__(None, None, None)


def test_the_daemon_connects_with_a_client_certificate(tmp_path, pki, tls_broker):
    b = tls_broker
    with home_assistant(b.port, username="ha", password=USERS["ha"]) as ha:
        d, config = _daemon(tmp_path, {
            "host": "127.0.0.1", "port": b.tls_port, "tls": True, "ca_file": str(pki.ca),
            "cert_file": str(pki.client_cert), "key_file": str(pki.client_key),
            "username": "impctl", "password_file": str(_password_file(tmp_path))},
            "MQTT connected")
        try:
            wait_until(lambda: (m := ha.latest(f"{BASE}/availability"))
                       and m.payload == b"online", 20, "online over TLS", proc=d.proc)
            assert ha.latest("homeassistant/sensor/gw1/t_air/config") is not None
            status = run_impctl("status", "--json", "--config", str(config))
            text = run_impctl("status", "--config", str(config))
            check = _check(config)
            assert check.returncode == 0 and "warning" not in check.stdout, check
        finally:
            _stop(d)
    assert json.loads(status.stdout)["mqtt"]["connected"] is True, status.stdout
    assert f"mqtt:      connected to 127.0.0.1:{b.tls_port}" in text.stdout, text.stdout
    everything = (d.output() + status.stdout + status.stderr + text.stdout + text.stderr
                  + check.stdout + check.stderr)
    assert PASSWORD not in everything


def test_tls_on_the_plain_port_says_what_is_likely(tmp_path, pki, tls_broker):
    b = tls_broker
    d, _ = _daemon(tmp_path, {"host": "127.0.0.1", "port": b.port, "tls": True,
                              "ca_file": str(pki.ca)}, "MQTT broker")
    try:
        [line] = [ln for ln in d.output().splitlines() if "MQTT broker" in ln]
    finally:
        _stop(d)
    assert "WARNING" in line and "Connection reset by peer" in line, line
    assert (f"does the broker at 127.0.0.1:{b.port} speak TLS on that port? (plain MQTT is "
            "usually on 1883, MQTT over TLS on 8883)") in line, line


def test_a_broker_that_wants_a_client_certificate_says_so(tmp_path, pki, tls_broker):
    b = tls_broker
    d, _ = _daemon(tmp_path, {"host": "127.0.0.1", "port": b.tls_port, "tls": True,
                              "ca_file": str(pki.ca), "username": "impctl",
                              "password_file": str(_password_file(tmp_path))},
                   "MQTT broker")
    try:
        wait_until(lambda: "retrying" in d.output(), 30, "the outage line", proc=d.proc)
        lines = [ln for ln in d.output().splitlines() if "MQTT" in ln or "socket" in ln]
    finally:
        _stop(d)
    [line] = lines  # one line for the outage, none per retry from the MQTT library
    assert "certificate required" in line, line
    assert (f"the broker at 127.0.0.1:{b.tls_port} asks for a client certificate: set "
            "mqtt.cert_file and mqtt.key_file") in line, line
    assert PASSWORD not in d.output()
