"""The night state machine against the real simulator over loopback Modbus TCP.

A constrained and a normal night each run through prepare → act → sample → end → restore →
assess with the accelerated clock. While the night runs, a watcher records what the simulated
heat pump itself is doing (its plant inputs, i.e. what the Modbus writes changed) and how many
samples another SQLite connection can already see; afterwards the owner's setpoint and mode must
be back on the simulator (plant and register image) and the journal must hold nothing pending.
"""

from __future__ import annotations

import asyncio
import sqlite3
from dataclasses import dataclass, field
from datetime import datetime, timedelta

import pytest
from daemon_fixtures import HEAVY_HOUSE, OWNER_MODE, OWNER_SETPOINT_C, OWNER_SETPOINT_RAW
from impctl_sim import SimConfig, constant_weather
from reliability_fixtures import run_virtual
from sim_fixtures import EPOCH, budget, client, simulator

from impctl.clock import VirtualClock
from impctl.controller import NightController, NightPolicy, NightRequest
from impctl.store import Store

# 3600× on a virtual-time event loop (:class:`impctl.clock.loop.VirtualTimeLoop`): the
# clock follows the loop's time, which jumps to the next timer when nothing is ready, so a
# simulated hour costs 1 s of loop time and computation none. A loaded machine makes the
# night take longer in wall time but cannot make the clock outrun the sampler (at 3600× of
# the wall clock a 120 s sample is due every 33 ms, which a busy 2-core machine misses).
SPEED = 3600.0
#: A valid constrained night needs 3 h of data after switch-off + the 1 h emission lag.
WINDOW_H = 4.5


@dataclass
class Trace:
    """What the simulator's plant showed over the night (simulated time, setpoint, mode) and
    the committed sample counts seen through a second connection."""

    plant: list[tuple[datetime, float, int]] = field(default_factory=list)
    committed: list[int] = field(default_factory=list)


async def _watch(sim, clock: VirtualClock, db_path, trace: Trace, done: asyncio.Event) -> None:
    other = sqlite3.connect(db_path)  # a second connection: sees only committed rows
    try:
        while not done.is_set():
            trace.plant.append((clock.now(), sim.plant.setpoint_c, sim.plant.loop_mode))
            trace.committed.append(other.execute("SELECT COUNT(*) FROM samples").fetchone()[0])
            await asyncio.sleep(0.01)
    finally:
        other.close()


def _loop_clock() -> VirtualClock:
    """The simulated clock of the running (virtual-time) loop, :data:`SPEED` × its time."""
    loop = asyncio.get_running_loop()
    return VirtualClock(EPOCH, SPEED, loop.time(), wall=loop.time)


async def _run_night(tmp_path, kind: str, setpoint_c: float):
    clock = _loop_clock()
    cfg = SimConfig(clock=clock, house=HEAVY_HOUSE, weather=constant_weather(0.0),
                    setpoint_c=OWNER_SETPOINT_C, plant_kind="iso")
    policy = NightPolicy(sample_interval_s=120.0, preheat_h=1.0)
    db_path = tmp_path / "impctl.db"
    async with simulator(cfg) as sim, client(sim, budget=budget(tmp_path)) as hp:
        with Store(db_path) as store:
            start = clock.now() + timedelta(hours=1, minutes=5)
            req = NightRequest(kind, setpoint_c, start, start + timedelta(hours=WINDOW_H))
            ctl = NightController(hp, store, clock, policy)
            trace, done = Trace(), asyncio.Event()
            watcher = asyncio.create_task(_watch(sim, clock, db_path, trace, done))
            night = await ctl.run(req)
            done.set()
            await watcher
            result = dict(
                night=night, req=req, trace=trace, samples=store.samples(night.id),
                pending=store.journal_pending(), events=store.events(50),
                plant=(sim.plant.setpoint_c, sim.plant.loop_mode),
                registers=((await sim.read_words(2187))[0], (await sim.read_words(2042))[0]),
                writes=dict(sim.stats.writes))
    return result


