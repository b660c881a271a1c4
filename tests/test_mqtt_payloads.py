"""The MQTT payloads without a broker: command parsing, fit results, discovery per config."""

from __future__ import annotations

import json
from datetime import UTC, datetime

import pytest
from mqtt_fixtures import check_discovery, render

from impctl.mqtt.commands import BadCommand, parse_command
from impctl.mqtt.config import MqttConfig
from impctl.mqtt.homeassistant.discovery import DeviceIdentity, Limits, discovery_messages
from impctl.mqtt.homeassistant.payloads import LiveState, fit_payloads

LIMITS = Limits(setpoint_min_c=16.0, setpoint_max_c=23.0, comfort_band_k=1.5,
                default_setpoint_c=21.0)
DEVICE = DeviceIdentity("Kronoterm heat pump, extended controller", "tcp 10.0.0.5:502", "0.1")


def _parse(name: str, payload: str | bytes, kind="constrained", sp=21.0):
    raw = payload.encode() if isinstance(payload, str) else payload
    return parse_command(name, raw, LIMITS, kind, sp)


def test_commands_parse_what_buttons_and_people_send():
    assert _parse("abort", "abort").name == "abort"
    assert _parse("abort", "PRESS").name == "abort"  # Home Assistant's default payload
    assert _parse("skip_tonight", "skip_tonight").name == "skip_tonight"
    t = _parse("trigger", "tonight", kind="normal", sp=22.0)
    assert (t.kind, t.setpoint_c, t.when) == ("normal", 22.0, "tonight")
    t = _parse("trigger", json.dumps({"kind": "constrained", "setpoint_c": 20.5,
                                      "when": "now"}))
    assert (t.kind, t.setpoint_c, t.when) == ("constrained", 20.5, "now")
    assert _parse("night_kind", "Normal").kind == "normal"
    assert _parse("night_setpoint", "22.5").setpoint_c == 22.5


@pytest.mark.parametrize(("name", "payload", "why"), [
    ("abort", "yes please", "expected 'abort' or PRESS"),
    # An empty payload clears a retained message (mosquitto_pub -r -n): never a press.
    ("abort", "", "empty payload: not a command"),
    ("skip_tonight", "", "empty payload: not a command"),
    ("trigger", "  ", "empty payload: not a command"),
    ("night_kind", "", "empty payload: not a command"),
    ("abort", b"\xff\xfe", "not UTF-8"),
    ("abort", "x" * 300, "too long"),
    ("trigger", "{not json", "expected tonight, now or a JSON object"),
    ("trigger", "[1, 2]", "expected a JSON object"),
    ("trigger", '{"kind": "hot"}', "kind must be"),
    ("trigger", '{"setpoint_c": "warm"}', "expected a number"),
    ("trigger", '{"setpoint_c": NaN}', "finite"),
    ("trigger", '{"when": "yesterday"}', "when must be"),
    ("trigger", '{"colour": 1}', "unknown field"),
    # Constrained at 22.5 °C would preheat to 24 °C, above the 23 °C limit.
    ("trigger", '{"kind": "constrained", "setpoint_c": 22.5}', "top 24 °C"),
    ("night_setpoint", "40", "outside the safety limits"),
    ("night_kind", "hot", "expected 'constrained' or 'normal'"),
    ("reboot", "now", "unknown command"),
])
def test_malformed_commands_say_why_in_one_line(name, payload, why):
    with pytest.raises(BadCommand) as exc:
        _parse(name, payload)
    assert why in str(exc.value) and "\n" not in str(exc.value)


def test_fit_payloads_units_intervals_and_undetermined():
    result = {"lumped": {
        "hlc": {"value": 180.0, "low": 170.0, "high": 190.0, "determined": True, "unit": "W/K"},
        "c_m": {"value": 3.2e7, "low": 2.9e7, "high": 3.6e7, "determined": False,
                "unit": "J/K"},
        "tau": {"value": 49.4, "low": 45.0, "high": 53.0, "determined": True, "unit": "h"}}}
    created = datetime(2026, 1, 20, 6, 0, tzinfo=UTC)
    out = fit_payloads((created, [1, 2, 3], result))
    assert out["hlc"]["value"] == 180.0 and (out["hlc"]["low"], out["hlc"]["high"]) == (
        170.0, 190.0)
    # C_m in MJ/K; not determined by the nights: no value, the interval kept.
    assert out["c_m"]["value"] is None and out["c_m"]["low"] == 29.0
    assert out["c_m"]["unit"] == "MJ/K" and out["c_m"]["determined"] is False
    assert out["tau"]["nights"] == [1, 2, 3]
    assert out["coast_h"]["value"] is None  # no flexibility block yet
    result["flexibility"] = {"coast_h": 6.25, "coast_h_low": 5.0, "coast_h_high": 7.5,
                             "rebound_kwh": 9.1}
    coast = fit_payloads((created, [1, 2, 3], result))["coast_h"]
    assert (coast["value"], coast["low"], coast["high"], coast["rebound_kwh"]) == (
        6.25, 5.0, 7.5, 9.1)
    assert all(v["value"] is None for v in fit_payloads(None).values())


