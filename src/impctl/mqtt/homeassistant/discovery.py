"""Home Assistant MQTT discovery: one device, its entities, their retained config messages.

Topics (``<base>`` = ``MqttConfig.topic``):

* ``<base>/availability`` — ``online`` / ``offline`` (retained; ``offline`` is the last will);
* ``<base>/state`` — live values and the night's state as one JSON object (not retained);
* ``<base>/fit/<name>`` — the last fit's HLC, C_m, τ and the coast time (retained);
* ``<base>/curve`` — the heating curve's expected saving and advice (retained);
* ``<base>/settings`` — the kind and setpoint the trigger button will use (retained);
* ``<base>/cmd/<command>`` — commands, only with ``commands = true``.

Config messages go to ``<discovery_prefix>/<component>/<client_id>/<key>/config`` (retained),
in Home Assistant's documented discovery schema (full key names, no abbreviations).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from ..config import MqttConfig

#: Payloads of the availability topic.
ONLINE, OFFLINE = "online", "offline"
#: The values of the night's state and kind (Home Assistant's enum sensors list them).
NIGHT_STATES = ("idle", "preparing", "active", "restoring")
NIGHT_KINDS = ("none", "constrained", "normal")
#: What the fit topics hold: name → (entity name, unit, device class or None).
FIT_QUANTITIES = {
    "hlc": ("Heat loss coefficient HLC", "W/K", None),
    "c_m": ("Heat capacity C_m", "MJ/K", None),
    "tau": ("Time constant τ", "h", "duration"),
    "coast_h": ("Coast time", "h", "duration"),
}


@dataclass(frozen=True)
class DeviceIdentity:
    """What Home Assistant shows in the device card.

    Attributes
    ----------
    model : str, e.g. "Kronoterm heat pump, extended controller"
    link : str, where impctl reaches it (gateway address or serial port), shown as the
        hardware version
    sw_version : str, impctl's version
    """

    model: str
    link: str
    sw_version: str


@dataclass(frozen=True)
class Limits:
    """The safety limits a household's trigger must respect (from the daemon config)."""

    setpoint_min_c: float
    setpoint_max_c: float
    comfort_band_k: float
    default_setpoint_c: float


def _state(key: str) -> str:
    return "{{ value_json." + key + " }}"


def _flag(key: str) -> str:
    return "{{ 'ON' if value_json." + key + " else 'OFF' }}"


