"""The daemon's nights on an accelerated clock: the cron rule evaluated and waited for on the
daemon's clock (not APScheduler's wall clock), a night more than ``misfire_grace_s`` late
skipped with a warning, as APScheduler skips a real-time one.

On the virtual-time loop with the clock on the loop's time, so the test is exact however loaded
the machine: the clock jumping ahead (a gateway suspended, a loop blocked) is the only way a
night is late.
"""

from __future__ import annotations

import asyncio
import logging
from datetime import datetime, timedelta
from zoneinfo import ZoneInfo

from reliability_fixtures import loop_wall, run_virtual

from impctl.clock import VirtualClock
from impctl.config import config_from_mapping
from impctl.daemon.nights.schedule import accelerated_nights

TZ = ZoneInfo("Europe/Ljubljana")
SPEED = 3600.0  # a simulated hour per second of the loop


def test_nights_start_on_the_daemons_clock_and_a_missed_one_is_skipped(caplog):
    cfg = config_from_mapping({"state_dir": "/tmp/never-created", "timezone": "Europe/Ljubljana",
                               "heatpump": {"host": "192.168.1.50"},
                               "night": {"window": "22:00-05:00", "preheat_h": 2.0},
                               "campaign": {"misfire_grace_s": 3600.0}})
    runs: list[tuple[datetime, datetime]] = []

    async def body() -> None:
        wall, jump_s = loop_wall(), [0.0]
        clock = VirtualClock(datetime(2026, 1, 12, 12, 0, tzinfo=TZ), SPEED,
                             wall=lambda: wall() + jump_s[0])

        async def night_job(act: datetime) -> None:
            runs.append((act, clock.now()))

        task = asyncio.create_task(accelerated_nights(cfg, clock, night_job))
        # 13 Jan 18:00: the clock jumps 3 h, past the 20:00 preheat start and its 1 h grace.
        await asyncio.sleep((datetime(2026, 1, 13, 18, 0, tzinfo=TZ) - clock.now())
                            / timedelta(seconds=SPEED))
        jump_s[0] += 3 * 3600 / SPEED
        while len(runs) < 2:
            await asyncio.sleep(1.0)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)

    with caplog.at_level(logging.INFO, logger="impctl.daemon"):
        run_virtual(body(), timeout_s=600)
    # 12 and 14 Jan ran at their preheat start (20:00 local), to the simulated second;
    # 13 Jan was missed by 3 h and skipped, with a warning naming it.
    assert [act.astimezone(TZ).isoformat() for act, _ in runs] == [
        "2026-01-12T20:00:00+01:00", "2026-01-14T20:00:00+01:00"]
    assert all(abs((now - act).total_seconds()) < 1.0 for act, now in runs), runs
    missed = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert missed == ["night job at 2026-01-13 20:00:00+01:00 missed by 10800 s "
                      "(daemon's clock)"], missed
