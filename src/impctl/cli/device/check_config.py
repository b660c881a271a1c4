"""``impctl check-config``: every problem of a configuration at once, and what the daemon would
do with it at the next night — before anything touches the heat pump."""

from __future__ import annotations

import os
from pathlib import Path
from zoneinfo import ZoneInfo

import click

from ...errors import InputError
from .. import cli
from .inputs_status import describe_inputs
from .options import config_option


def state_dir_problem(state_dir: str | Path) -> str | None:
    """Why the daemon could not keep its store in ``state_dir``, or None.

    Checked without creating anything: an existing directory must be writable; a missing one
    must be creatable (its nearest existing parent a writable directory, not on /proc or /sys).
    """
    path = Path(state_dir)
    if not path.is_absolute():
        return "must be an absolute path (systemd starts the daemon in /)"
    if path.exists():
        if not path.is_dir():
            return "is a file, not a directory"
        if not os.access(path, os.W_OK | os.X_OK):
            return "is not writable by this user"
        return None
    parent = path.parent
    while not parent.exists():
        parent = parent.parent
    if parent.parts[:2] in (("/", "proc"), ("/", "sys")):
        return f"lies on the kernel's virtual file system {'/'.join(parent.parts[:2])[1:]}"
    if not parent.is_dir():
        return f"cannot be created: {parent} is a file"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"cannot be created by this user ({parent} is not writable)"
    return None


def _tonight(cfg, store) -> list[str]:
    """What the next night would do, as lines for people."""
    from ...daemon.configured import clock_from_config
    from ...daemon.nights.next_night import peek_next_night, why_no_night
    from ...daemon.nights.schedule import next_act_time

    tz = ZoneInfo(cfg.timezone)
    act = next_act_time(cfg, clock_from_config(cfg).now())
    req, request_id = peek_next_night(store, cfg, act)
    if req is None:
        return [f"nothing at the next night ({act.astimezone(tz):%Y-%m-%d}): "
                + why_no_night(store, cfg)]
    n = cfg.night
    origin = f"manual request {request_id}" if request_id is not None else "the campaign"
    start, end = req.window_start.astimezone(tz), req.window_end.astimezone(tz)
    lines = [f"{req.kind} night from {origin}, window {start:%Y-%m-%d %H:%M}–{end:%H:%M %Z}"]
    if req.kind == "constrained":
        off = ("loop-1 mode 0 (heating off, hot water unaffected)"
               if n.constrained_action == "loop_off"
               else f"loop-1 setpoint {n.setpoint_floor_c:g} °C")
        lines += [f"  {act.astimezone(tz):%H:%M} preheat: loop-1 setpoint {req.t_max_c:g} °C "
                  "(T_set + ΔT)",
                  f"  {start:%H:%M} switch-off: {off}, until T_air reaches T_min "
                  f"{req.t_min_c:g} °C or the window ends"]
    else:
        lines.append(f"  {act.astimezone(tz):%H:%M} loop-1 setpoint {req.setpoint_c:g} °C, held "
                     "through the window; heat output measured")
    floor = req.t_min_c - n.abort_margin_k
    lines += [f"  aborts below {floor:g} °C indoors (or the owner's setpoint − ΔT − margin, if "
              f"lower), without readings for {n.link_lost_limit_s:g} s, on any heat-pump error",
              f"  refused unless the outdoor temperature lies in {n.t_out_min_c:g}…"
              f"{n.t_out_max_c:g} °C and the heat pump is on, error-free, not in defrost",
              "  then the owner's loop-1 setpoint and mode are restored and verified "
              "(at most 4 writes, budget "
              f"{cfg.heatpump.writes.daily_budget}/register/day)"]
    return lines