def test_discovery_without_commands_has_no_buttons_and_templates_render():
    cfg = MqttConfig(host="h", client_id="gw9")
    msgs = dict(discovery_messages(cfg, DEVICE, LIMITS))
    configs = {t: json.loads(p) for t, p in msgs.items()}
    assert check_discovery(configs) == []
    # + next experiment, heat pump electricity, heat delivered; the curve's flow now and saving
    assert len(configs) == 23
    assert not [t for t in configs if "/button/" in t or "/select/" in t or "/number/" in t]
    state = LiveState(t_air_c=20.456, t_out_c=None, q_hc_w=1234.4, night_state="active",
                      night_kind="normal", campaign_valid=2, campaign_planned=5,
                      link_ok=True, writes={"2187": "2/12", "2042": "1/12"})
    payload = json.dumps(state.as_json()).encode()
    by_key = {t.split("/")[3]: c for t, c in configs.items()}
    assert render(by_key["t_air"]["value_template"], payload) == "20.46"
    assert render(by_key["t_out"]["value_template"], payload) == "None"  # HA: unknown
    assert render(by_key["q_hc"]["value_template"], payload) == "1234.0"
    assert render(by_key["campaign"]["value_template"], payload) == "2/5"
    assert json.loads(render(by_key["campaign"]["json_attributes_template"], payload)) == {
        "valid_nights": 2, "planned_nights": 5}
    assert render(by_key["writes_today"]["value_template"], payload) == "3"
    assert render(by_key["experiment_active"]["value_template"], payload) == "ON"
    assert render(by_key["link"]["value_template"], payload) == "ON"
    assert configs["homeassistant/sensor/gw9/tau/config"]["device_class"] == "duration"


def test_the_heating_curve_sensors_say_what_to_set_and_what_it_saves():
    """The suggested flow temperature now follows the outdoor temperature along the kept
    curve; the expected saving is the curve result's, its advice an attribute in plain
    words; no curve kept: both unknown, never a number."""
    from impctl.daemon.curve.state import suggested_flow_c
    from impctl.mqtt.homeassistant.payloads import curve_payload

    cfg = MqttConfig(host="h", client_id="gw9")
    by_key = {t.split("/")[3]: json.loads(p)
              for t, p in discovery_messages(cfg, DEVICE, LIMITS)}
    flow, saving = by_key["curve_flow_now"], by_key["curve_saving"]
    assert flow["name"] == "Suggested flow temperature now" and flow["unit_of_measurement"] == "°C"
    assert saving["name"] == "Expected saving this winter"
    assert saving["unit_of_measurement"] == "kWh" and saving["state_topic"] == "impctl/gw9/curve"
    curve = {"schema": "impctl-curve/1", "lowers": True, "hotter_at_0_k": 4.2,
             "advice": "Your heating runs its water 4 K hotter than this house needs …",
             "recommended": {"flow_c": [44.0, 26.0], "flow_at_0_c": 35.0},
             "running": {"flow_at_0_c": 39.2},
             "savings": {"saving_kwh": {"value": 312.0, "low": 250.0, "high": 380.0},
                         "climate": {"description": "an assumed winter"}},
             "cop": {"assumed": False}}
    state = LiveState(t_out_c=-5.0, suggested_flow_c=suggested_flow_c(curve, -5.0))
    assert render(flow["value_template"], json.dumps(state.as_json()).encode()) == "38.0"
    payload = json.dumps(curve_payload(curve)).encode()
    assert render(saving["value_template"], payload) == "312.0"
    attrs = curve_payload(curve)
    assert attrs["advice"].startswith("Your heating runs") and attrs["low"] == 250.0
    assert "HLC" not in attrs["advice"] and "HLC" not in saving["name"] + flow["name"]
    kept = curve_payload({**curve, "lowers": False})
    assert kept["value"] == 0.0  # the curve is kept: nothing to save
    assert curve_payload(None)["value"] is None
    assert suggested_flow_c(None, 3.0) is None and suggested_flow_c(curve, None) is None


def test_password_from_file_or_systemd_credential(tmp_path, monkeypatch):
    monkeypatch.delenv("CREDENTIALS_DIRECTORY", raising=False)
    assert MqttConfig(host="h").password() is None
    (tmp_path / "pw").write_text("from-file\nignored\n")
    assert MqttConfig(host="h", password_file=str(tmp_path / "pw")).password() == "from-file"
    creds = tmp_path / "creds"
    creds.mkdir()
    (creds / "mqtt.password").write_text("from-systemd\n")
    monkeypatch.setenv("CREDENTIALS_DIRECTORY", str(creds))
    assert MqttConfig(host="h").password() == "from-systemd"


def test_counted_warnings_bound_the_lines_and_lose_no_count(caplog):
    """A few lines in full per kind and window, the rest counted at the window's end (or at
    stop); commands that are no command share one kind however many names they use."""
    import logging

    from impctl.mqtt.counted import CountedWarnings

    now = [0.0]
    log = logging.getLogger("test.counted")
    warnings = CountedWarnings(log, lambda: now[0], window_s=60.0, in_full=2)
    with caplog.at_level(logging.WARNING, logger="test.counted"):
        for i in range(1000):
            warnings.warn((None, "malformed"), "b/cmd/+ (unknown commands)", f"unknown {i}",
                          f"MQTT command b/cmd/x{i} ignored: unknown command 'x{i}'")
        now[0] = 61.0  # the next one, a minute later, opens a new window
        warnings.warn((None, "malformed"), "b/cmd/+ (unknown commands)", "unknown z", "z")
        warnings.flush()
    assert [r.getMessage() for r in caplog.records] == [
        "MQTT command b/cmd/x0 ignored: unknown command 'x0'",
        "MQTT command b/cmd/x1 ignored: unknown command 'x1'",
        "MQTT: 998 more commands on b/cmd/+ (unknown commands) ignored within 60 s of the "
        "first: the last: unknown 999",
        "z"]