def entities(cfg: MqttConfig, limits: Limits) -> list[tuple[str, str, dict]]:
    """(component, key, component-specific config) of every entity impctl announces."""
    base = cfg.topic
    state, settings = f"{base}/state", f"{base}/settings"
    temp = {"device_class": "temperature", "unit_of_measurement": "°C",
            "state_class": "measurement", "suggested_display_precision": 1}
    energy = {"device_class": "energy", "unit_of_measurement": "kWh",
              "state_class": "total_increasing", "suggested_display_precision": 0}
    out: list[tuple[str, str, dict]] = [
        ("sensor", "t_air", {"name": "Indoor temperature", "state_topic": state,
                             "value_template": _state("t_air_c"), **temp}),
        ("sensor", "t_out", {"name": "Outdoor temperature", "state_topic": state,
                             "value_template": _state("t_out_c"), **temp}),
        ("sensor", "q_hc", {"name": "Heat power", "state_topic": state,
                            "value_template": _state("q_hc_w"), "device_class": "power",
                            "unit_of_measurement": "W", "state_class": "measurement",
                            "suggested_display_precision": 0}),
        ("sensor", "night_state", {"name": "Night state", "state_topic": state,
                                   "value_template": _state("night_state"),
                                   "device_class": "enum", "options": list(NIGHT_STATES),
                                   "icon": "mdi:weather-night"}),
        ("sensor", "night_kind", {"name": "Night kind", "state_topic": state,
                                  "value_template": _state("night_kind"),
                                  "device_class": "enum", "options": list(NIGHT_KINDS),
                                  "icon": "mdi:thermometer-lines"}),
        ("sensor", "next_night", {"name": "Next experiment", "state_topic": state,
                                  "value_template": _state("next_night_at"),
                                  "device_class": "timestamp",
                                  "icon": "mdi:calendar-clock"}),
        # The heat pump's lifetime counters (heating + hot water): the electricity one is a
        # device's consumption in Home Assistant's Energy dashboard.
        ("sensor", "energy_el", {"name": "Heat pump electricity", "state_topic": state,
                                 "value_template": _state("energy_el_kwh"), **energy}),
        ("sensor", "energy_heat", {"name": "Heat delivered", "state_topic": state,
                                   "value_template": _state("energy_heat_kwh"), **energy,
                                   "icon": "mdi:radiator"}),
        ("sensor", "campaign", {"name": "Campaign progress", "state_topic": state,
                                "value_template": _state("campaign"),
                                "json_attributes_topic": state,
                                "json_attributes_template":
                                    "{{ {'valid_nights': value_json.campaign_valid, "
                                    "'planned_nights': value_json.campaign_planned} "
                                    "| tojson }}",
                                "icon": "mdi:progress-check"}),
        # The campaign (issue 18): nights spent, how precise the last fit is, why it goes on.
        ("sensor", "nights_run", {"name": "Campaign nights run", "state_topic": state,
                                  "value_template": _state("nights_run"),
                                  "state_class": "total", "icon": "mdi:weather-night"}),
        ("sensor", "nights_valid", {"name": "Campaign nights valid", "state_topic": state,
                                    "value_template": _state("nights_valid"),
                                    "state_class": "total", "icon": "mdi:check-circle"}),
        ("sensor", "hlc_halfwidth", {"name": "HLC interval half-width", "state_topic": state,
                                     "value_template": _state("hlc_rel_pct"),
                                     "unit_of_measurement": "%", "state_class": "measurement",
                                     "suggested_display_precision": 1,
                                     "icon": "mdi:arrow-collapse-horizontal"}),
        ("sensor", "tau_halfwidth", {"name": "τ interval half-width", "state_topic": state,
                                     "value_template": _state("tau_rel_pct"),
                                     "unit_of_measurement": "%", "state_class": "measurement",
                                     "suggested_display_precision": 1,
                                     "icon": "mdi:arrow-collapse-horizontal"}),
        ("sensor", "campaign_status", {"name": "Campaign status", "state_topic": state,
                                       "value_template": _state("campaign_status"),
                                       "json_attributes_topic": state,
                                       "json_attributes_template":
                                           "{{ {'mode': value_json.campaign_mode, "
                                           "'reason': value_json.campaign_reason} | tojson }}",
                                       "icon": "mdi:flag-checkered"}),
        ("sensor", "writes_today", {"name": "Writes today", "state_topic": state,
                                    "value_template": _state("writes_today"),
                                    "json_attributes_topic": state,
                                    "json_attributes_template":
                                        "{{ value_json.writes | tojson }}",
                                    "state_class": "measurement",
                                    "entity_category": "diagnostic", "icon": "mdi:counter"}),
        # The heating curve (impctl curve): what to set the heat pump to, and what it saves.
        ("sensor", "curve_flow_now", {"name": "Suggested flow temperature now",
                                      "state_topic": state,
                                      "value_template": _state("suggested_flow_c"), **temp,
                                      "icon": "mdi:thermometer-water"}),
        ("sensor", "curve_saving", {"name": "Expected saving this winter",
                                    "state_topic": f"{base}/curve",
                                    "value_template": _state("value"),
                                    "json_attributes_topic": f"{base}/curve",
                                    "unit_of_measurement": "kWh",
                                    "suggested_display_precision": 0,
                                    "icon": "mdi:piggy-bank-outline"}),
        ("binary_sensor", "experiment_active", {
            "name": "Experiment active", "state_topic": state,
            "value_template": _flag("experiment_active"), "device_class": "running"}),
        ("binary_sensor", "link", {
            "name": "Heat pump link", "state_topic": state, "value_template": _flag("link_ok"),
            "device_class": "connectivity", "entity_category": "diagnostic"}),
    ]
    for name, (label, unit, device_class) in FIT_QUANTITIES.items():
        topic = f"{base}/fit/{name}"
        conf = {"name": label, "state_topic": topic, "value_template": _state("value"),
                "json_attributes_topic": topic, "unit_of_measurement": unit,
                "state_class": "measurement", "icon": "mdi:home-thermometer-outline",
                "suggested_display_precision": 1}
        if device_class:
            conf["device_class"] = device_class
        if name == "coast_h":
            # Unavailable (not "unknown") until a fit carries the flexibility block.
            conf["availability_mode"] = "all"
            conf["availability"] = [
                {"topic": f"{base}/availability"},
                {"topic": topic, "value_template":
                    "{{ 'online' if value_json.value is not none else 'offline' }}"}]
        out.append(("sensor", name, conf))
    if cfg.commands:
        cmd = f"{base}/cmd"
        out += [
            ("button", "abort", {"name": "Stop tonight's experiment",
                                 "command_topic": f"{cmd}/abort", "payload_press": "abort",
                                 "icon": "mdi:stop-circle"}),
            ("button", "skip_tonight", {"name": "Skip tonight",
                                        "command_topic": f"{cmd}/skip_tonight",
                                        "payload_press": "skip_tonight",
                                        "icon": "mdi:debug-step-over"}),
            ("button", "trigger", {"name": "Run a night tonight",
                                   "command_topic": f"{cmd}/trigger",
                                   "payload_press": "tonight", "icon": "mdi:play-circle"}),
            ("select", "night_kind_setting", {
                "name": "Kind of triggered night", "command_topic": f"{cmd}/night_kind",
                "state_topic": settings, "value_template": _state("kind"),
                "options": ["constrained", "normal"], "entity_category": "config"}),
            ("number", "night_setpoint_setting", {
                "name": "Setpoint of triggered night",
                "command_topic": f"{cmd}/night_setpoint", "state_topic": settings,
                "value_template": _state("setpoint_c"), "min": limits.setpoint_min_c,
                "max": limits.setpoint_max_c, "step": 0.5, "mode": "box",
                "unit_of_measurement": "°C", "device_class": "temperature",
                "entity_category": "config"}),
        ]
    return out


