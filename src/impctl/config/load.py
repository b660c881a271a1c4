"""Reading and validating the gateway's ``config.toml``: every problem at once, one line
each (:class:`ConfigError`), the values checked against the heat pump's limits and each other.
"""

from __future__ import annotations

import math
import time
from dataclasses import fields
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..fit.checks.instruments import METER_ERROR_LIMITS, SENSOR_OFFSET_LIMITS_K
from ..heatpump import config_from_mapping as heatpump_from_mapping
from ..imp.gain import NIGHT_GAIN_LIMITS_W
from ..imp.protocol import EMITTER_KINDS
from ..mqtt.config import mqtt_from_mapping
from ..mqtt.inputs import inputs_from_mapping, own_topic
from ..numtext import non_ascii_problem
from .sections import (
    CampaignConfig,
    ClockConfig,
    Config,
    CurveConfig,
    FitConfig,
    NightConfig,
    RecordConfig,
    TargetHalfwidth,
    _window,
)


class ConfigError(InputError):
    """Several config problems at once; ``str()`` gives one line per problem."""

    def __init__(self, problems: list[InputError]):
        self.problems = problems
        super().__init__("\n".join(str(p) for p in problems))

    def _line(self) -> str:  # InputError formats its own line; keep the joined lines as-is
        return "\n".join(str(p) for p in self.problems)


_SECTIONS = {"night": NightConfig, "campaign": CampaignConfig, "clock": ClockConfig,
             "fit": FitConfig, "record": RecordConfig, "curve": CurveConfig}
#: Sub-tables inside a section: key → its dataclass.
_SUBTABLES = {"target_rel_halfwidth": TargetHalfwidth}
#: Operational bounds. The link-lost limit: a house with the heating off may lose ~1 K/h, so
#: an hour without readings is the most a night may run blind before it is aborted.
LINK_LOST_LIMIT_MAX_S = 3600.0
#: Fewer than half the expected samples cannot pin a night's dynamics.
MIN_COVERAGE_LOW = 0.5
#: ΔT: T_min = T_set − 3 K (18 °C from 21 °C) is the edge of EN 16798-1 category III comfort.
COMFORT_BAND_MAX_K = 3.0
#: The curve's margin [K]: 0 (the bound itself) to 5 K, as ``impctl curve --margin-k``.
CURVE_MARGIN_K = (0.0, 5.0)
#: The comfort watch's raise [K]: at least half a kelvin (less goes unnoticed by a room), at
#: most 3 K at a time (the margin again, several times over).
CURVE_RAISE_K = (0.5, 3.0)
#: How far below its setpoint the room counts as short [K]: a tenth of a kelvin is a sensor's
#: resolution, more than 2 K is a cold room, not a margin.
CURVE_SHORT_K = (0.2, 2.0)
#: Time the room may stay short before the watch raises the curve [h].
CURVE_SHORT_H = (0.25, 6.0)
#: Marker left in the problem list when [heatpump] could not be read: its safety limits are
#: unknown then, so the setpoints are not checked against the defaults (no invented problems).
_HEATPUMP_FAILED = "\0heatpump"



def _coerce(value: Any, default: Any, where: str, problems: list[str]) -> Any:
    if default is None:   # an optional number: absent = not given
        return _coerce(value, 0.0, where, problems) if value is not None else None
    if isinstance(default, bool):
        if isinstance(value, bool):
            return value
        problems.append(f"{where}: must be true or false, got {value!r}")
    elif isinstance(default, int):
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        problems.append(f"{where}: must be an integer, got {value!r}")
    elif isinstance(default, float):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if math.isfinite(value):
                return float(value)
            problems.append(f"{where}: must be a finite number, got {value!r}")
        else:
            problems.append(f"{where}: must be a number, got {value!r}")
    elif isinstance(default, str):
        if isinstance(value, str):
            return value
        problems.append(f"{where}: must be a string, got {value!r}")
    elif isinstance(default, tuple):
        if isinstance(value, list) and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in value):
            return tuple(float(v) for v in value)
        problems.append(f"{where}: must be a list of finite numbers, got {value!r}")
    return default


def _is_table(value: Any, where: str, problems: list[str], what: str = "a [table]") -> bool:
    """True if ``value`` is a TOML table; else one problem line naming ``where``."""
    if isinstance(value, dict):
        return True
    problems.append(f"{where}: must be {what}")
    return False


