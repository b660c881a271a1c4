"""Write discipline, seen on the wire: how many writes a night makes, that each one is
compared before and read back after, and that the daily budget refuses a night it cannot
afford — without sending anything.

The daemon (in-process) talks to the simulator through :class:`reliability_fixtures.
ModbusProxy`, which records every request in order (function code, address, value), so the
checks do not rely on impctl's own account of what it sent.

Already proven elsewhere (not repeated here): a fault-free constrained night writes 2187 and
2042 twice each and a normal night 2187 twice (``test_controller_nights``); the client's
budget refuses the write past the limit and sends nothing, a restore may use the reserve
(``test_heatpump_writes``); failed restores do not use the budget up
(``test_reliability_faults``).
"""

from __future__ import annotations

from collections import Counter

import pytest
from reliability_fixtures import DaemonRig, daemon_rig
from sim_fixtures import run

SPEED = 7200.0
FC_READ, FC_WRITE = 3, 6


def _writes(trace: list[tuple[int, int, int]]) -> list[tuple[int, int]]:
    """(documented register, written word) of every FC 06 in order."""
    return [(addr + 1, value) for fc, addr, value in trace if fc == FC_WRITE]


def _each_write_compared_and_read_back(trace: list[tuple[int, int, int]]) -> None:
    for i, (fc, addr, _) in enumerate(trace):
        if fc != FC_WRITE:
            continue
        before = [t for t in trace[:i] if t[0] == FC_READ and t[1] <= addr < t[1] + t[2]]
        assert before and before[-1] == (FC_READ, addr, 1), (i, trace[max(0, i - 3):i + 1])
        after = trace[i + 1]
        assert after == (FC_READ, addr, 1), (i, trace[i:i + 2])  # the read-back, at once


async def _owner_mode(rig: DaemonRig, mode: int) -> None:
    rig.sim.rw[2042] = mode
    rig.sim.plant.loop_mode = mode
    await rig.until(lambda: rig.sim.rw[2042] == mode)
    while (await rig.sim.read_words(2042)) != [mode]:  # published by the model task
        await rig.sim_minutes(1)


@pytest.mark.parametrize("kind, owner_mode, expected", [
    ("constrained", 1, {2187: 2, 2042: 2}),
    ("normal", 1, {2187: 2}),
    # The owner runs loop 1 by schedule (2042 = 2): it is held at 1 (on) for the night, so a
    # schedule cannot drop to ECO mid-experiment; that costs one write more.
    ("constrained", 2, {2187: 2, 2042: 3}),
    ("normal", 2, {2187: 2, 2042: 2}),
])
def test_writes_per_night_each_compared_and_read_back(tmp_path, kind, owner_mode, expected):
    async def body():
        async with daemon_rig(tmp_path, speed=SPEED) as rig:
            if owner_mode != 1:
                await _owner_mode(rig, owner_mode)
            start = len(rig.proxy.stats.trace)
            nid = await rig.trigger(kind, 21.0 if kind == "constrained" else 22.0)
            await rig.until(lambda: rig.finished(nid), 20)
            trace = rig.proxy.stats.trace[start:]
            night = rig.night(nid)
            assert night.state == "done", night
            writes = _writes(trace)
            assert Counter(ma for ma, _ in writes) == expected
            assert len(writes) <= 4 or (kind, owner_mode) == ("constrained", 2)
            _each_write_compared_and_read_back(trace)
            # The last writes put the owner's values back, as raw words.
            last = {ma: word for ma, word in writes}
            assert last[2187] == 210 and last.get(2042, owner_mode) == owner_mode
            assert (rig.sim.plant.setpoint_c, rig.sim.plant.loop_mode) == (21.0, owner_mode)
    run(body(), 60)


def test_the_daily_budget_refuses_a_night_it_cannot_afford_and_sends_nothing(tmp_path):
    """daily_budget = 4 (the least the config accepts): a constrained and a normal night use
    2187's budget up; a third night the same day is refused before the first write."""
    async def body():
        writes = {"verify_delay_s": 0.0, "daily_budget": 4}
        async with daemon_rig(tmp_path, speed=SPEED, heatpump={"writes": writes}) as rig:
            budget = rig.daemon.client.budget
            day = rig.clock.now().date()
            for kind, sp in (("constrained", 21.0), ("normal", 22.0)):
                nid = await rig.trigger(kind, sp)
                await rig.until(lambda nid=nid: rig.finished(nid), 20)
                assert rig.night(nid).state == "done"
            assert (budget.used(2187, day), budget.used(2042, day)) == (4, 2)
            start = len(rig.proxy.stats.trace)
            third = await rig.trigger("normal", 22.0)
            await rig.until(lambda: rig.night(third).valid is not None, 20)
            night = rig.night(third)
            assert rig.clock.now().date() == day  # still the same (UTC) day
            assert night.state == "refused" and night.valid is False
            assert night.reasons == ("daily write budget of register 2187 nearly used up "
                                     "(4/4)",), night.reasons
            assert _writes(rig.proxy.stats.trace[start:]) == []
            assert rig.store.journal_pending() == []
            assert (rig.sim.plant.setpoint_c, rig.sim.plant.loop_mode) == (21.0, 1)
            assert (budget.used(2187, day), budget.used(2042, day)) == (4, 2)
    run(body(), 60)
