"""Config validation at start: ``impctl daemon --config bad.toml`` exits 2 with one line per
problem, each naming the file and the key; the documented example config loads."""

from __future__ import annotations

import dataclasses
import re
import tomllib

from daemon_fixtures import ROOT, run_cli

from impctl.config import (
    CampaignConfig,
    ClockConfig,
    Config,
    CurveConfig,
    FitConfig,
    NightConfig,
    RecordConfig,
    load_config,
)
from impctl.heatpump import HeatPumpConfig, LinkConfig, WritePolicy

EXAMPLE = ROOT / "deploy" / "config.example.toml"


def _problems(result, path) -> list[str]:
    """stderr lines, each checked to be ``impctl: FILE: …`` and returned without the prefix."""
    lines = result.stderr.splitlines()
    prefix = f"impctl: {path}: "
    assert lines and all(line.startswith(prefix) for line in lines), result.stderr
    return [line[len(prefix):] for line in lines]


def test_bad_config_lists_every_problem_one_line_each(tmp_path):
    state = tmp_path / "state"
    bad = tmp_path / "bad.toml"
    bad.write_text(f"""
state_dir = "{state}"
colour = "blue"                 # unknown key

[heatpump]
host = "192.168.1.50"

[night]
sample_interval_s = "sixty"     # wrong type
comfort_band_k = 4.0            # wider than max_comfort_band_k (3 K)

[campaign]
constrained_setpoint_c = 21.0
normal_setpoints_c = [21.0, 25.0]   # above heatpump.writes.loop1_setpoint_c = [16, 24]
""")
    result = run_cli("daemon", "--config", str(bad), timeout_s=30)
    assert result.returncode == 2
    assert result.stdout == ""
    problems = _problems(result, bad)
    assert problems == [
        "key 'colour': unknown key",
        "key 'night.sample_interval_s': must be a number, got 'sixty'",
        "key 'night.comfort_band_k': must lie in (0, 3] K (night.max_comfort_band_k)",
        "key 'campaign.normal_setpoints_c': 25 °C is outside the safety limits "
        "heatpump.writes.loop1_setpoint_c = [16, 24] °C",
        "key 'campaign.constrained_setpoint_c': T_max = T_set + ΔT = 25 °C exceeds the safety "
        "limit 24 °C",
    ]
    assert not state.exists()  # refused before anything was created