def _build(cls: type, data: dict, prefix: str, problems: list[str]) -> Any:
    known = {f.name: f for f in fields(cls) if f.name != "source"}
    kwargs = {}
    for key, value in data.items():
        where = f"key '{prefix}{key}'"
        if key not in known:
            problems.append(f"{where}: unknown key")
            continue
        if key == "heatpump" and cls is Config:
            if not isinstance(value, dict):
                problems.append(f"{where}: must be a [table]")
                continue
            try:
                kwargs[key] = heatpump_from_mapping(value)
            except InputError as exc:
                for p in getattr(exc, "problems", [exc]):  # every [heatpump] problem
                    problems.append(": ".join(x for x in (p.place, p.problem) if x))
                problems.append(_HEATPUMP_FAILED)
            continue
        if key == "mqtt" and cls is Config:  # [mqtt], parsed by impctl.mqtt.config
            if _is_table(value, where, problems):
                kwargs[key] = mqtt_from_mapping(value, problems)
            continue
        if key == "inputs" and cls is Config:  # [inputs], parsed by impctl.mqtt.inputs
            if _is_table(value, where, problems):
                kwargs[key] = inputs_from_mapping(value, problems, own_topic(data.get("mqtt")))
                if "mqtt" not in data:
                    problems.append(f"{where}: needs [mqtt]: the inputs are read from that "
                                    "broker")
            continue
        if key in _SECTIONS and cls is Config:
            if _is_table(value, where, problems):
                kwargs[key] = _build(_SECTIONS[key], value, f"{key}.", problems)
            continue
        if key in _SUBTABLES and cls is CampaignConfig:
            if _is_table(value, where, problems, "a table such as {hlc = 0.05, tau = 0.08}"):
                kwargs[key] = _build(_SUBTABLES[key], value, f"{prefix}{key}.", problems)
            continue
        default = known[key].default
        kwargs[key] = _coerce(value, default, where, problems)
    return cls(**kwargs)


