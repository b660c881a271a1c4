"""Whole campaigns run by the real daemon against the simulator with the accelerated clock.

In-process :class:`~impctl.daemon.service.Daemon` (its cron rule evaluated and waited for on
the accelerated clock) and an in-process simulator on loopback Modbus TCP, real SQLite files,
all on one virtual-time event loop (the accelerated clock follows the loop's time): however
loaded the machine, a night starts at its preheat time and gets every sample, and the fit
subprocesses take no simulated time (the loop's clock waits for them). A
watcher samples the simulated heat pump all the time: whenever no night is running, the
owner's setpoint and mode must be on the heat pump.

* a full campaign (2 constrained + 3 normal nights) across the end of summer time
  (25 Oct 2026, Europe/Ljubljana): one night per day, 22:00–05:00 local, the night of the
  change 8 h long, every night valid and restored, a fit after each valid night from the
  first with a night of each kind, run in a subprocess (``impctl export`` → ``impctl fit``)
  and stored with its night count;
* a short campaign across the start of summer time (29 Mar 2026): the night of the change
  lasts 6 h, the next 7 h.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass, field
from datetime import date, datetime, timedelta
from zoneinfo import ZoneInfo

from daemon_fixtures import HEAVY_HOUSE, OWNER_MODE, OWNER_SETPOINT_C, daemon_mapping
from impctl_sim import SimConfig, constant_weather
from reliability_fixtures import loop_wall, run_virtual
from sim_fixtures import simulator

from impctl.clock import VirtualClock
from impctl.config import config_from_mapping
from impctl.controller import NightRequest
from impctl.daemon import fitting
from impctl.daemon.nights.schedule import window_for
from impctl.daemon.service import Daemon
from impctl.store import Store

TZ = ZoneInfo("Europe/Ljubljana")
#: Campaigns run one night a day, so five nights take 4 days + 9 h of simulated time
#: (≈ 35 s at 10800×; 53 s at 7200×). Samples every 5 simulated minutes = 36 per second.
SPEED = 10800.0
FINAL = ("done", "aborted", "refused", "interrupted")
#: Real time for a campaign with fits: the nights take ~15 s, each fit (export + fit, ~4 s of
#: CPU) ~5 s on an idle machine, ~10–20 s on 2 cores saturated by other processes. A guard
#: against a hang, not a deadline the product must meet.
FITS_TIMEOUT_S = 480.0


def unniced_fits(monkeypatch) -> None:
    """The daemon's fit subprocesses at the test's priority (``FIT_NICE`` 0, the product's
    10): the nice keeps a gateway's fit from delaying tonight's samples, which take no time on
    the virtual-time loop; on a machine saturated by other processes a niced fit gets 1–5 %
    of a core (CFS weight 110 against 1024): minutes per fit, and the test would time out."""
    monkeypatch.setattr(fitting, "FIT_NICE", 0)


@dataclass
class Watch:
    """Plant states seen while no night was running (each with the simulated time)."""

    idle_states: list[tuple[datetime, float, int]] = field(default_factory=list)
    nights_seen: set[int] = field(default_factory=set)


async def _watch(sim, clock, db_path, watch: Watch, done: asyncio.Event) -> None:
    with Store(db_path) as store:  # a second connection, as `impctl status` would use
        while not done.is_set():
            # Read the plant first: if the store then shows nothing running and nothing
            # pending, the plant state was read after the last restore had completed.
            state = (clock.now(), sim.plant.setpoint_c, sim.plant.loop_mode)
            nights = store.nights()
            watch.nights_seen.update(n.id for n in nights)
            if all(n.state in FINAL for n in nights) and not store.journal_pending():
                watch.idle_states.append(state)
            await asyncio.sleep(0.02)


async def _campaign(tmp_path, epoch: datetime, speed: float, campaign: dict, *,
                    until, timeout_s: float, night: dict | None = None, after=None):
    """Run the daemon until ``until(db_path)``; then ``await after(cfg, clock)`` if given (its
    result is returned as ``after``), and until the watcher saw the plant after the last night.
    Run it with :func:`run_virtual`; ``timeout_s`` is real (wall-clock) time, what the fit
    subprocesses take.
    """
    deadline = time.monotonic() + timeout_s

    def in_time(what: str) -> None:
        assert time.monotonic() < deadline, f"timed out after {timeout_s:g} s waiting for {what}"

    clock = VirtualClock(epoch, speed, wall=loop_wall())
    simcfg = SimConfig(clock=clock, house=HEAVY_HOUSE, weather=constant_weather(0.0),
                       setpoint_c=OWNER_SETPOINT_C, plant_kind="iso")
    async with simulator(simcfg) as sim:
        mapping = daemon_mapping(tmp_path / "state", sim.port, clock,
                                 night={"sample_interval_s": 300, **(night or {})},
                                 campaign={"enabled": True, **campaign},
                                 # the ideal 5R1C has no night gains: [fit] tells the fit
                                 fit={"night_gain_w": 0.0})
        cfg = config_from_mapping(mapping, "test")
        daemon = Daemon(cfg, clock=clock)
        watch, done = Watch(), asyncio.Event()
        task = asyncio.create_task(daemon.run())
        watcher = asyncio.create_task(_watch(sim, clock, cfg.db_path, watch, done))
        try:
            while not until(cfg.db_path):
                assert not task.done(), "the daemon stopped by itself"
                in_time("the campaign")
                await asyncio.sleep(0.1)
            after_result = await after(cfg, clock) if after is not None else None
            # Let the watcher look at the heat pump once more after the last night.
            with Store(cfg.db_path) as store:
                last_end = max(n.ended for n in store.nights())
            while not any(t > last_end for t, *_ in watch.idle_states):
                in_time("the heat pump idle after the last night")
                await asyncio.sleep(0.02)
        finally:
            daemon.stop.set()
            assert await task == 0
            done.set()
            await watcher
        return dict(cfg=cfg, watch=watch, writes=dict(sim.stats.writes),
                    plant=(sim.plant.setpoint_c, sim.plant.loop_mode), after=after_result)


def _local(ts: datetime) -> datetime:
    return ts.astimezone(TZ)


def _check_nights_restored(result, nights) -> None:
    watch = result["watch"]
    # Between the nights (and after the last) the heat pump showed the owner's state only.
    assert watch.idle_states, "never saw the heat pump idle"
    assert {(sp, mode) for _, sp, mode in watch.idle_states} == {(OWNER_SETPOINT_C, OWNER_MODE)}
    for n in nights:  # idle seen after every night's end
        assert any(t > n.ended for t, *_ in watch.idle_states), n
    assert result["plant"] == (OWNER_SETPOINT_C, OWNER_MODE)


def test_full_campaign_across_the_end_of_summer_time(tmp_path, monkeypatch):
    """2 constrained + 3 normal nights from 23 Oct 2026: one night a day, all valid."""
    unniced_fits(monkeypatch)
    def until(db) -> bool:
        if not db.exists():
            return False
        with Store(db) as store:
            fit = store.last_fit()
            return fit is not None and len(fit[1]) == 5

    epoch = datetime(2026, 10, 23, 19, 0, tzinfo=TZ)
    result = run_virtual(_campaign(
        tmp_path, epoch, SPEED,
        {"mode": "fixed", "constrained_nights": 2, "constrained_setpoint_c": 21.0,
         "normal_setpoints_c": [21.0, 22.0, 23.0], "fit_when_complete": True},
        until=until, timeout_s=FITS_TIMEOUT_S))
    with Store(result["cfg"].db_path) as store:
        fit = store.last_fit()
        fit_events = [m for _, _, m in store.events(50) if m.startswith("fit")][::-1]
        fit_counts = [f.night_count for f in store.fits()]
        nights = store.nights()
        plan = store.campaign()
        pending = store.journal_pending()
        journal = store._db.execute("SELECT COUNT(*), COUNT(restored) FROM journal").fetchone()
        counts = {n.id: store.sample_count(n.id) for n in nights}
        integrity = store.integrity_check()
    assert integrity == "ok"
    # Exactly the campaign: five nights, every one valid, in plan order, one per day.
    assert [(n.kind, n.setpoint_c) for n in nights] == [
        ("constrained", 21.0), ("constrained", 21.0), ("normal", 21.0), ("normal", 22.0),
        ("normal", 23.0)]
    assert all(n.state == "done" and n.valid for n in nights), [
        (n.id, n.state, n.reasons) for n in nights]
    assert [row[3] for row in plan] == [n.id for n in nights]
    starts = [_local(n.window_start) for n in nights]
    ends = [_local(n.window_end) for n in nights]
    assert [s.date().isoformat() for s in starts] == [
        "2026-10-23", "2026-10-24", "2026-10-25", "2026-10-26", "2026-10-27"]
    assert {(s.hour, s.minute) for s in starts} == {(22, 0)}
    assert {(e.hour, e.minute) for e in ends} == {(5, 0)}
    hours = [(n.window_end - n.window_start) / timedelta(hours=1) for n in nights]
    assert hours == [7.0, 8.0, 7.0, 7.0, 7.0]  # 24/25 Oct: the clocks go back at 03:00
    # Every night sampled across its window (5-min samples) and restored, verified.
    for n, h in zip(nights, hours, strict=True):
        assert counts[n.id] >= 0.9 * h * 12, (n.id, counts[n.id])
    assert pending == [] and journal[0] == journal[1] == 10
    # 2187: set + restore on every night but the normal one at the owner's own 21 °C
    # (already there: never written); 2042: switch-off + restore on the constrained nights.
    assert result["writes"] == {2187: 8, 2042: 4}
    _check_nights_restored(result, nights)
    # A fit after the valid nights (in a subprocess, one at a time), from the first night that
    # gave a night of each kind (the third) to the last, each stored with its night count.
    _, fit_nights, summary = fit
    assert sorted(fit_nights) == [n.id for n in nights]
    assert fit_counts[0] >= 3 and fit_counts[-1] == 5 and fit_counts == sorted(set(fit_counts))
    assert fit_events == [f"fit stored ({c} nights)" for c in fit_counts]
    assert summary["fit"] and summary["lumped"]["hlc"]["unit"] == "W/K"
    # The data were the right ones: the heavy house's true HLC is found (±10 %), by a fit
    # told the configured night gain ([fit] night_gain_w reached the daemon's impctl fit).
    assert summary["fit"]["night_gain"]["statement"] == "night gain declared 0 W (known, ± 0 W)"
    assert summary["fit"]["night_gain"]["source"] == "declared"
    hlc = summary["lumped"]["hlc"]["value"]
    assert abs(hlc / float(HEAVY_HOUSE.hlc_w_per_k) - 1) < 0.10, hlc


def test_campaign_across_the_start_of_summer_time(tmp_path):
    """28/29 Mar 2026: 22:00 CET → 05:00 CEST is 6 h; the next night is 7 h again."""
    def until(db) -> bool:
        if not db.exists():
            return False
        with Store(db) as store:
            nights = store.nights()
            # Assessed (the verdict is stored just after the final state).
            return len(nights) >= 2 and all(n.state in FINAL and n.valid is not None
                                            for n in nights)

    # 19:00: the first preheat (20:00) is 0.33 s of the loop's time away at 10800× (the
    # daemon's start-up takes none of it on the virtual-time loop).
    epoch = datetime(2026, 3, 28, 19, 0, tzinfo=TZ)
    result = run_virtual(_campaign(
        tmp_path, epoch, SPEED,
        {"mode": "fixed", "constrained_nights": 0, "normal_setpoints_c": [21.0, 22.0]},
        until=until, timeout_s=60))
    with Store(result["cfg"].db_path) as store:
        nights = store.nights()
        last = [store.samples(n.id)[-1].ts for n in nights]
    assert len(nights) == 2
    assert all(n.state == "done" and n.valid for n in nights)
    assert [_local(n.window_start).isoformat() for n in nights] == [
        "2026-03-28T22:00:00+01:00", "2026-03-29T22:00:00+02:00"]
    assert [_local(n.window_end).isoformat() for n in nights] == [
        "2026-03-29T05:00:00+02:00", "2026-03-30T05:00:00+02:00"]
    assert [n.window_end - n.window_start for n in nights] == [timedelta(hours=6),
                                                               timedelta(hours=7)]
    # The request the daemon builds from the local window knows its absolute length too.
    cfg = result["cfg"]
    assert NightRequest("normal", 21.0, *window_for(date(2026, 3, 28), cfg)).duration_h == 6.0
    assert NightRequest("normal", 21.0, *window_for(date(2026, 10, 24), cfg)).duration_h == 8.0
    # Each night ran for its absolute length: its last sample is at the window's end.
    assert [abs(t - n.window_end) < timedelta(minutes=5) for t, n in zip(last, nights,
                                                                       strict=True)] == [True] * 2
    _check_nights_restored(result, nights)
