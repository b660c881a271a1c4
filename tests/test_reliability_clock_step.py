"""The system clock steps in the middle of a constrained night (NTP correcting a clock that ran
ahead, a wrong ``date -s``, a resume from suspend).

Real parts: the controller runs a constrained night against the simulator over loopback TCP,
with a real store, on the virtual-time loop. The step is injected where a real one happens —
in the wall-clock source of impctl's clock (:class:`SteppedWall`); the monotonic source (the
loop's time) and the simulated house (on its own, unstepped clock) go on as before, as the
kernel's monotonic clock and the real house would. Nothing of the controller is replaced.

What is promised: no wait lasts longer than one sample interval; a step beyond the tolerance
(2 min, or two sample intervals) either way ends the night at the next poll with the reason
stored, and the heat pump is restored; a smaller step is ridden out, the window still ends on
time (it is held on the monotonic clock too); samples are never stored out of order.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from datetime import timedelta

import pytest
from daemon_fixtures import HEAVY_HOUSE
from impctl_sim import SimConfig, constant_weather
from reliability_fixtures import WRITE_AUDIT, captured_logs, loop_wall, run_virtual
from sim_fixtures import EPOCH, budget, hp_config, simulator, wait_for

from impctl.clock import VirtualClock
from impctl.controller import NightController, NightPolicy, NightRequest
from impctl.heatpump import HeatPumpClient
from impctl.store import Store

#: Simulated seconds per second of the loop's time (the simulator's model steps stay cheap).
SPEED = 60.0
INTERVAL_S = 60.0


class SteppedWall:
    """A wall-clock source that can be stepped: ``base()`` plus an offset [s of the source]."""

    def __init__(self, base: Callable[[], float]) -> None:
        self.base = base
        self.offset_s = 0.0

    def __call__(self) -> float:
        return self.base() + self.offset_s


async def _night_with_step(tmp_path, step_s: float) -> dict:
    base = loop_wall()
    house_clock = VirtualClock(EPOCH, SPEED, wall=base)  # the house's time: never steps
    wall = SteppedWall(base)
    clock = VirtualClock(EPOCH, SPEED, house_clock.wall_epoch_s, wall=wall, monotonic=base)
    cfg = SimConfig(clock=house_clock, house=HEAVY_HOUSE, weather=constant_weather(0.0))
    async with simulator(cfg) as sim:
        hp = HeatPumpClient(hp_config(sim.port), clock=clock, budget=budget(tmp_path))
        await hp.connect(max_wait_s=5.0)
        try:
            with Store(tmp_path / "impctl.db") as store, captured_logs(clock) as logs:
                ctl = NightController(hp, store, clock, NightPolicy(
                    sample_interval_s=INTERVAL_S, preheat_h=0.5, anticipate_s=0.0))
                start = clock.now() + timedelta(minutes=31)
                req = NightRequest("constrained", 21.0, start, start + timedelta(hours=2.5))
                task = asyncio.create_task(ctl.run(req))
                # 1.5 h into the window, the heating off for as long: the clock steps.
                await wait_for(lambda: house_clock.now() >= start + timedelta(hours=1.5), 600)
                assert sim.plant.loop_mode == 0 and not task.done()
                mark = logs.mark()
                wall.offset_s += step_s / SPEED
                stepped_at = house_clock.now()
                night = await asyncio.wait_for(task, 600)
                ended_after = house_clock.now() - stepped_at
                order = [r[0] for r in store._db.execute(
                    "SELECT ts FROM samples WHERE night_id = 1 ORDER BY rowid")]
                return dict(night=night, req=req, ended_after=ended_after,
                            registers=((await sim.read_words(2187))[0],
                                       (await sim.read_words(2042))[0]),
                            order=order, pending=store.journal_pending(),
                            warnings=logs.lines(mark, logging.WARNING, exclude=WRITE_AUDIT),
                            end_true=house_clock.now() - (night.ended - req.window_end)
                            if night.ended else None)
        finally:
            hp.close()


def _in_order(order: list[str]) -> bool:
    from datetime import datetime

    times = [datetime.fromisoformat(t) for t in order]
    return all(a < b for a, b in zip(times, times[1:], strict=False))


@pytest.mark.parametrize("step_h, shown", [(-3.0, "−3.0 h"), (3.0, "+3.0 h")],
                         ids=["back-3h", "ahead-3h"])
def test_a_clock_step_ends_the_night_within_one_sample_interval(tmp_path, step_h, shown):
    r = run_virtual(_night_with_step(tmp_path, step_h * 3600), 900)
    night = r["night"]
    assert night.state == "aborted" and night.valid is False, night
    assert night.reasons[0] == f"system clock stepped by {shown}", night.reasons
    # Seen at the next poll, not hours later: the heat pump is back within one interval
    # (plus the restore's writes and read-backs) of true time.
    assert r["ended_after"] <= timedelta(seconds=1.5 * INTERVAL_S), r["ended_after"]
    assert r["registers"] == (210, 1) and r["pending"] == []
    assert _in_order(r["order"]), r["order"]
    assert len(r["warnings"]) == 1, r["warnings"]
    assert r["warnings"][0].endswith(f"night aborted: system clock stepped by {shown}")


def test_a_step_within_the_tolerance_is_ridden_out_in_order_and_on_time(tmp_path):
    """90 s back (under the 2-min tolerance): not a reason to end the night, but the sample
    that would land before the last one is not stored, and the window still ends when it
    ends in true time (held on the monotonic clock), not 90 s later."""
    r = run_virtual(_night_with_step(tmp_path, -90.0), 900)
    night, req = r["night"], r["req"]
    assert night.state == "done", night
    assert _in_order(r["order"]), r["order"]
    # In true time, from the step to the end: what was left of the window, not 90 s more.
    left = req.window_end - (req.window_start + timedelta(hours=1.5))
    assert r["ended_after"] <= left + timedelta(seconds=INTERVAL_S), (r["ended_after"], left)
    assert r["registers"] == (210, 1) and r["pending"] == []
    assert not r["warnings"], r["warnings"]
