"""The heating curve on the in-process daemon rig (real simulator, the tests' TCP proxy, a real
SQLite store, one accelerated clock): a curve write whose read-back never came, and the owner
recording while impctl's curve is set.

What is promised:

* a point written and not read back (the link dropped right after the write) is never taken
  for the owner's change: the owner's points stay journaled, impctl sets its curve again when
  the link is back, and a stop gives the owner's points back;
* while the owner has impctl's curve set, the house is still recorded between nights (the
  curve's journal entries are pending on purpose, not a restore waiting).
"""

from __future__ import annotations

import json
import sqlite3
from datetime import timedelta
from pathlib import Path

from reliability_fixtures import QUICK_LINK, daemon_rig, run_virtual

SPEED = 600.0
LINK = {**QUICK_LINK, "writes": {"verify_delay_s": 0.0}}


def _asked(state: Path) -> None:
    state.mkdir(parents=True, exist_ok=True)
    (state / "curve-intent.json").write_text(json.dumps({"apply": True, "why": "the test"}))


def _kept(state: Path, points: tuple[float, float]) -> None:
    (state / "curve.json").write_text(json.dumps({
        "schema": "impctl-curve/1", "lowers": True, "advice": "Your heating runs hot.",
        "recommended": {"t_out_c": [-15.0, 15.0], "flow_c": list(points),
                        "flow_at_0_c": sum(points) / 2}}))


def _raw(points: tuple[float, float]) -> tuple[int, int]:
    return round(points[0] * 10), round(points[1] * 10)


async def _curve_set(rig, state: Path) -> tuple[tuple[int, int], tuple[float, float]]:
    """A kept curve 4 K and 2 K below the owner's points, set and held: (the owner's raw
    points, impctl's points [°C])."""
    owner = (rig.sim.rw[2309], rig.sim.rw[2314])
    points = ((owner[0] - 40) / 10.0, (owner[1] - 20) / 10.0)
    _kept(state, points)
    await rig.until(lambda: rig.daemon.curve.held == points, 60)
    return owner, points


def test_a_curve_point_written_without_a_read_back_is_never_the_owners(tmp_path):
    state = tmp_path / "state"
    _asked(state)
    seen = {}

    async def body():
        async with daemon_rig(tmp_path, speed=SPEED, heatpump=LINK) as rig:
            def points():
                return rig.sim.rw[2309], rig.sim.rw[2314]
            seen["owner"] = points()
            first = ((seen["owner"][0] - 40) / 10.0, (seen["owner"][1] - 20) / 10.0)
            _kept(state, first)
            await rig.until(lambda: rig.daemon.curve.held == first, 60)
            # a new fit, 2 K and 1 K lower: the first point's write lands, then the link drops
            second = (first[0] - 2.0, first[1] - 1.0)
            rig.proxy.set("down-after-write")
            _kept(state, second)
            await rig.until(lambda: rig.proxy.mode == "down", 60)
            assert points() == (_raw(second)[0], _raw(first)[1])   # half of the move landed
            await rig.sim_minutes(60)
            rig.proxy.set("pass")
            await rig.until(lambda: rig.daemon.curve.held == second, 60)
            assert points() == _raw(second)
            seen["db"] = rig.daemon.cfg.db_path
            seen["intent"] = json.loads((state / "curve-intent.json").read_text())
        seen["after"] = points()

    run_virtual(body(), 200)
    assert seen["intent"]["apply"] is True
    with sqlite3.connect(seen["db"]) as con:
        outcomes = [o for (o,) in con.execute("SELECT outcome FROM journal")]
    assert not any(o and o.startswith("owner changed") for o in outcomes), outcomes
    assert seen["after"] == seen["owner"]   # the stop gave the owner's points back


def test_the_house_is_recorded_while_impctls_curve_is_set(tmp_path):
    state = tmp_path / "state"
    _asked(state)

    async def body():
        async with daemon_rig(tmp_path, speed=SPEED, night={"sample_interval_s": 120},
                              record={"keep_days": 7}) as rig:
            _, points = await _curve_set(rig, state)
            set_at = rig.clock.now()
            end = set_at + timedelta(hours=3)
            await rig.until(lambda: rig.clock.now() >= end, 3 * 3600 / SPEED + 30)
            rows = [s for r in rig.store.owner_records() for s in rig.store.samples(r.id)
                    if s.ts >= set_at]
            assert len(rows) >= 10, len(rows)   # a row each 5 min for 3 h, less the edges
            assert [e.register for e in rig.store.journal_pending()] == [
                "loop1_curve_cold", "loop1_curve_mild"]   # still set, on purpose
    run_virtual(body(), 3 * 86400 / SPEED)


def test_a_curve_point_that_reads_as_missing_is_not_the_owners_change(tmp_path):
    state = tmp_path / "state"
    _asked(state)

    async def body():
        async with daemon_rig(tmp_path, speed=SPEED, heatpump=LINK) as rig:
            _, points = await _curve_set(rig, state)
            mark = rig.logs.mark()
            rig.sim.rw[2309] = 0x8000   # a "no value" word: the point reads as missing
            await rig.sim_minutes(10)   # several looks
            assert rig.daemon.curve.held == points
            assert not any("owner changed" in line for line in rig.logs.lines(mark))
            rig.sim.rw[2309] = _raw(points)[0]
            await rig.sim_minutes(10)
            assert rig.daemon.curve.held == points
            assert [e.register for e in rig.store.journal_pending()] == [
                "loop1_curve_cold", "loop1_curve_mild"]
    run_virtual(body(), 200)


def test_impctls_points_landing_after_impctl_restore_closed_the_journal_go_back(tmp_path):
    """``impctl restore`` in another process, while the watch writes the curve: it finds the
    owner's points still on the heat pump, marks them restored, and impctl's points land after
    it — the heat pump holds impctl's curve with nothing journaled. The watch's next look puts
    the owner's points back and sets no curve until asked again."""
    from impctl.store import Store

    state = tmp_path / "state"
    _asked(state)

    async def body():
        async with daemon_rig(tmp_path, speed=SPEED, heatpump=LINK) as rig:
            owner, points = await _curve_set(rig, state)
            assert (rig.sim.rw[2309], rig.sim.rw[2314]) == _raw(points)
            # what that `impctl restore` left: the journal closed, impctl's points on the pump
            with Store(rig.daemon.cfg.db_path, create=False) as other:
                for entry in other.journal_pending():
                    other.journal_mark_restored(entry.id)
            await rig.until(lambda: (rig.sim.rw[2309], rig.sim.rw[2314]) == owner, 60)
            assert rig.daemon.curve.held is None
            intent = json.loads((state / "curve-intent.json").read_text())
            assert intent["apply"] is False
            await rig.sim_minutes(10)
            assert (rig.sim.rw[2309], rig.sim.rw[2314]) == owner   # not set again
    run_virtual(body(), 200)
