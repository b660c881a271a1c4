"""Every number of ``config.toml`` has an upper bound a person would defend, and the MQTT
password file is read as text or refused in one line.

The schema is walked from the dataclasses themselves, so a numeric key added later without
a bound fails here. The CLI runs as a real subprocess (exit status, stderr, no traceback).
"""

from __future__ import annotations

import math
import os
from dataclasses import fields
from typing import Any

import pytest
from cli_fixtures import run_impctl
from daemon_fixtures import run_cli

from impctl.config import ClockConfig, NightConfig, config_from_mapping
from impctl.config.sections import CampaignConfig, FitConfig, TargetHalfwidth
from impctl.errors import InputError
from impctl.heatpump.config import ExternalRegister, WritePolicy
from impctl.modbus.config import LinkConfig
from impctl.mqtt.config import MqttConfig

HOST = {"host": "192.168.1.50"}
METER = {"device_id": 30, "address": 0}


def _lines(result, path) -> list[str]:
    prefix = f"impctl: {path}: "
    lines = result.stderr.splitlines()
    assert lines and all(x.startswith(prefix) for x in lines), result.stderr
    return [x[len(prefix):] for x in lines]


def test_the_issue_s_config_is_refused_with_every_problem_at_once(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text(f"""state_dir = "{tmp_path / 's'}"
[heatpump]
host = "192.168.1.50"
[heatpump.writes]
daily_budget = 100000
[night]
window = "05:00-04:59"
preheat_h = 12
[campaign]
constrained_nights = 1000000
max_nights = 1000000
""")
    result = run_impctl("check-config", "--config", str(cfg))
    assert result.returncode == 2 and result.stdout == ""
    assert "Traceback" not in result.stderr
    lines = _lines(result, cfg)
    assert len(lines) == 5, lines
    assert any(x.startswith("[heatpump.writes] key 'daily_budget': daily_budget + "
                            "restore_reserve = 100002 writes per register per day; at most 18")
               and "EEPROM endurance" in x for x in lines)
    assert "key 'night.window': '05:00-04:59' lasts 23.98 h; a night window lasts 1–12 h " \
           "(longer takes the heat from a home in daytime)" in lines
    assert "key 'night.preheat_h': must lie in 0–4 h, got 12" in lines
    for key in ("max_nights", "constrained_nights"):
        assert (f"key 'campaign.{key}': 1000000 nights: at most 60 (two winter months) are "
                "asked of a household") in lines
    assert not (tmp_path / "s").exists()


def test_the_eeprom_budget_bound_is_derived_from_the_endurance():
    from impctl.heatpump.config import WRITES_PER_DAY_MAX

    # 100,000 writes over 15 years of daily spending: 18 per register per day.
    assert WRITES_PER_DAY_MAX == 18
    WritePolicy(daily_budget=16, restore_reserve=2)
    with pytest.raises(InputError, match="at most 18"):
        WritePolicy(daily_budget=17, restore_reserve=2)


# -- every numeric key of the schema ------------------------------------------------------------
#: Where each dataclass sits in the TOML mapping.
_TABLES: list[tuple[type, tuple[str, ...]]] = [
    (NightConfig, ("night",)), (CampaignConfig, ("campaign",)),
    (TargetHalfwidth, ("campaign", "target_rel_halfwidth")), (ClockConfig, ("clock",)),
    (FitConfig, ("fit",)), (LinkConfig, ("heatpump",)), (WritePolicy, ("heatpump", "writes")),
    (ExternalRegister, ("heatpump", "heat_meter")), (MqttConfig, ("mqtt",)),
]


def _numeric_keys() -> list[tuple[tuple[str, ...], str, Any]]:
    out = []
    for cls, path in _TABLES:
        for f in fields(cls):
            kind = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")
            if any(word in kind for word in ("int", "float")) and "bool" not in kind:
                out.append((path, f.name, kind))
    return out


NUMERIC_KEYS = _numeric_keys()


def test_the_schema_walk_finds_the_numeric_keys():
    names = {".".join((*p, k)) for p, k, _ in NUMERIC_KEYS}
    assert {"night.preheat_h", "campaign.max_nights", "heatpump.writes.daily_budget",
            "heatpump.port", "heatpump.heat_meter.scale", "mqtt.keepalive_s",
            "clock.speed", "campaign.normal_setpoints_c"} <= names
    assert len(NUMERIC_KEYS) >= 45


def _huge(kind: str, name: str) -> Any:
    if "tuple" in kind:
        return [1.0, 1e12]
    return 10**12 if kind.startswith("int") or "int |" in kind else 1e12


def _mapping(path: tuple[str, ...], key: str, value: Any) -> dict:
    mapping: dict[str, Any] = {"state_dir": "/tmp/x", "heatpump": {**HOST},
                               "mqtt": {"host": "broker"}}
    if path[:2] == ("heatpump", "heat_meter"):
        mapping["heatpump"]["heat_meter"] = {**METER}
    table = mapping
    for part in path:
        table = table.setdefault(part, {})
    table[key] = value
    return mapping


@pytest.mark.parametrize("path, key, kind", NUMERIC_KEYS,
                         ids=[".".join((*p, k)) for p, k, _ in NUMERIC_KEYS])
def test_every_numeric_key_has_an_upper_bound(path, key, kind):
    value = _huge(kind, key)
    if key == "wall_epoch_s":  # also needs a simulated clock to mean anything
        mapping = _mapping(path, key, value)
        mapping["clock"]["epoch"] = "2026-01-12T20:00:00+00:00"
    else:
        mapping = _mapping(path, key, value)
    with pytest.raises(InputError) as err:
        config_from_mapping(mapping, "c.toml")
    named = [line for line in str(err.value).splitlines() if f"'{key}'" in line
             or f".{key}'" in line]
    assert named, f"{'.'.join((*path, key))} = {value!r} accepted: {err.value}"


def test_the_defaults_and_the_example_values_are_inside_the_bounds():
    cfg = config_from_mapping({"state_dir": "/tmp/x", "heatpump": {**HOST,
                               "heat_meter": {**METER, "scale": 1.0}},
                               "night": {"window": "22:00-10:00", "preheat_h": 4.0}})
    assert cfg.night.preheat_h == 4.0 and math.isclose(cfg.heatpump.writes.daily_budget, 12)


# -- the MQTT password file ---------------------------------------------------------------------
def _mqtt_config(tmp_path, password: bytes, mode: int) -> tuple:
    pw = tmp_path / "mqtt.password"
    pw.write_bytes(password)
    os.chmod(pw, mode)
    cfg = tmp_path / "c.toml"
    cfg.write_text(f"""state_dir = "{tmp_path / 's'}"
[heatpump]
host = "192.168.1.50"
[mqtt]
host = "127.0.0.1"
username = "impctl"
password_file = "{pw}"
""")
    return cfg, pw


@pytest.mark.parametrize("command", ["check-config", "status", "daemon"])
def test_a_non_utf8_password_file_is_one_line_and_exit_2(tmp_path, command):
    cfg, pw = _mqtt_config(tmp_path, b"s\xe9cret\xff\n", 0o600)
    # the daemon in its own process; the other commands' line is checked in this one
    result = (run_cli(command, "--config", str(cfg), timeout_s=30) if command == "daemon"
              else run_impctl(command, "--config", str(cfg)))
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    assert _lines(result, cfg) == [
        f"key 'mqtt.password_file': {pw}: not UTF-8 text (byte 2): write the password as "
        "plain text on the first line"]
    assert not (tmp_path / "s").exists()


def test_a_non_utf8_systemd_credential_is_one_line_and_exit_2(tmp_path, monkeypatch):
    """No password_file: the unit's credential ``mqtt.password`` is checked the same way."""
    cfg, _ = _mqtt_config(tmp_path, b"unused\n", 0o600)
    cfg.write_text(cfg.read_text().replace(f'password_file = "{tmp_path / "mqtt.password"}"\n',
                                           ""))
    creds = tmp_path / "credentials"
    creds.mkdir()
    (creds / "mqtt.password").write_bytes(b"s\xe9cret\n")
    monkeypatch.setenv("CREDENTIALS_DIRECTORY", str(creds))
    result = run_impctl("check-config", "--config", str(cfg))
    assert result.returncode == 2, result.stdout + result.stderr
    assert "Traceback" not in result.stderr
    assert _lines(result, cfg) == [
        f"systemd credential mqtt.password (the MQTT password): {creds / 'mqtt.password'}: "
        "not UTF-8 text (byte 2): write the password as plain text on the first line"]


def test_a_password_file_others_can_read_is_a_warning(tmp_path):
    cfg, pw = _mqtt_config(tmp_path, b"secret\n", 0o644)
    result = run_impctl("check-config", "--config", str(cfg))
    assert result.returncode == 0, result.stderr
    assert (f"warning:   {pw}: the MQTT password file is readable by other users (mode 0644): "
            f"chmod 600 {pw}") in result.stdout
    result = run_impctl("status", "--config", str(cfg))
    assert f"impctl: warning: {pw}: the MQTT password file is readable" in result.stderr
    os.chmod(pw, 0o600)
    from impctl.config import config_warnings, load_config

    assert config_warnings(load_config(cfg)) == []
    result = run_impctl("check-config", "--config", str(cfg))
    assert result.returncode == 0 and "warning" not in result.stdout
