"""The ``[inputs]`` section: what the house already measures, read from MQTT topics.

Each input is a topic carrying one plain number, the way Home Assistant's ``mqtt_statestream``
publishes an entity's state (``homeassistant/sensor/house_power/state`` → ``523.4``, retained).
Every input is optional. A payload that is not a plausible plain number in the stated unit
(text, NaN, a unit suffix, JSON, a power that looks like kW) is a missing value, never a
number: :func:`parse_payload` says why, the daemon logs it once.

Units: W, °C, persons; ages and limits in s.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, fields
from typing import Any

from ..numtext import non_ascii_problem

#: Topic names: no MQTT wildcards, no empty level, no spaces.
_TOPIC = re.compile(r"^[^#+/\s]+(/[^#+/\s]+)*$")
#: A plain decimal number, as Home Assistant writes a sensor's state ("523.4", "-3", "1e3").
#: ASCII digits only: ``\d`` and ``float()`` would take '٢٢' or '２２' as 22.
_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$", re.ASCII)
#: States Home Assistant publishes for an entity without a value: missing, not a problem.
HA_NO_VALUE = frozenset({"unavailable", "unknown", "none", "null", ""})

#: Plausible ranges per input: (low, high, unit). Outside them a value is refused.
#: Household electricity: below 20 W is not a lived-in home at night (fridge, router and
#: standby alone draw more) but is what a kW reading looks like; 30 kW is above a 3 × 32 A
#: supply's continuous draw.
HOUSE_POWER_W = (20.0, 30_000.0, "W")
#: A heated room at night; outside this the sensor is outdoors, in a freezer or broken.
ROOM_TEMPERATURE_C = (0.0, 40.0, "°C")
#: Outdoor air, beyond the records of any place with a heat pump.
OUTDOOR_TEMPERATURE_C = (-50.0, 50.0, "°C")
#: People at home.
OCCUPANTS = (0.0, 30.0, "persons")
#: Bounds of the staleness limits [s].
MAX_AGE_BOUNDS_S = (60.0, 86_400.0)
OCCUPANTS_MAX_AGE_BOUNDS_S = (60.0, 7 * 86_400.0)


@dataclass(frozen=True)
class InputsConfig:
    """``[inputs]``: MQTT topics of values the house already measures (all optional).

    Attributes
    ----------
    house_power_w : topic of the household's electricity [W] (a smart meter, a clamp)
    house_power_includes_heat_pump : the meter also sees the heat pump; impctl subtracts the
        heat pump's own electrical power (Kronoterm register 2129, extended controllers) at
        each sample to get ``p_house_w``
    room_temperature_c : topics of room temperature sensors [°C]; their mean is ``t_rooms_c``
    outdoor_temperature_c : topic of an outdoor temperature [°C] (a weather station or
        service), ``t_out_ref_c``: checks the heat pump's own outdoor sensor
    occupants : topic of the number of people at home
    max_age_s : a value older than this when a sample is taken counts as missing [s]
    occupants_max_age_s : the same for ``occupants``, which Home Assistant republishes only
        when it changes (a household asleep for 8 h keeps the same count) [s]
    """

    house_power_w: str = ""
    house_power_includes_heat_pump: bool = False
    room_temperature_c: tuple[str, ...] = ()
    outdoor_temperature_c: str = ""
    occupants: str = ""
    max_age_s: float = 3600.0
    occupants_max_age_s: float = 86_400.0

    def topics(self) -> dict[str, str]:
        """Topic → input name (``house_power_w``, ``room_temperature_c:<i>``, …)."""
        out = {}
        for name in ("house_power_w", "outdoor_temperature_c", "occupants"):
            if getattr(self, name):
                out[getattr(self, name)] = name
        for i, topic in enumerate(self.room_temperature_c):
            out[topic] = f"room_temperature_c:{i}"
        return out


def _bounds(name: str) -> tuple[float, float, str]:
    if name == "house_power_w":
        return HOUSE_POWER_W
    if name.startswith("room_temperature_c"):
        return ROOM_TEMPERATURE_C
    if name == "outdoor_temperature_c":
        return OUTDOOR_TEMPERATURE_C
    return OCCUPANTS


def parse_payload(name: str, payload: bytes) -> tuple[float | None, str | None]:
    """One MQTT payload of input ``name`` → (value, problem).

    ``(x, None)`` for a plausible plain number; ``(None, None)`` for Home Assistant's
    ``unavailable`` / ``unknown`` (and an empty payload): missing, nothing wrong with the
    publisher; ``(None, why)`` for anything else.
    """
    try:
        text = payload.decode("utf-8").strip()
    except UnicodeDecodeError:
        return None, "not UTF-8 text"
    if text.lower() in HA_NO_VALUE:
        return None, None
    shown = text if len(text) <= 40 else text[:37] + "..."
    if not _NUMBER.match(text):
        if text.lower() in ("nan", "+nan", "-nan", "inf", "+inf", "-inf", "infinity"):
            return None, f"{shown!r} is not a finite number"
        if text[:1] in "{[\"":
            return None, (f"{shown!r} is JSON; publish the plain number (Home Assistant's "
                          "mqtt_statestream does)")
        m = re.match(r"^([+-]?[\d.]+(?:[eE][+-]?\d+)?)\s*([A-Za-z°%/]+)$", text, re.ASCII)
        if m:
            return None, (f"{shown!r} carries a unit; publish the plain number in "
                          f"{_bounds(name)[2]}")
        if (ascii_problem := non_ascii_problem(text)) is not None:
            return None, ascii_problem
        return None, f"{shown!r} is not a number"
    value = float(text)
    if not math.isfinite(value):
        return None, f"{shown!r} is not a finite number"
    lo, hi, unit = _bounds(name)
    if name == "house_power_w" and value < 0:
        return None, (f"{value:g} W is negative: a grid meter behind PV or a battery is not "
                      "the house's consumption")
    if name == "house_power_w" and 0 < value < lo:
        return None, (f"{value:g} looks like kW (below {lo:g} W no lived-in home draws at "
                      "night); publish the power in W")
    if not lo <= value <= hi:
        return None, f"{value:g} {unit} is outside the plausible {lo:g}…{hi:g} {unit}"
    if name == "occupants" and value != round(value):
        return None, f"{value:g} is not a whole number of people"
    return value, None


def _topic_list(value: Any, where: str, problems: list[str]) -> tuple[str, ...]:
    if isinstance(value, str):
        return (value,) if value else ()
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        return tuple(value)
    problems.append(f"{where}: must be a topic or a list of topics, got {value!r}")
    return ()


def inputs_from_mapping(data: dict, problems: list[str], own_topic: str | None = None,
                        prefix: str = "inputs.") -> InputsConfig:
    """Build :class:`InputsConfig` from the ``[inputs]`` table; appends one line per problem
    (``key 'inputs.max_age_s': …``) to ``problems``. ``own_topic`` is impctl's base topic
    (no input may be read from under it)."""
    defaults = {f.name: f.default for f in fields(InputsConfig)}
    kwargs: dict[str, Any] = {}

    def bad(key: str, text: str) -> None:
        problems.append(f"key '{prefix}{key}': {text}")

    for key, value in data.items():
        where = f"key '{prefix}{key}'"
        if key not in defaults:
            problems.append(f"{where}: unknown key")
        elif key == "room_temperature_c":
            kwargs[key] = _topic_list(value, where, problems)
        elif key == "house_power_includes_heat_pump":
            if isinstance(value, bool):
                kwargs[key] = value
            else:
                bad(key, f"must be true or false, got {value!r}")
        elif key in ("max_age_s", "occupants_max_age_s"):
            if isinstance(value, (int, float)) and not isinstance(value, bool) and (
                    math.isfinite(value)):
                kwargs[key] = float(value)
            else:
                bad(key, f"must be a finite number of seconds, got {value!r}")
        elif isinstance(value, str):
            kwargs[key] = value
        else:
            bad(key, f"must be a topic (a string), got {value!r}")
    cfg = InputsConfig(**kwargs)
    seen: dict[str, str] = {}
    named = [(k, getattr(cfg, k)) for k in ("house_power_w", "outdoor_temperature_c",
                                             "occupants")]
    named += [("room_temperature_c", t) for t in cfg.room_temperature_c]
    for key, topic in named:
        if not topic:
            continue
        if not _TOPIC.match(topic):
            bad(key, f"must be a topic without wildcards (+ #), spaces or empty levels, "
                     f"got {topic!r}")
        elif own_topic and (topic == own_topic or topic.startswith(own_topic + "/")):
            bad(key, f"{topic!r} lies under impctl's own topic {own_topic}/")
        elif topic in seen:
            bad(key, f"{topic!r} is also {prefix}{seen[topic]}: one topic, one input")
        seen.setdefault(topic, key)
    if cfg.house_power_includes_heat_pump and not cfg.house_power_w:
        bad("house_power_includes_heat_pump", "needs inputs.house_power_w")
    for key, (lo, hi) in (("max_age_s", MAX_AGE_BOUNDS_S),
                          ("occupants_max_age_s", OCCUPANTS_MAX_AGE_BOUNDS_S)):
        value = getattr(cfg, key)
        if not lo <= value <= hi:
            bad(key, f"must lie in {lo:g}–{hi:g} s, got {value:g}")
    return cfg


def own_topic(mqtt: Any) -> str | None:
    """impctl's base topic from the raw ``[mqtt]`` table (as :class:`MqttConfig.topic`)."""
    if not isinstance(mqtt, dict):
        return None
    base = mqtt.get("base_topic")
    if isinstance(base, str) and base:
        return base
    client = mqtt.get("client_id")
    if not isinstance(client, str) or not client:
        from .config import default_client_id

        client = default_client_id()
    return f"impctl/{client}"