#: The command entities (component, key): announced with ``commands = true`` only.
COMMAND_ENTITIES = (("button", "abort"), ("button", "skip_tonight"), ("button", "trigger"),
                    ("select", "night_kind_setting"), ("number", "night_setpoint_setting"))


def withdrawn_topics(cfg: MqttConfig) -> list[str]:
    """Retained topics to clear (empty retained message) when commands are off: the command
    entities' config messages, so Home Assistant removes buttons a configuration with
    ``commands = true`` left behind, and the trigger's settings topic."""
    if cfg.commands:
        return []
    return [f"{cfg.discovery_prefix}/{component}/{cfg.client_id}/{key}/config"
            for component, key in COMMAND_ENTITIES] + [f"{cfg.topic}/settings"]


def discovery_messages(cfg: MqttConfig, device: DeviceIdentity,
                       limits: Limits) -> list[tuple[str, str]]:
    """(topic, JSON payload) of every retained discovery config message."""
    dev = {"identifiers": [f"impctl_{cfg.client_id}"], "name": f"impctl {cfg.client_id}",
           "manufacturer": "Kronoterm (via impctl)", "model": device.model,
           "sw_version": device.sw_version, "hw_version": device.link}
    origin = {"name": "impctl", "sw_version": device.sw_version}
    out = []
    for component, key, conf in entities(cfg, limits):
        payload = {**conf, "unique_id": f"impctl_{cfg.client_id}_{key}",
                   "device": dev, "origin": origin, "has_entity_name": True}
        if "availability" not in payload:
            payload.update(availability_topic=f"{cfg.topic}/availability",
                           payload_available=ONLINE, payload_not_available=OFFLINE)
        topic = f"{cfg.discovery_prefix}/{component}/{cfg.client_id}/{key}/config"
        out.append((topic, json.dumps(payload, ensure_ascii=False)))
    return out