def _check_restored_and_recorded(r) -> None:
    night, req = r["night"], r["req"]
    # The owner's state is back on the heat pump itself, and nothing is left pending.
    assert r["plant"] == (OWNER_SETPOINT_C, OWNER_MODE)
    assert r["registers"] == (OWNER_SETPOINT_RAW, OWNER_MODE)
    assert r["pending"] == []
    assert any("restored loop1_setpoint" in m for _, _, m in r["events"])
    # Samples: committed one by one while the night ran (another connection saw them grow),
    # covering the preheat and the whole window.
    counts = r["trace"].committed
    assert counts[-1] == len(r["samples"])
    assert len({c for c in counts if 0 < c < counts[-1]}) > 10
    in_window = [s for s in r["samples"] if req.window_start <= s.ts <= req.window_end]
    assert len(in_window) >= 0.9 * (WINDOW_H * 3600 / 120)
    assert all(s.t_air_c is not None and s.q_hc_w is not None and s.t_out_c == 0.0
               for s in r["samples"])
    # Assessed: done, valid, with the reason it ended.
    assert night.state == "done"
    assert night.valid is True, night.reasons
    assert night.reasons[0] == "window ended"
    assert night.started is not None and night.ended >= req.window_end


def test_constrained_night_switches_off_then_restores(tmp_path):
    r = run_virtual(_run_night(tmp_path, "constrained", 21.0), timeout_s=60)
    req, trace = r["req"], r["trace"]
    act = req.window_start - timedelta(hours=1)
    preheat = [(sp, mode) for t, sp, mode in trace.plant
               if act + timedelta(minutes=10) < t < req.window_start]
    window = [(sp, mode) for t, sp, mode in trace.plant
              if req.window_start + timedelta(minutes=10) < t < req.window_end]
    assert preheat and window
    # Preheat: the setpoint at T_max = T_set + ΔT, heating on.
    assert set(preheat) == {(req.t_max_c, 1)}
    # The window: loop 1 switched off (mode 0, the configured "loop_off" action).
    assert {mode for _, mode in window} == {0}
    # The samples say the same (they record what the heat pump reported).
    window_samples = [s for s in r["samples"]
                      if s.ts > req.window_start + timedelta(minutes=10)]
    assert {s.loop_mode for s in window_samples} == {0}
    assert max(s.q_hc_w for s in window_samples) == 0.0
    # A valid constrained night never reached T_min in this heavy house.
    assert min(s.t_air_c for s in r["samples"]) > req.t_min_c
    # Two writes each of 2187 and 2042: the night's own and the restore.
    assert r["writes"] == {2187: 2, 2042: 2}
    _check_restored_and_recorded(r)


def test_normal_night_holds_setpoint_then_restores(tmp_path):
    r = run_virtual(_run_night(tmp_path, "normal", 22.0), timeout_s=60)
    req, trace = r["req"], r["trace"]
    act = req.window_start - timedelta(hours=1)
    during = {(sp, mode) for t, sp, mode in trace.plant
              if act + timedelta(minutes=10) < t < req.window_end}
    assert during == {(22.0, 1)}  # T_set, heating on, from the preheat to the window's end
    window_samples = [s for s in r["samples"] if s.ts >= req.window_start]
    assert {s.setpoint_c for s in window_samples} == {22.0}
    assert all(s.q_hc_w > 0 for s in window_samples)
    # The house was held near T_set (the point of a normal night).
    assert abs(window_samples[-1].t_air_c - 22.0) < 0.3
    assert r["writes"] == {2187: 2}  # mode already 1: never written (no EEPROM wear)
    _check_restored_and_recorded(r)


@pytest.mark.parametrize("kind", ["constrained", "normal"])
def test_a_second_night_journals_the_owner_again(tmp_path, kind):
    """Two nights in a row on one store: the second journal entry is the owner's value, never
    a value impctl wrote itself."""
    async def body():
        clock = _loop_clock()
        cfg = SimConfig(clock=clock, house=HEAVY_HOUSE, weather=constant_weather(0.0),
                        setpoint_c=20.5)
        policy = NightPolicy(sample_interval_s=300.0, preheat_h=0.5, min_coverage=0.5)
        async with simulator(cfg) as sim, client(sim, budget=budget(tmp_path)) as hp:
            with Store(tmp_path / "impctl.db") as store:
                ctl = NightController(hp, store, clock, policy)
                for _ in range(2):
                    start = clock.now() + timedelta(minutes=31)
                    night = await ctl.run(NightRequest(kind, 22.0, start,
                                                       start + timedelta(hours=1)))
                    assert night.state == "done"
                    assert (sim.plant.setpoint_c, sim.plant.loop_mode) == (20.5, 1)
                assert store.journal_pending() == []
                raws = store._db.execute(
                    "SELECT register, raw_value FROM journal ORDER BY id").fetchall()
                assert [tuple(r) for r in raws] == [("loop1_setpoint", 205), ("loop1_mode", 1)] * 2
    run_virtual(body(), timeout_s=60)
