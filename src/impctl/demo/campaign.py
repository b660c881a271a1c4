"""The demo's IMP campaign: the simulator serves the house, the daemon runs the nights against it
until the campaign has its valid nights; then what the campaign did.

Both run in one process on a virtual-time event loop (:mod:`impctl.clock.loop`): the clock they
share advances only when both wait, and stands still while the daemon's fit subprocesses run,
so a campaign's nights and numbers depend on the seed, not on how busy the machine is."""

from __future__ import annotations

import asyncio
import math
import time
from datetime import datetime, timedelta
from pathlib import Path
from zoneinfo import ZoneInfo

from ..clock import VirtualClock
from ..config import config_from_mapping
from ..imp.protocol import DEFAULT_BAND_K, DEFAULT_CONSTRAINED_SETPOINT_C, DEFAULT_SETPOINTS_C
from ..model import HouseParameters
from ..store import Store
from .options import (
    FIT_WAIT_S,
    OWNER_SAMPLE_S,
    TZ,
    DemoError,
    DemoOptions,
    Progress,
    fit_night_gain_w,
    plant_summary,
)


async def run_campaign(opts: DemoOptions, house: HouseParameters, progress: Progress,
                       trainer, weather, realism) -> Path:
    """Simulator + daemon until the campaign has its valid nights; returns the db path. Run
    it on a :class:`~impctl.clock.loop.VirtualTimeLoop` (:func:`impctl.clock.loop.run`).

    Raises
    ------
    DemoError
        The campaign stopped, or the heat pump was not restored: why, in one line.
    """
    from impctl_sim import KronotermSimulator, SimConfig

    from ..daemon.nights.recording import close_for_good
    from ..daemon.service import Daemon

    campaign_start = datetime.fromisoformat(opts.start).replace(tzinfo=ZoneInfo(TZ))
    # The gateway is installed (and records the owner's days) before the campaign begins.
    epoch = campaign_start - timedelta(days=opts.owner_days_before)
    clock = VirtualClock.on_loop(epoch, opts.speed)
    state = opts.out / "state"
    state.mkdir(parents=True, exist_ok=True)
    n_norm = opts.normal_nights
    setpoints = list(DEFAULT_SETPOINTS_C)  # the gateway's normal nights; the day is 21 °C
    per_sp = max(1, -(-n_norm // len(setpoints)))
    realistic = opts.plant == "realistic"
    # The realistic plant costs more per step (≈ 0.3 ms): 2-min steps.
    simcfg = SimConfig(house=house, clock=clock, setpoint_c=21.0, weather=weather,
                       plant_kind=opts.plant, realism=realism, timezone=TZ,
                       step_s=120.0 if realistic else None)
    async with KronotermSimulator(simcfg) as sim:
        progress.line(f"simulator: demo house on Modbus TCP 127.0.0.1:{sim.port}, "
                      f"clock ×{opts.speed:g} on virtual time (advancing only when the "
                      f"daemon and the simulator wait) from {epoch:%Y-%m-%d %H:%M %Z}; plant "
                      f"{plant_summary(opts, realism)['kind']}")
        mapping = {
            "state_dir": str(state), "timezone": TZ, "log_level": "warning",
            "model_dir": str(opts.model_dir or ""),
            "heatpump": {"host": "127.0.0.1", "port": sim.port, "timeout_s": 1.0,
                         "retries": 0, "attempts": 3, "retry_delay_s": 0.05,
                         "connect_backoff_s": [0.05, 0.5], "drain_s": 0.0,
                         "writes": {"verify_delay_s": 0.0}},
            # The gateway's band (DEFAULT_BAND_K, 2.5 K since h14w) on both plants: the ideal
            # plant's massless air node drops ~1.2 K at switch-off, so it needs at least 2 K.
            "night": {"sample_interval_s": opts.sample_interval_s, "t_out_max_c": 12.0,
                      "comfort_band_k": max(DEFAULT_BAND_K, 2.0)},
            "campaign": _campaign_section(opts, setpoints, per_sp),
            "clock": {"epoch": epoch.isoformat(), "speed": opts.speed},
            "fit": ({} if fit_night_gain_w(opts) is None
                    else {"night_gain_w": fit_night_gain_w(opts)}),
            "record": {"interval_s": OWNER_SAMPLE_S, "sample_interval_s": OWNER_SAMPLE_S},
        }
        cfg = config_from_mapping(mapping, "demo config")
        started = time.perf_counter()
        if opts.owner_days_before > 0:  # the daemon records, no campaign yet
            before = config_from_mapping(
                {**mapping, "campaign": {**mapping["campaign"], "enabled": False}},
                "demo config")
            await _daemon_until(before, clock, lambda: clock.now() >= campaign_start,
                                _owner_progress(before, clock, sim, progress, "before"))
        progress.timing_s["owner_before"] = time.perf_counter() - started
        daemon = Daemon(cfg, clock=clock)
        task = asyncio.create_task(daemon.run())
        try:
            started = time.perf_counter()
            await _watch(cfg, clock, sim, progress, trainer, task)
            progress.timing_s["nights"] = time.perf_counter() - started
            started = time.perf_counter()
            if opts.owner_days_after > 0:  # the campaign is done; the daemon records on
                until = _noon_after(clock.now() + timedelta(days=opts.owner_days_after))
                await _until(task, lambda: clock.now() >= until,
                             _owner_progress(cfg, clock, sim, progress, "after"))
            progress.timing_s["owner_after"] = time.perf_counter() - started
        finally:
            daemon.stop.set()
            await asyncio.gather(task, return_exceptions=True)
        if not task.cancelled() and task.exception() is not None:
            raise DemoError(f"the daemon stopped: {task.exception()!r} (see demo.log)")
        with Store(cfg.db_path) as store:
            left = store.journal_pending()
            close_for_good(cfg, store, clock)  # the demo's last owner day ends with it
        if left:
            raise DemoError("the heat pump was not restored: " +
                            ", ".join(e.register for e in left))
        progress.line(f"campaign done; simulator loop-1 setpoint back at "
                      f"{sim.plant.setpoint_c:.1f} °C, mode {sim.plant.loop_mode}")
        return cfg.db_path


def _noon_after(ts: datetime) -> datetime:
    """The first local noon at or after ``ts``: where an owner record ends."""
    local = ts.astimezone(ZoneInfo(TZ))
    noon = local.replace(hour=12, minute=0, second=0, microsecond=0)
    return noon if noon >= local else (noon + timedelta(days=1)).replace(hour=12)


def _owner_progress(cfg, clock, sim, progress: Progress, when: str):
    """A progress line (every 3 s of wall time) while the daemon records the owner's days."""
    last = [0.0]

    def line() -> None:
        if time.perf_counter() - last[0] < 3.0:
            return
        last[0] = time.perf_counter()
        with Store(cfg.db_path) as store:
            records = len(store.owner_records())
        now = clock.now().astimezone(ZoneInfo(TZ))
        progress.line(f"owner days ({when} the campaign): {records} records | sim "
                      f"{now:%a %d %b %H:%M} T_air {sim.plant.t_air_c:.1f} °C, T_out "
                      f"{sim.plant.t_out_c:.1f} °C | recording, nothing written")
    return line


async def _until(task: asyncio.Task, done, tick) -> None:
    """Until ``done()``; ``tick()`` on the way; the daemon ``task`` must stay up."""
    while not done():
        if task.done():
            raise DemoError(f"the daemon stopped: {task!r} (see demo.log)")
        await asyncio.sleep(0.5)  # the loop's time
        tick()


async def _daemon_until(cfg, clock, done, tick) -> None:
    """A daemon of ``cfg`` until ``done()``, then stopped (its last row stored)."""
    from ..daemon.service import Daemon

    daemon = Daemon(cfg, clock=clock)
    task = asyncio.create_task(daemon.run())
    try:
        await _until(task, done, tick)
    finally:
        daemon.stop.set()
        await asyncio.gather(task, return_exceptions=True)


def _campaign_section(opts: DemoOptions, setpoints: list[float], per_sp: int) -> dict:
    """``[campaign]``: the fixed counts, or the adaptive campaign (the daemon fits after
    every valid night and decides; the demo's classifiers are ready before it starts)."""
    # The gateway's constrained T_set (21 °C, the owner's day setpoint): T_max 23.5, T_min
    # 18.5 °C with the default ΔT 2.5 K.
    common = {"constrained_setpoint_c": DEFAULT_CONSTRAINED_SETPOINT_C}
    if opts.adaptive:
        return {**common, "mode": "adaptive", "normal_setpoints_c": setpoints,
                "max_nights": opts.max_nights,
                "target_rel_halfwidth": {"hlc": opts.target_rel[0], "tau": opts.target_rel[1]}}
    n_norm = opts.normal_nights
    # The demo's own guard (_watch: 3 × the plan + 6 nights) ends a demo that cannot finish;
    # the daemon's stop after invalid nights must not come first and leave it waiting.
    n_plan = opts.constrained_nights + n_norm
    return {**common, "mode": "fixed", "constrained_nights": opts.constrained_nights,
            "max_invalid_nights": 2 * n_plan + 6,
            "normal_setpoints_c": setpoints[: min(n_norm, 3)],
            "normal_nights_per_setpoint": per_sp if n_norm >= 3 else 1,
            "fit_when_complete": False}


def _campaign_done(store: Store, adaptive: bool) -> tuple[bool, int, str]:
    """(finished, valid nights, what the campaign is at) — adaptive: stopped and the fit of
    every valid night stored; fixed: every plan entry valid."""
    valid = len(store.nights(valid=True))
    if adaptive:
        from ..daemon.fitting import fit_ready

        decisions, fits = store.decisions(1), store.fits()
        stopped = bool(decisions) and decisions[0].action == "stop"
        fitted = (bool(fits) and fits[-1].night_count == valid) or fit_ready(store) is not None
        return (stopped and fitted, valid,
                f"{valid} valid, adaptive" + (": stopped" if stopped else ""))
    plan = store.campaign()
    done = sum(1 for *_, v in plan if v)
    return bool(plan) and done == len(plan), done, f"{done}/{len(plan)} valid"


async def _watch(cfg, clock, sim, progress: Progress, trainer, task) -> None:
    """Until the campaign is done: progress every 3 s of wall time, one line per night that
    ends invalid (why), and the stop of a campaign that cannot finish (:class:`DemoError`)."""
    from ..daemon.nights.schedule import campaign_plan, gave_up

    last = 0.0
    adaptive = cfg.campaign.adaptive
    # Adaptive: the policy stops at max_nights (refused nights do not count; a margin for them).
    limit = cfg.campaign.max_nights + 6 if adaptive else 3 * len(campaign_plan(cfg)) + 6
    stopped_at = None
    told: set[int] = set()
    while not task.done():
        await asyncio.sleep(0.5)  # the loop's time: 0.5 × speed simulated seconds
        with Store(cfg.db_path) as store:
            finished, _, where = _campaign_done(store, adaptive)
            nights = store.nights()
            stopped = None if adaptive else gave_up(store, cfg)
        for n in nights:
            if n.valid is False and n.id not in told:
                told.add(n.id)
                verdict = "refused" if n.state == "refused" else "not valid"
                progress.line(f"night {n.id} ({n.kind}, {n.setpoint_c:g} °C) {verdict}: "
                              + ("; ".join(n.reasons) or "no reason recorded"))
        if finished:
            return
        if stopped is not None:
            raise DemoError(stopped)
        if where.endswith("stopped"):
            # The daemon's fits take no simulated time (the clock waits for them): a stop
            # without the fit of every valid night after a simulated day means it failed.
            stopped_at = stopped_at or clock.now()
            if clock.now() - stopped_at > timedelta(seconds=FIT_WAIT_S):
                return  # the last fit failed (logged in demo.log): what there is, is shown
        if time.perf_counter() - last >= 3.0:
            last = time.perf_counter()
            running = [n for n in nights if n.state in ("preparing", "active", "restoring")]
            now = clock.now().astimezone(ZoneInfo(TZ))
            what = (f"night {running[-1].id} {running[-1].kind} {running[-1].setpoint_c:g} °C "
                    f"{running[-1].state}" if running else "between nights")
            train = progress.trainer_done(trainer)
            progress.line(f"nights {where} ({len(nights)} run) | "
                          f"sim {now:%a %d %b %H:%M} T_air {sim.plant.t_air_c:.1f} °C, "
                          f"T_out {sim.plant.t_out_c:.1f} °C | {what} | classifiers: {train}")
        if len(nights) > limit:
            raise DemoError(f"{len(nights)} nights run and the campaign is not done "
                            f"({where}); see `impctl nights --db {cfg.db_path}`")


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None  # JSON has no Infinity: unknown is null


def campaign_summary(store: Store, opts: DemoOptions) -> dict:
    """``nights_run`` / ``nights_valid`` (both modes) and the campaign block of summary.json:
    the interval after each fit and, adaptive, every decision with its reason."""
    from ..campaign import FitSummary

    run = [n for n in store.nights() if n.state != "refused"]
    valid = [n for n in run if n.valid]
    intervals = []
    for f in store.fits():
        fs = FitSummary.from_fit_json(f.result, f.night_count)
        intervals.append({"valid_nights": f.night_count, "hlc_w_per_k": fs.hlc_w_per_k,
                          "hlc_rel": _finite(fs.hlc_rel), "tau_h": fs.tau_h,
                          "tau_rel": _finite(fs.tau_rel)})
    block = {"mode": "adaptive" if opts.adaptive else "fixed", "nights_run": len(run),
             "nights_valid": len(valid), "nights": [[n.kind, n.setpoint_c, n.valid]
                                                    for n in run],
             "intervals": intervals}
    if opts.adaptive:
        block["target_rel_halfwidth"] = {"hlc": opts.target_rel[0], "tau": opts.target_rel[1]}
        block["max_nights"] = opts.max_nights
        block["decisions"] = [{"act": d.act, "action": d.action, "kind": d.kind,
                               "setpoint_c": d.setpoint_c, "reason": d.reason}
                              for d in reversed(store.decisions(200))]
        stop = next((d for d in reversed(block["decisions"]) if d["action"] == "stop"), None)
        block["line"] = (f"Campaign: adaptive, {len(run)} nights run, {len(valid)} valid. "
                         + (stop["reason"] if stop else ""))
    else:
        block["line"] = (f"Campaign: fixed {opts.constrained_nights} + {opts.normal_nights}, "
                         f"{len(run)} nights run, {len(valid)} valid.")
    summary = store.owner_summary()
    owner = {"records": summary.count, "labelled": summary.labelled, "rows": summary.rows,
             "row_s": OWNER_SAMPLE_S, "days_before": opts.owner_days_before,
             "days_after": opts.owner_days_after}
    labelled = sum(summary.labelled.values())
    owner["line"] = (f"Owner days: {summary.count} records of the owner's own heating "
                     f"({summary.rows} rows of {OWNER_SAMPLE_S / 60:g} min, recorded read-only "
                     f"{opts.owner_days_before:g} days before and {opts.owner_days_after:g} "
                     f"after the campaign and between its nights; {labelled} labelled"
                     + (": " + ", ".join(f"{k} {n}" for k, n in summary.labelled.items())
                        if labelled else "") + "), in nights.csv as kind owner.")
    return {"nights_run": len(run), "nights_valid": len(valid), "campaign": block,
            "owner": owner}