def test_setpoint_outside_the_configured_limits_and_heatpump_problems(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("""
[heatpump]
host = "192.168.1.50"

[heatpump.writes]
loop1_setpoint_c = [16.0, 22.0]

[campaign]
constrained_setpoint_c = 15.0
normal_setpoints_c = [21.0, 22.5]
""")
    problems = _problems(run_cli("daemon", "--config", str(bad), timeout_s=30), bad)
    assert problems == [
        "key 'campaign.constrained_setpoint_c': 15 °C is outside the safety limits "
        "heatpump.writes.loop1_setpoint_c = [16, 22] °C",
        "key 'campaign.normal_setpoints_c': 22.5 °C is outside the safety limits "
        "heatpump.writes.loop1_setpoint_c = [16, 22] °C",
        "key 'night.comfort_band_k': T_min − abort margin would fall below 14 °C"]
    bad.write_text("""
[heatpump]
host = "gw"
port = "502"
""")
    result = run_cli("daemon", "--config", str(bad), timeout_s=30)
    assert result.returncode == 2
    [line] = _problems(result, bad)
    assert line.startswith("[heatpump]")


def test_not_toml_and_missing_file_are_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[night\n")
    result = run_cli("daemon", "--config", str(bad), timeout_s=30)
    assert result.returncode == 2
    [line] = _problems(result, bad)
    assert line.startswith("not valid TOML")
    missing = tmp_path / "none.toml"
    result = run_cli("daemon", "--config", str(missing), timeout_s=30)
    assert result.returncode == 2 and _problems(result, missing) == ["file not found"]


def test_example_config_loads_and_documents_every_key():
    cfg = load_config(EXAMPLE)
    # "every key, with its default unless marked example": the values are the defaults.
    assert cfg.night == NightConfig() and cfg.campaign == CampaignConfig()
    assert cfg.clock == ClockConfig() and cfg.heatpump.writes == WritePolicy()
    assert cfg.fit == FitConfig() and cfg.record == RecordConfig()
    assert dataclasses.replace(cfg.heatpump.link, host="127.0.0.1") == LinkConfig()
    assert (cfg.state_dir, cfg.timezone, cfg.log_level, cfg.model_dir) == (
        "/var/lib/impctl", "Europe/Ljubljana", "info", "")
    data = tomllib.loads(EXAMPLE.read_text())
    for section, cls in (("night", NightConfig), ("campaign", CampaignConfig),
                         ("clock", ClockConfig), ("curve", CurveConfig)):
        assert set(data[section]) == {f.name for f in dataclasses.fields(cls)}, section
    assert cfg.curve == CurveConfig()
    # [fit]'s keys are optional (absent = not declared): documented as comments
    assert data["fit"] == {} and cfg.fit.night_gain_w is None
    top = {k for k, v in data.items() if not isinstance(v, dict)}
    assert top == {f.name for f in dataclasses.fields(Config)} - {
        "heatpump", "night", "campaign", "clock", "mqtt", "inputs", "source", "fit", "record",
        "curve"}
    # [record]: every key but the optional snapshot interval (a comment)
    assert set(data["record"]) == {f.name for f in dataclasses.fields(RecordConfig)} - {
        "sample_interval_s"}
    assert re.search(r"^# *sample_interval_s", EXAMPLE.read_text(), re.M)
    hp_keys = {f.name for f in dataclasses.fields(LinkConfig)} | {
        f.name for f in dataclasses.fields(HeatPumpConfig)} - {"link", "writes", "heat_meter"}
    assert set(data["heatpump"]) - {"writes"} == hp_keys
    # The optional keys are documented as comments.
    text = EXAMPLE.read_text()
    for key in ("heat_meter", "loop2_setpoint_c", "correction_k", *(
            f.name for f in dataclasses.fields(FitConfig))):
        assert re.search(rf"^# *\[?(heatpump\.)?{key}", text, re.M), key


def test_example_documents_every_mqtt_key_and_mqtt_is_checked(tmp_path):
    from impctl.mqtt.config import MqttConfig

    text = EXAMPLE.read_text()
    assert load_config(EXAMPLE).mqtt is None  # off unless configured
    for f in dataclasses.fields(MqttConfig):
        assert re.search(rf"^# {f.name} = ", text, re.M), f.name
    # The commented block, uncommented, is a valid [mqtt] section.
    block = "\n".join(line[2:] for line in text.splitlines()
                      if line.startswith("# ") and "[mqtt]" not in line
                      and re.match(r"# \w+ = ", line))
    mqtt_keys = {f.name for f in dataclasses.fields(MqttConfig)}
    lines = [ln for ln in block.splitlines() if ln.split(" = ")[0] in mqtt_keys]
    good = tmp_path / "good.toml"
    good.write_text(f'state_dir = "{tmp_path}"\n[heatpump]\nhost = "127.0.0.1"\n[mqtt]\n'
                    + "\n".join(lines) + "\n")
    cfg = load_config(good).mqtt
    assert cfg.host == "192.168.1.10" and cfg.port == 1883 and not cfg.commands
    assert cfg.client_id.startswith("impctl-") and cfg.topic == f"impctl/{cfg.client_id}"

    bad = tmp_path / "bad.toml"
    bad.write_text(f"""
state_dir = "{tmp_path / 'state'}"
[heatpump]
host = "127.0.0.1"
[mqtt]
port = 70000
password_file = "{tmp_path / 'missing.password'}"
client_id = "my gateway"
base_topic = "impctl/#"
commands = "yes"
colour = "blue"
""")
    result = run_cli("daemon", "--config", str(bad), timeout_s=30)
    assert result.returncode == 2 and result.stdout == ""
    assert _problems(result, bad) == [
        "key 'mqtt.commands': must be true or false, got 'yes'",
        "key 'mqtt.colour': unknown key",
        "key 'mqtt.host': required: the broker's host name or address",
        "key 'mqtt.port': must lie in 1–65535",
        "key 'mqtt.client_id': only letters, digits, '_' and '-' (1–64 characters): it is "
        "used in topics and Home Assistant ids, got 'my gateway'",
        "key 'mqtt.base_topic': must be a topic without wildcards (+ #), spaces or empty "
        "levels, got 'impctl/#'",
        "key 'mqtt.password_file': needs mqtt.username",
        "key 'mqtt.password_file': cannot read it: No such file or directory",
    ]
    assert not (tmp_path / "state").exists()
