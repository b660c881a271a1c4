"""Device-side commands: daemon, trigger, status, nights, export (restore: :mod:`.restore_cmd`).

None of these import torch, scikit-learn or pandas at module level (export imports pandas
only when it runs).
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import sys
from datetime import datetime
from pathlib import Path
from zoneinfo import ZoneInfo

import click

from ...errors import InputError
from ...numtext import non_ascii_problem, parse_int
from .. import cli
from .options import config_option


def _load(config_path: Path):
    from ...config import config_warnings, load_config

    cfg = load_config(config_path)
    for text in config_warnings(cfg):
        click.echo(f"impctl: warning: {text}", err=True)
    return cfg


def _setup_logging(level: str, timezone: str = "UTC") -> None:
    # Under systemd (JOURNAL_STREAM set) journald adds timestamps; a <N> prefix sets priority.
    journald = "JOURNAL_STREAM" in os.environ
    fmt = "%(levelname)s %(name)s: %(message)s" if journald else (
        "%(asctime)s %(levelname)s %(name)s: %(message)s")
    zone = ZoneInfo(timezone)

    class _Prio(logging.Formatter):
        def formatTime(self, record: logging.LogRecord, datefmt: str | None = None) -> str:
            # Local time of the configured zone WITH its offset, like the messages' times.
            return datetime.fromtimestamp(record.created, zone).isoformat(
                timespec="milliseconds")

        def format(self, record: logging.LogRecord) -> str:
            text = super().format(record)
            if not journald:
                return text
            prio = {logging.DEBUG: 7, logging.INFO: 6, logging.WARNING: 4,
                    logging.ERROR: 3, logging.CRITICAL: 2}.get(record.levelno, 6)
            return f"<{prio}>{text}"

    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_Prio(fmt))
    logging.basicConfig(level=level.upper(), handlers=[handler], force=True)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    logging.getLogger("apscheduler").setLevel(logging.WARNING)  # one line per job run is noise


@cli.command("daemon")
@config_option
def daemon_command(config_path: Path) -> None:
    """Run the impctl service (systemd Type=notify): schedule and run IMP nights."""
    from ...daemon.service import Daemon

    cfg = _load(config_path)
    _setup_logging(cfg.log_level, cfg.timezone)
    sys.exit(asyncio.run(Daemon(cfg).run()))


@cli.command("trigger")
@config_option
@click.option("--kind", type=click.Choice(["constrained", "normal"]), default=None,
              help="Heating off (constrained) or held at the setpoint (normal). Required "
                   "unless --cancel.")
@click.option("--setpoint", type=float, default=None,
              help="T_set [°C] (default: the campaign's constrained setpoint).")
@click.option("--tonight", is_flag=True, help="Run at the next night window (the default).")
@click.option("--now", is_flag=True,
              help="Start now: the preheat, then the night until the night window ends "
                   "(at least 3 h of it must be left); outside the window and its preheat "
                   "only with --force.")
@click.option("--expires-h", "expires_h", type=float, default=None,
              help="Drop the request unstarted after this many hours of real time [h] "
                   "(default: 1 h for --now; the end of the next night for --tonight).")
@click.option("--force", is_flag=True,
              help="Allow a --now night in daytime, or with less than 3 h of the window "
                   "left: the preheat, then a whole window's length.")
@click.option("--cancel", is_flag=True,
              help="Cancel every request not yet started, and a waiting skip of the next "
                   "night.")
@click.option("--foreground", is_flag=True,
              help="Run one night in this process, without a daemon (Ctrl-C, or the "
                   "terminal closing, restores).")
def trigger_command(config_path: Path, kind: str | None, setpoint: float | None,
                    tonight: bool, now: bool, expires_h: float | None, force: bool,
                    cancel: bool, foreground: bool) -> None:
    """Queue a manual IMP night for the running daemon (or run one in the foreground).

    A request identical to one already waiting (kind, setpoint, --now/--tonight) is not
    queued twice: the waiting one stands.
    """
    from ...daemon.configured import clock_from_config
    from ...daemon.locks.store import DaemonLock, probe
    from ...daemon.nights.schedule import request_expiry
    from ...store import Store

    cfg = _load(config_path)
    if cancel:
        if kind or now or tonight or foreground or setpoint is not None:
            raise InputError("--cancel takes no other option", place="--cancel")
        _cancel_requests(cfg)
        return
    if kind is None:
        raise InputError("missing --kind constrained|normal", place="--kind")
    if now and tonight:
        raise InputError("--now and --tonight are mutually exclusive; choose one",
                         place="--now/--tonight")
    if expires_h is not None and not (0 < expires_h <= 72):
        raise InputError(f"{expires_h:g} h: must lie in (0, 72] h", place="--expires-h")
    when = "now" if now else "tonight"
    sp = cfg.campaign.constrained_setpoint_c if setpoint is None else setpoint
    lo, hi = cfg.heatpump.writes.loop1_setpoint_c
    band = cfg.night.comfort_band_k
    top = sp + band if kind == "constrained" else sp
    if not lo <= sp <= hi or top > hi:
        raise InputError(f"setpoint {sp:g} °C (top {top:g} °C) outside the safety limits "
                         f"[{lo:g}, {hi:g}] °C", place="--setpoint")
    clock = clock_from_config(cfg)
    from ...daemon.nights.schedule import daytime_reason, now_window

    daytime = daytime_reason(cfg, clock.now())
    if when == "now" and daytime and not force:
        raise InputError(f"{daytime}: a --now night would run in daytime; add --force to run "
                         "it anyway, or use --tonight", place="--now")
    if when == "now" and not force:
        window = now_window(cfg, clock.now(), False)
        if isinstance(window, str):   # too little of the window left: it would end at once
            raise InputError(f"{window}; add --force to run a whole night from now, or use "
                             "--tonight", place="--now")
    if foreground:
        _setup_logging(cfg.log_level, cfg.timezone)
        with Store(cfg.db_path):  # creates the state directory, or one clear line
            pass
        from ...daemon.locks.heat_pump import HeatPumpLock

        role = "trigger --foreground"
        with DaemonLock(cfg.state_dir, role=role) as lock, \
                HeatPumpLock(cfg.heatpump.link, cfg.state_dir, role=role):
            sys.exit(asyncio.run(_foreground_night(cfg, kind, sp, when, lock, force)))
    from ...daemon.nights.waiting import describe_queued, queue_night

    expires = request_expiry(cfg, clock, when, expires_h)
    with Store(cfg.db_path) as store:
        rid, joined = queue_night(store, kind, sp, when, expires,
                                  forced=force and when == "now")
        if joined:  # the waiting request's expiry, maybe later than this one's
            expires = next((r.expires for r in store.pending_requests() if r.id == rid),
                           None) or expires
    tz = ZoneInfo(cfg.timezone)
    click.echo(f"{describe_queued(rid, joined, kind, sp, when)} for the daemon; "
               f"expires unstarted at {expires.astimezone(tz):%Y-%m-%d %H:%M %Z}")
    info = probe(cfg.state_dir)
    if not info.running or info.stale:
        click.echo(f"impctl: warning: daemon {info.describe()}; the request waits until a "
                   f"daemon starts on {cfg.state_dir} (cancel it with impctl trigger --cancel)",
                   err=True)


def _cancel_requests(cfg) -> None:
    from ...store import Store

    if not cfg.db_path.exists():
        click.echo("nothing to cancel (no store yet)")
        return
    from ...daemon.nights.waiting import cancel_waiting

    with Store(cfg.db_path) as store:
        done, skips = cancel_waiting(store)
    if not done and not skips:
        click.echo("nothing to cancel: no request or skip is waiting (a night already running "
                   "is stopped with systemctl restart impctl, which restores)")
        return
    for r in done:
        click.echo(f"cancelled request {r.id}: {r.kind} night ({r.when})")
    for c in skips:
        click.echo(f"cancelled skip {c.id} ({c.source}): the next night runs as planned")


async def _foreground_night(cfg, kind: str, sp: float, when: str, lock,
                            force: bool = False) -> int:
    import signal

    from ...daemon.locks.store import HEARTBEAT_S

    async def heartbeat() -> None:  # `impctl status` shows this process as alive
        while True:
            lock.heartbeat()
            await asyncio.sleep(HEARTBEAT_S)

    from ...controller import NightController, NightRefused, NightRequest
    from ...daemon.configured import clock_from_config, open_client, policy_from_config
    from ...daemon.nights.schedule import next_act_time, now_window, window_after_act
    from ...store import Store

    clock = clock_from_config(cfg)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    # SIGHUP: the terminal or SSH session of a foreground night went away; by default it
    # would end the process at once, the heating as the night left it
    for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        loop.add_signal_handler(sig, stop.set)
    with Store(cfg.db_path) as store:
        client = open_client(cfg, clock)
        await client.connect(max_wait_s=60.0)
        try:
            if when == "now":
                window = now_window(cfg, clock.now(), force)
                if isinstance(window, str):
                    raise InputError(window, place="--now")
                start, end = window
            else:
                start, end = window_after_act(next_act_time(cfg, clock.now()), cfg)
            ctl = NightController(client, store, clock, policy_from_config(cfg),
                                  on_status=lambda t: click.echo(t, err=True), stop=stop)
            beat = asyncio.create_task(heartbeat())
            try:
                night = await ctl.run(NightRequest(kind, sp, start, end,
                                                   cfg.night.comfort_band_k, source="trigger"))
            except NightRefused as exc:  # not even created: the store cannot record
                click.echo(f"impctl: night not started: {exc}", err=True)
                return 1
            finally:
                beat.cancel()
        finally:
            client.close()
    click.echo(f"night {night.id}: {night.state}, {'valid' if night.valid else 'not valid'}"
               f" — {'; '.join(night.reasons)}")
    return 0 if night.state in ("done", "aborted", "refused") else 1


@cli.command("status")
@config_option
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
def status_command(config_path: Path, as_json: bool) -> None:
    """Current night and live values, campaign progress, last fit, link health, writes."""
    from .status import collect_status, format_status

    cfg = _load(config_path)
    status = collect_status(cfg)
    click.echo(json.dumps(status, indent=2, default=str) if as_json
               else format_status(status, cfg.timezone))


@cli.command("nights")
@config_option
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
def nights_command(config_path: Path, as_json: bool) -> None:
    """List the stored nights with their validity and reasons."""
    from ...store import Store

    cfg = _load(config_path)
    tz = ZoneInfo(cfg.timezone)
    with Store(cfg.db_path, create=False) as store:
        rows = [(n, store.sample_count(n.id)) for n in store.nights()]
    if as_json:
        click.echo(json.dumps([{
            "id": n.id, "kind": n.kind, "setpoint_c": n.setpoint_c, "t_min_c": n.t_min_c,
            "t_max_c": n.t_max_c, "window_start": n.window_start.isoformat(),
            "window_end": n.window_end.isoformat(), "state": n.state, "source": n.source,
            "valid": n.valid, "samples": count, "reasons": list(n.reasons),
            "started": n.started and n.started.isoformat(),
            "ended": n.ended and n.ended.isoformat()} for n, count in rows], indent=2))
        return
    click.echo(f"{'id':>4} {'kind':<11} {'T_set °C':>8} {'window start (local)':<22} "
               f"{'state':<11} {'valid':<5} {'samples':>7}  reasons")
    for n, count in rows:
        valid = "-" if n.valid is None else ("yes" if n.valid else "no")
        click.echo(f"{n.id:>4} {n.kind:<11} {n.setpoint_c:>8.1f} "
                   f"{n.window_start.astimezone(tz):%Y-%m-%d %H:%M %Z}  {n.state:<11} "
                   f"{valid:<5} {count:>7}  {'; '.join(n.reasons)}")


@cli.command("export")
@config_option
@click.option("--db", "db_path", type=click.Path(path_type=Path), default=None,
              help="Store file (default: impctl.db in the config's state_dir).")
@click.option("--format", "fmt", type=click.Choice(["csv", "parquet"]), default="csv",
              show_default=True)
@click.option("--nights", "night_ids", default=None,
              help="Comma-separated night ids (default: all valid nights and every owner "
                   "record).")
@click.option("--all", "include_invalid", is_flag=True, help="Include nights not valid.")
@click.option("--no-owner", "no_owner", is_flag=True,
              help="Leave out the owner records (the house recorded between IMP nights).")
@click.option("--out", "out_path", type=click.Path(path_type=Path), required=True,
              help="NIGHTS file to write (timestamp,t_air,t_out,q_hc,setpoint,heating,night,"
                   "kind); its directory must exist.")
@click.option("--force", is_flag=True,
              help="Overwrite an existing file (never a database: the store is refused).")
def export_command(config_path: Path, db_path: Path | None, fmt: str, night_ids: str | None,
                   include_invalid: bool, no_owner: bool, out_path: Path, force: bool) -> None:
    """Write stored nights in the measured-data format of ``impctl fit``: the IMP nights and
    the owner records (kind owner, labelled where they are not the owner's ordinary night),
    in time order; the emitter the configuration declares ([fit] emitter) in an emitter
    column, so that a fleet reads the installer's word with the nights.

    Never writes onto the store or another database, into a directory that does not exist,
    or onto an existing file without --force; unknown night ids or nothing to export give
    exit status 2 and write nothing.
    """
    from ...store import Store
    from ...store.export import export_nights

    cfg = _load(config_path) if db_path is None or config_path.is_file() else None
    if db_path is None:
        db_path = cfg.db_path
    ids = None
    if night_ids:
        try:
            ids = [parse_int(x) for x in night_ids.split(",") if x.strip()]
        except ValueError:
            raise InputError(non_ascii_problem(night_ids) or f"expected comma-separated ids, "
                             f"got {night_ids!r}", place="--nights") from None
    with Store(db_path, create=False) as store:
        n = export_nights(store, out_path, fmt, ids, valid_only=not (include_invalid or ids),
                          force=force, owner=not no_owner,
                          emitter=(cfg.fit.emitter or None) if cfg is not None else None)
    click.echo(f"wrote {n} samples to {out_path}")
