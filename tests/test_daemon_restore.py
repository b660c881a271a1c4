"""The daemon keeps putting the owner's settings back after a night gave up restoring.

In-process daemon and simulator (real Modbus TCP on loopback, real SQLite, accelerated clock),
on the virtual-time loop: the accelerated clock follows the loop's time, so the 0.25 s of the
7200× clock before the night starts or the 3.5 s of its window do not pass while a loaded
machine is busy elsewhere (timeouts below are virtual seconds).
A constrained night loses the link after switching the heating off; the night aborts after
the link-lost limit and its own restore retries until ``restore_timeout_s`` (an hour) and then
stops, leaving the journal pending. The link comes back hours later: the daemon must restore
then — not at the next night or the next restart — or the house stays unheated all day.
"""

from __future__ import annotations

import asyncio
from datetime import datetime, timedelta
from zoneinfo import ZoneInfo

from daemon_fixtures import HEAVY_HOUSE, OWNER_MODE, OWNER_SETPOINT_C, daemon_mapping
from impctl_sim import SimConfig, constant_weather
from reliability_fixtures import loop_wall, run_virtual
from sim_fixtures import simulator, wait_for

from impctl.clock import VirtualClock
from impctl.config import config_from_mapping
from impctl.daemon.service import Daemon

EPOCH = datetime(2026, 1, 12, 9, 0, tzinfo=ZoneInfo("Europe/Ljubljana"))


def test_link_back_after_the_night_gave_up_restoring(tmp_path):
    async def body():
        clock = VirtualClock(EPOCH, 7200.0, wall=loop_wall())
        simcfg = SimConfig(clock=clock, house=HEAVY_HOUSE, weather=constant_weather(0.0),
                           setpoint_c=OWNER_SETPOINT_C)
        async with simulator(simcfg) as sim:
            # Short wall-clock Modbus timeouts: at 7200× a 0.5 s timeout is an hour simulated.
            mapping = daemon_mapping(tmp_path / "state", sim.port, clock,
                                     heatpump={"timeout_s": 0.05},
                                     night={"window": "22:00-05:00", "preheat_h": 0.5,
                                            "link_lost_limit_s": 900})
            daemon = Daemon(config_from_mapping(mapping), clock=clock)
            task = asyncio.create_task(daemon.run())
            try:
                await wait_for(lambda: daemon.scheduler is not None, 10)
                daemon.store.add_request("constrained", 21.0, "now", forced=True)
                # Taken now, as the 1 s trigger-poll job would (APScheduler times it on the
                # wall clock, not on the loop's virtual time).
                await daemon._poll_requests()
                await wait_for(lambda: sim.plant.loop_mode == 0 and any(
                    s.loop_mode == 0 for s in daemon.store.samples(1)), 10)
                sim.faults.drop = True
                await wait_for(lambda: daemon.store.night(1).state == "aborted", 20)
                night = daemon.store.night(1)
                assert night.reasons[0].startswith("heat-pump link lost for ")
                assert night.reasons[1] == "restore incomplete: loop1_setpoint, loop1_mode"
                assert len(daemon.store.journal_pending()) == 2
                # Hours of outage after the night gave up: the heat pump is unreachable.
                gave_up = clock.now()
                await wait_for(lambda: clock.now() > gave_up + timedelta(hours=3), 10)
                assert sim.plant.loop_mode == 0
                sim.faults.drop = False
                await wait_for(lambda: not daemon.store.journal_pending(), 20)
                assert (sim.plant.setpoint_c, sim.plant.loop_mode) == (OWNER_SETPOINT_C,
                                                                       OWNER_MODE)
                assert (await sim.read_words(2187), await sim.read_words(2042)) == ([210], [1])
                assert not task.done()
            finally:
                daemon.stop.set()
                assert await task == 0
    run_virtual(body(), timeout_s=600)