def _check(cfg: Config, problems: list[str], limits_known: bool = True) -> None:
    night, camp = cfg.night, cfg.campaign
    lo, hi = cfg.heatpump.writes.loop1_setpoint_c

    def bad(key: str, text: str) -> None:
        problems.append(f"key '{key}': {text}")

    gain_lo, gain_hi = NIGHT_GAIN_LIMITS_W
    for key in ("night_gain_w", "night_gain_sd_w"):
        value = getattr(cfg.fit, key)
        if value is not None and not gain_lo <= value <= gain_hi:
            bad(f"fit.{key}", f"must lie in [{gain_lo:g}, {gain_hi:g}] W (≈ 75 W per "
                f"sleeper + base load), got {value:g}")
    for key, (low, high), unit in (("t_air_offset_sd_k", SENSOR_OFFSET_LIMITS_K, " K"),
                                   ("t_out_offset_sd_k", SENSOR_OFFSET_LIMITS_K, " K"),
                                   ("meter_error", METER_ERROR_LIMITS, "")):
        value = getattr(cfg.fit, key)
        if value is not None and not low <= value <= high:
            bad(f"fit.{key}", f"must lie in [{low:g}, {high:g}]{unit}, got {value:g}")
    if cfg.fit.night_gain_sd_w is not None and cfg.fit.night_gain_w is None:
        bad("fit.night_gain_sd_w", "is the SD of a declared gain: set fit.night_gain_w too")
    if cfg.fit.emitter not in ("", *EMITTER_KINDS):
        bad("fit.emitter", f"must be one of {', '.join(map(repr, EMITTER_KINDS))} (a mixed "
            f"house: 'underfloor'), got {cfg.fit.emitter!r}")
    if (cfg.inputs is not None and cfg.inputs.house_power_includes_heat_pump
            and cfg.heatpump.generation == "compact"):
        bad("inputs.house_power_includes_heat_pump", "a compact controller does not report "
            "its electrical power (register 2129 is on extended controllers only), so impctl "
            "cannot subtract it: give a meter that excludes the heat pump and set false")
    for key, (low, high) in (("margin_k", CURVE_MARGIN_K), ("raise_k", CURVE_RAISE_K),
                             ("short_k", CURVE_SHORT_K), ("short_h", CURVE_SHORT_H)):
        value = getattr(cfg.curve, key)
        if not low <= value <= high:
            bad(f"curve.{key}", f"must lie in [{low:g}, {high:g}], got {value:g}")
    if cfg.heatpump.writes.daily_budget < 4:
        bad("heatpump.writes.daily_budget", "must allow at least 4 writes (a night needs them)")
    window = None
    try:
        window = _window(night.window)
        if window[0] == window[1]:
            bad("night.window", "start and end are the same")
    except ValueError:
        bad("night.window", non_ascii_problem(night.window)
            or f"expected HH:MM-HH:MM, got {night.window!r}")
    if not 0 < night.max_comfort_band_k <= COMFORT_BAND_MAX_K:
        bad("night.max_comfort_band_k",
            f"must lie in (0, {COMFORT_BAND_MAX_K:g}] K: further below the owner's setpoint a "
            "home is no longer comfortable")
    if not 0 < night.comfort_band_k <= night.max_comfort_band_k:
        bad("night.comfort_band_k",
            f"must lie in (0, {night.max_comfort_band_k:g}] K (night.max_comfort_band_k)")
    if not 5 <= night.sample_interval_s <= 900:
        bad("night.sample_interval_s", "must lie in 5–900 s")
    if night.abort_margin_k < 0 or night.abort_margin_k > 2:
        bad("night.abort_margin_k", "must lie in 0–2 K")
    if night.link_lost_limit_s < night.sample_interval_s:
        bad("night.link_lost_limit_s", "must be at least night.sample_interval_s")
    elif night.link_lost_limit_s > LINK_LOST_LIMIT_MAX_S:
        bad("night.link_lost_limit_s",
            f"must be at most {LINK_LOST_LIMIT_MAX_S:g} s: a night with the heating off is never "
            "left unwatched longer")
    if night.constrained_action not in ("loop_off", "setpoint_floor"):
        bad("night.constrained_action", "must be 'loop_off' or 'setpoint_floor'")
    if limits_known and not lo <= night.setpoint_floor_c <= hi:
        bad("night.setpoint_floor_c",
            f"must lie within heatpump.writes.loop1_setpoint_c = [{lo:g}, {hi:g}] °C")
    if not MIN_COVERAGE_LOW <= night.min_coverage <= 1:
        bad("night.min_coverage", f"must lie in [{MIN_COVERAGE_LOW:g}, 1]: a night with less "
                                  "than half its samples is not data")
    if night.t_out_min_c >= night.t_out_max_c:
        bad("night.t_out_max_c", "must be above night.t_out_min_c")
    if not 0 <= night.emission_lag_h <= 6:
        bad("night.emission_lag_h", "must lie in 0–6 h")
    if camp.misfire_grace_s < 1:  # the scheduler's grace: a whole, positive number of s
        bad("campaign.misfire_grace_s", "must be at least 1 s")
    if cfg.clock.epoch:
        try:
            aware = datetime.fromisoformat(cfg.clock.epoch).tzinfo is not None
        except ValueError:
            aware = None
        if not aware:
            bad("clock.epoch", "must be an ISO 8601 instant with its zone, e.g. "
                               f"2026-01-12T20:00:00+01:00, got {cfg.clock.epoch!r}")
    if cfg.clock.wall_epoch_s < 0:
        bad("clock.wall_epoch_s", "must be >= 0 (POSIX seconds; 0 = at start)")
    elif cfg.clock.epoch and aware and cfg.clock.speed > 0 and cfg.clock.wall_epoch_s > 0:
        # An accelerated clock started long ago runs past the calendar (wall_epoch_s = 1 at
        # 600× is the year 36,000): refuse it here rather than crash at the first reading.
        try:
            sim_s = datetime.fromisoformat(cfg.clock.epoch).timestamp() + (
                time.time() - cfg.clock.wall_epoch_s) * cfg.clock.speed
            datetime.fromtimestamp(sim_s, UTC) + timedelta(days=366)
            datetime.fromtimestamp(sim_s, UTC) - timedelta(days=366)
        except (OverflowError, ValueError, OSError):
            bad("clock.wall_epoch_s", f"{cfg.clock.wall_epoch_s:g} s at clock.speed "
                f"{cfg.clock.speed:g}× puts the simulated clock outside the calendar; use 0 "
                "(= at start) or the POSIX second at which the clock showed clock.epoch")
    band = night.comfort_band_k
    setpoints = [("campaign.constrained_setpoint_c", camp.constrained_setpoint_c)]
    setpoints += [("campaign.normal_setpoints_c", sp) for sp in camp.normal_setpoints_c]
    for key, sp in setpoints if limits_known else ():
        if not lo <= sp <= hi:
            bad(key, f"{sp:g} °C is outside the safety limits heatpump.writes.loop1_setpoint_c "
                     f"= [{lo:g}, {hi:g}] °C")
    if limits_known and camp.constrained_setpoint_c + band > hi:
        bad("campaign.constrained_setpoint_c",
            f"T_max = T_set + ΔT = {camp.constrained_setpoint_c + band:g} °C exceeds the "
            f"safety limit {hi:g} °C")
    if camp.constrained_setpoint_c - band - night.abort_margin_k < 14.0:
        bad("night.comfort_band_k", "T_min − abort margin would fall below 14 °C")
    if camp.constrained_nights < 0 or camp.normal_nights_per_setpoint < 0:
        bad("campaign.constrained_nights", "night counts must be >= 0")
    _check_adaptive(camp, bad)
    _check_record(cfg, bad)
    from .bounds import bound_problems  # the upper bounds, each with its reason

    bound_problems(cfg, window, bad)
    if cfg.clock.speed <= 0:
        bad("clock.speed", "must be > 0")
    if cfg.log_level.lower() not in ("debug", "info", "warning", "error"):
        bad("log_level", "must be debug, info, warning or error")
    try:
        from zoneinfo import ZoneInfo

        ZoneInfo(cfg.timezone)
    except Exception:
        bad("timezone", f"unknown time zone {cfg.timezone!r}")