def _describe(cfg) -> list[str]:
    hp = cfg.heatpump
    meter = ("heat meter " + hp.heat_meter.describe()) if hp.heat_meter else (
        "register 2329 (extended controllers only; a compact one refuses IMP nights)")
    room = hp.room_sensor if isinstance(hp.room_sensor, str) else (
        "external " + hp.room_sensor.describe())
    lo, hi = hp.writes.loop1_setpoint_c
    return [f"heat pump: {hp.link.describe()}, generation {hp.generation}",
            f"sensors:   T_air from {room}, Q_HC from {meter}",
            f"writes:    loop-1 setpoint clamped to [{lo:g}, {hi:g}] °C, "
            f"{hp.writes.daily_budget} writes/register/day (+{hp.writes.restore_reserve} "
            "for restores only)",
            f"nights:    {cfg.night.window} {cfg.timezone}, ΔT {cfg.night.comfort_band_k:g} K, "
            f"a sample every {cfg.night.sample_interval_s:g} s",
            "campaign:  " + _campaign_line(cfg.campaign),
            "recording: " + _record_line(cfg),
            "inputs:    " + describe_inputs(cfg.inputs)]


def _record_line(cfg) -> str:
    rec = cfg.record
    if not rec.enabled:
        return "off (record.enabled = false): nothing recorded between nights"
    return (f"the house between nights, read-only: a snapshot every "
            f"{rec.snapshot_interval_s(cfg.night):g} s, rows of {rec.interval_s:g} s, owner "
            f"records kept {rec.keep_days} days")


def _campaign_line(camp) -> str:
    if not camp.enabled:
        return "disabled (manual nights only)"
    if camp.adaptive:
        t = camp.target_rel_halfwidth
        return (f"adaptive: until HLC ±{t.hlc:.0%} and τ ±{t.tau:.0%}, at most "
                f"{camp.max_nights} nights, a fit after every valid night")
    normal = len(camp.normal_setpoints_c) * camp.normal_nights_per_setpoint
    return (f"fixed: {camp.constrained_nights} constrained + {normal} normal valid nights, "
            f"{'a fit after every valid night' if camp.fit_when_complete else 'no fit'}")


@cli.command("check-config")
@config_option
def check_config_command(config_path: Path) -> None:
    """Check a configuration: every problem at once (exit 2), else what the daemon would do
    at the next night. Touches nothing: no heat pump, no store created."""
    from ...config import ConfigError, config_warnings, load_config, read_config_toml
    from ...daemon.locks.store import probe
    from ...store import Store

    problems: list[InputError] = []
    cfg = None
    try:
        cfg = load_config(config_path)
    except ConfigError as exc:
        problems += exc.problems
    except InputError as exc:  # not found, not TOML: nothing more to check
        raise exc from None
    if cfg is not None:
        state_dir = cfg.state_dir
    else:
        raw = read_config_toml(config_path).get("state_dir", "/var/lib/impctl")
        state_dir = raw if isinstance(raw, str) else None
    if state_dir is not None:
        problem = state_dir_problem(state_dir)
        if problem:
            problems.append(InputError(f"{state_dir} {problem}", config_path,
                                       "key 'state_dir'"))
    if problems:
        raise ConfigError(problems)
    lines = [f"config:    {config_path}: no problem found", *_describe(cfg)]
    lines += [f"warning:   {text}" for text in config_warnings(cfg)]
    lines.append(f"daemon:    {probe(cfg.state_dir).describe()}")
    offset = None
    if cfg.db_path.exists():
        with Store(cfg.db_path, create=False) as store:
            tonight = _tonight(cfg, store)
            offset = store.outdoor_offset() if (
                cfg.inputs is not None and cfg.inputs.outdoor_temperature_c) else None
        if offset is not None:  # the outdoor reference against the heat pump's sensor
            lines.append(("WARNING:   " if offset.persistent else "outdoor:   ")
                         + offset.describe())
    else:
        lines.append(f"store:     {cfg.db_path} (created when the daemon first starts)")
        tonight = _tonight(cfg, _NoStore())
    lines.append("next:      " + tonight[0])
    lines += ["           " + line for line in tonight[1:]]
    click.echo("\n".join(lines))


class _NoStore:
    """Stands in for a store that does not exist yet: no requests, no campaign progress."""

    def pending_requests(self) -> list:
        return []

    def campaign(self) -> list:
        return []

    def nights(self, **_filters) -> list:  # the adaptive campaign's history: none yet
        return []

    def fits(self) -> list:
        return []

    def night_t_out_means(self) -> dict:
        return {}
