"""The system clock steps while the daemon runs between nights (NTP correcting a clock that ran
ahead, a wrong ``date -s``, a resume from suspend).

Real parts: the daemon against the simulator over loopback TCP (through a proxy), a real
store, on the virtual-time loop. The step is injected where a real one happens — in the
wall-clock source of the daemon's clock (:class:`SteppedWall`, as the controller's clock-step
tests do); the loop's monotonic time and the simulated house go on unstepped, as the kernel's
monotonic clock and the real house would.

What is promised: the 1-second polls of the store (the manual triggers, Home Assistant's stop
button) go on within seconds after a step back of 3 h — they wait on the loop's monotonic
time, not for a wall-clock instant; the owner recording ends its row at the step, notes the
step on its record, and never stores a row before or over a newer one.
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import timedelta

import pytest
from reliability_fixtures import daemon_rig, run_virtual

from impctl.clock import VirtualClock

SPEED = 600.0


class SteppedWall:
    """A wall-clock source that can be stepped: ``base()`` plus an offset [s of the source]."""

    def __init__(self, base: Callable[[], float]) -> None:
        self.base = base
        self.offset_s = 0.0

    def __call__(self) -> float:
        return self.base() + self.offset_s


def _stepped(walls: list[SteppedWall]) -> Callable[[VirtualClock], VirtualClock]:
    def make(house: VirtualClock) -> VirtualClock:
        wall = SteppedWall(house._wall)
        walls.append(wall)
        return VirtualClock(house.epoch, house.factor, house.wall_epoch_s, wall=wall,
                            monotonic=house._wall)
    return make


def test_a_queued_abort_and_a_trigger_are_taken_within_seconds_after_a_step_back(tmp_path):
    async def scenario():
        walls: list[SteppedWall] = []
        async with daemon_rig(tmp_path, speed=SPEED, daemon_clock=_stepped(walls)) as rig:
            await rig.sim_minutes(20)
            walls[0].offset_s -= 3 * 3600 / SPEED  # the wall clock steps back 3 h
            await rig.sim_minutes(2)
            loop = rig.clock  # the house's (unstepped) time: the loop's, scaled
            cid = rig.store.add_command("abort", "test")
            queued = loop.now()
            await rig.until(lambda: not rig.store.pending_commands(), 30)
            abort_after = loop.now() - queued
            rig.store.add_request("normal", 22.0, "now", forced=True)
            queued = loop.now()
            await rig.until(lambda: rig.store.nights(), 30)
            night_after = loop.now() - queued
            taken = rig.store._db.execute("SELECT taken FROM commands WHERE id = ?",
                                          (cid,)).fetchone()[0]
            night = rig.store.nights()[0]
            await rig.until(lambda: rig.finished(night.id), 600)
            return abort_after, night_after, taken, rig.store.night(night.id)

    abort_after, night_after, taken, night = run_virtual(scenario(), 86400)
    # Within 2 s of the loop's (monotonic) time, as without a step: not 3 h later.
    assert taken is not None
    assert abort_after <= timedelta(seconds=2 * SPEED), abort_after
    assert night_after <= timedelta(seconds=2 * SPEED), night_after
    assert night.source == "trigger" and night.state == "done", night


@pytest.mark.parametrize("step_h", [-3.0, 3.0], ids=["back-3h", "ahead-3h"])
def test_owner_rows_stay_in_order_across_a_step_and_the_record_notes_it(tmp_path, step_h):
    async def scenario():
        walls: list[SteppedWall] = []
        async with daemon_rig(tmp_path, speed=SPEED, daemon_clock=_stepped(walls),
                              record={"sample_interval_s": 60}) as rig:
            await rig.sim_minutes(62)
            mark = rig.logs.mark()
            walls[0].offset_s += step_h * 3600 / SPEED
            await rig.sim_minutes(5 * 60)
            records = rig.store.owner_records()
            order = [r[0] for r in rig.store._db.execute(
                "SELECT ts FROM samples ORDER BY rowid")]
            return records, order, rig.logs.lines(mark), [m for _, _, m in rig.store.events()]

    records, order, warnings, events = run_virtual(scenario(), 86400)
    shown = f"{'−' if step_h < 0 else '+'}3.0 h"
    assert warnings == [f"WARNING impctl.record: owner recording: system clock stepped by "
                        f"{shown}; the current row ends here"], warnings
    assert f"owner recording: system clock stepped by {shown}" in events
    assert any(r.startswith(f"clock stepped: by {shown} at ") for n in records
               for r in n.reasons), [n.reasons for n in records]
    stamps = order  # UTC ISO text of one format: its order is the instants'
    assert all(a < b for a, b in zip(stamps, stamps[1:], strict=False)), stamps
    # 5 h after the step, recording goes on: back 3 h, the rows resume once the wall clock
    # passes the newest row stored (about 2 h later); ahead 3 h, after a 3-h hole at once
    assert len(order) >= (12 + 20 if step_h < 0 else 12 + 56), len(order)