def _check_adaptive(camp: CampaignConfig, bad) -> None:
    if camp.mode not in ("adaptive", "fixed"):
        bad("campaign.mode", f"must be 'adaptive' or 'fixed', got {camp.mode!r}")
    for name in ("hlc", "tau"):
        value = getattr(camp.target_rel_halfwidth, name)
        if not 0 < value < 1:
            bad(f"campaign.target_rel_halfwidth.{name}",
                f"must lie in (0, 1) (0.05 = ±5 % of the estimate), got {value:g}")
    if camp.min_each_kind < 1:
        bad("campaign.min_each_kind", "must be >= 1: a fit needs a night of each kind")
    if camp.max_nights < 2 * camp.min_each_kind:
        bad("campaign.max_nights", f"must be at least 2 × campaign.min_each_kind = "
                                   f"{2 * camp.min_each_kind} (a night of each kind)")
    if camp.stall_nights < 1:
        bad("campaign.stall_nights", "must be >= 1")
    if camp.max_invalid_nights < 1:
        bad("campaign.max_invalid_nights", "must be >= 1")
    if camp.next_night not in ("plan", "information"):
        bad("campaign.next_night", f"must be 'plan' or 'information', got {camp.next_night!r}")
    if camp.mode == "adaptive" and not camp.normal_setpoints_c:
        bad("campaign.normal_setpoints_c", "the adaptive campaign needs at least one normal "
                                           "setpoint to choose from")


#: ``[record] interval_s`` [s]: a row of at least a minute, at most an hour (the house's heat
#: store moves over hours; an hour's mean still shows a day's course). A divisor of an hour, so
#: rows start on the hour and at local noon, where an owner record starts.
RECORD_INTERVAL_S = (60.0, 3600.0)
#: ``[record] keep_days``: at least a day; at most ten years (a season is ~200 days; the store
#: grows by about 3.7 MB per 100 days at the defaults, docs/explanation/benchmarks.md).
RECORD_KEEP_DAYS = (1, 3660)


def _check_record(cfg: Config, bad) -> None:
    rec = cfg.record
    lo, hi = RECORD_INTERVAL_S
    if not lo <= rec.interval_s <= hi or 3600.0 % rec.interval_s:
        bad("record.interval_s", f"must lie in {lo:g}–{hi:g} s and divide an hour (60, 300, "
            f"600, 900, 1800, 3600 …), got {rec.interval_s:g}")
    if rec.sample_interval_s is not None and not 5 <= rec.sample_interval_s <= 900:
        bad("record.sample_interval_s", "must lie in 5–900 s")
    k_lo, k_hi = RECORD_KEEP_DAYS
    if not k_lo <= rec.keep_days <= k_hi:
        bad("record.keep_days", f"must lie in {k_lo}–{k_hi} days, got {rec.keep_days}")


def config_from_mapping(data: dict, source: str | Path | None = None) -> Config:
    """Validate a parsed TOML mapping; raises :class:`ConfigError` listing every problem."""
    problems: list[str] = []
    if "heatpump" not in data:
        # Never a silent default address: the daemon would drive whatever answers there.
        problems += ["[heatpump]: missing section: set transport and host (tcp) or serial_port "
                     "(rtu) of the heat pump", _HEATPUMP_FAILED]
    cfg = _build(Config, data, "", problems)
    # Check the values too when some keys were bad (those fell back to their defaults), so
    # one run lists every problem, one line each.
    limits_known = _HEATPUMP_FAILED not in problems
    problems = [p for p in problems if p != _HEATPUMP_FAILED]
    _check(cfg, problems, limits_known)
    if problems:
        raise ConfigError([InputError(p, source) for p in problems])
    return Config(**{**{f.name: getattr(cfg, f.name) for f in fields(Config)},
                     "source": str(source or "")})


def read_config_toml(path: str | Path) -> dict:
    """Parse the TOML file; a UTF-8 byte-order mark (Windows editors write one) is accepted."""
    import tomllib

    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path) from None
    try:
        return tomllib.loads(raw.decode("utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid TOML: {exc}", path) from None


def config_warnings(cfg: Config) -> list[str]:
    """What a valid configuration allows but should not (one line each, for the log and
    ``impctl check-config``): an MQTT password file or client key other users can read, an
    MQTT password sent over the network in clear text."""
    return cfg.mqtt.warnings() if cfg.mqtt is not None else []


def load_config(path: str | Path) -> Config:
    """Read and validate the daemon configuration file."""
    return config_from_mapping(read_config_toml(path), Path(path))
