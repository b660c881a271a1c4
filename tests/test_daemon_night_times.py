"""Which night runs when: a night job fired late within its grace, a skip after it, a window
that starts at a local time the spring DST change skips.

The in-process :class:`~impctl.daemon.service.Daemon` against the simulator over loopback TCP,
a real SQLite store, on the virtual-time loop (as ``test_daemon_campaign*``).
"""

from __future__ import annotations

import asyncio
import contextlib
from datetime import datetime
from zoneinfo import ZoneInfo

from daemon_fixtures import HEAVY_HOUSE, OWNER_SETPOINT_C, daemon_mapping
from impctl_sim import SimConfig, constant_weather
from reliability_fixtures import loop_wall, run_virtual
from sim_fixtures import simulator, wait_for

from impctl.clock import VirtualClock
from impctl.config import config_from_mapping
from impctl.daemon.nights.waiting import queue_skip
from impctl.daemon.service import Daemon

TZ = ZoneInfo("Europe/Ljubljana")
SPEED = 600.0
#: 22:30 local on 12 Jan: tonight's preheat (20:00) is 2.5 h past, its window (22:00) has begun.
LATE = datetime(2026, 1, 12, 22, 30, tzinfo=TZ)


@contextlib.asynccontextmanager
async def _daemon(tmp_path, epoch: datetime, grace_s: float = 14400):
    """A daemon on the default night window (22:00–05:00, 2 h preheat) with the fixed campaign
    on and ``misfire_grace_s`` 4 h (allowed up to 12 h: "a night whose 22:00 start was missed by
    less still runs")."""
    clock = VirtualClock(epoch, SPEED, wall=loop_wall())
    simcfg = SimConfig(clock=clock, house=HEAVY_HOUSE, weather=constant_weather(0.0),
                       setpoint_c=OWNER_SETPOINT_C)
    async with simulator(simcfg) as sim:
        mapping = daemon_mapping(tmp_path / "state", sim.port, clock,
                                 night={"window": "22:00-05:00", "preheat_h": 2.0,
                                        "sample_interval_s": 300},
                                 campaign={"enabled": True, "misfire_grace_s": grace_s})
        daemon = Daemon(config_from_mapping(mapping, "test"), clock=clock)
        task = asyncio.create_task(daemon.run())
        try:
            await wait_for(lambda: daemon.scheduler is not None or task.done(), 20)
            assert not task.done(), task
            yield daemon, clock
        finally:
            daemon.stop.set()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(task, 120)


def _local(ts: datetime) -> datetime:
    return ts.astimezone(TZ)


def test_a_night_job_fired_late_within_the_grace_runs_tonights_window(tmp_path):
    """APScheduler calls ``_night_job()`` without arguments (service.py ``add_job``); fired
    2.5 h late (a resume from suspend, a clock stepped forward by NTP at boot), inside
    ``misfire_grace_s``, it must run *tonight's* window (12 Jan 22:00 → 13 Jan 05:00)."""
    async def scenario():
        async with _daemon(tmp_path, LATE) as (daemon, clock):
            job = asyncio.create_task(daemon._night_job())   # as APScheduler fires it
            await wait_for(lambda: daemon.store.nights(), 20)
            night = daemon.store.nights()[0]
            daemon.stop.set()
            await asyncio.wait_for(asyncio.gather(job, return_exceptions=True), 120)
            return night

    night = run_virtual(scenario(), 86400)
    assert (_local(night.window_start), _local(night.window_end)) == (
        datetime(2026, 1, 12, 22, 0, tzinfo=TZ), datetime(2026, 1, 13, 5, 0, tzinfo=TZ)), (
        f"night {night.id} created at 12 Jan 22:30 for the window "
        f"{_local(night.window_start)} → {_local(night.window_end)}")


def test_a_night_job_fired_too_late_for_a_night_runs_none_and_writes_nothing(tmp_path):
    """Fired at 04:00 (a resume from suspend) within a 12 h grace: tonight's window has 1 h
    left, less than a night needs — no night, no write, nothing counted against the campaign."""
    async def scenario():
        async with _daemon(tmp_path, datetime(2026, 1, 13, 4, 0, tzinfo=TZ),
                           grace_s=43200) as (daemon, clock):
            await daemon._night_job()   # as APScheduler fires it
            return daemon.store.nights(), daemon.client.budget.used(
                2187, clock.now().date()), daemon.client.budget.used(2042, clock.now().date())

    nights, setpoint_writes, mode_writes = run_virtual(scenario(), 86400)
    assert nights == [] and setpoint_writes == mode_writes == 0


def test_a_skip_of_the_next_night_holds_after_a_late_night_job(tmp_path):
    """The same late job, then the household asks to skip the next night (13 Jan 10:00): at
    13 Jan 20:30 no night of 13 Jan may be under way and the skip must have been honoured."""
    async def scenario():
        async with _daemon(tmp_path, LATE) as (daemon, clock):
            job = asyncio.create_task(daemon._night_job())   # as APScheduler fires it
            await wait_for(lambda: daemon.store.nights(), 20)
            await wait_for(lambda: _local(clock.now()) >= datetime(2026, 1, 13, 10, 0,
                                                                   tzinfo=TZ), 600)
            queue_skip(daemon.store, "test")
            await wait_for(lambda: _local(clock.now()) >= datetime(2026, 1, 13, 20, 30,
                                                                   tzinfo=TZ), 600)
            nights = daemon.store.nights()
            pending = daemon.store.pending_commands("skip_tonight")
            daemon.stop.set()
            await asyncio.wait_for(asyncio.gather(job, return_exceptions=True), 120)
            return nights, pending

    nights, pending = run_virtual(scenario(), 3 * 86400)
    tonight = [n for n in nights if _local(n.window_start).date().isoformat() == "2026-01-13"
               and n.state in ("preparing", "active")]
    assert not tonight and not pending, (
        f"skip of 13 Jan still pending: {bool(pending)}; nights of 13 Jan under way: "
        f"{[(n.id, n.state, _local(n.window_start).isoformat()) for n in tonight]}")


def test_a_one_hour_window_in_the_spring_forward_gap_is_not_run_as_a_zero_length_night(tmp_path):
    """``night.window = "02:00-03:00"`` (1 h: inside the configured 1–12 h bound). On 29 Mar
    2026 02:00 does not exist, and 02:00+01:00 is the same instant as the end 03:00+02:00: a
    night of no length, which would count as an invalid scheduled night. Nothing runs that
    night."""
    from impctl.daemon.nights.next_night import next_campaign_night
    from impctl.daemon.nights.schedule import next_act_time
    from impctl.store import Store

    cfg = config_from_mapping({"state_dir": str(tmp_path / "state"),
                               "heatpump": {"host": "192.168.1.50"},
                               "night": {"window": "02:00-03:00", "preheat_h": 2.0}}, "test")
    act = next_act_time(cfg, datetime(2026, 3, 28, 12, 0, tzinfo=TZ))
    assert _local(act) == datetime(2026, 3, 29, 0, 0, tzinfo=TZ)
    with Store(tmp_path / "impctl.db") as store:
        store.set_campaign([("constrained", 21.0)])
        req = next_campaign_night(store, cfg, act)   # what _night_job(act) calls
    assert req is None or req.duration_h > 0, (
        f"night request {req.window_start.isoformat()} → {req.window_end.isoformat()}: "
        f"{req.duration_h:g} h")
