"""The watch's check that the controller follows impctl's curve points, against a controller
that works out its flow target (2128) on a cycle of its own, longer than the watch's looks.

The in-process daemon rig (real simulator, the tests' TCP proxy, a real SQLite store) on
virtual time: the simulated controller works out 2128 once per model step, so a model step of
4 simulated minutes against a look each minute puts the writes between two of its updates,
the same way on every run. The tests act right after a model step.

What is promised:

* a controller that follows is never judged as not following, however soon after its last
  update the curve was set: the check is judged on a flow target read once impctl's points
  have stood long enough for the controller to have worked it out;
* nor when the owner's points went back just before the curve is set again (``impctl curve
  --restore`` then ``--apply``; so too the daemon's start putting them back): the baseline is
  a flow target read once the points found have stood that long, not one still saying what
  impctl's curve asked for;
* a controller that does not follow is still caught (``test_curve_daemon``).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from reliability_fixtures import daemon_rig, run_virtual

from impctl.daemon.curve.intent import set_intent

SPEED = 60.0               # a look each simulated minute (the rig's sample interval)
SLOW_STEP_S = 240.0        # the controller's cycle: 2128 worked out each 4 simulated minutes
QUICK_STEP_S = 6.0         # … each simulated tick of the simulator
FOLLOWED = "heating curve followed"
NOT_FOLLOWED = "did not follow"


def _curve_asked(tmp_path: Path) -> Path:
    """A state directory in which the owner has asked for the curve."""
    state = tmp_path / "state"
    state.mkdir()
    set_intent(state, True, "the test")
    return state


def _kept_quick(rig, state: Path) -> tuple[tuple[int, int], tuple[float, float]]:
    """A controller that updates every few seconds, and a curve below the owner's points
    kept for it: (the owner's raw points, the curve [°C])."""
    rig.sim.config.step_s = QUICK_STEP_S
    owner, points = _lowered(rig)
    _kept(state, points)
    return owner, points


def _kept(state: Path, points: tuple[float, float]) -> None:
    state.mkdir(parents=True, exist_ok=True)
    (state / "curve.json").write_text(json.dumps({
        "schema": "impctl-curve/1", "lowers": True, "advice": "Your heating runs hot.",
        "recommended": {"t_out_c": [-15.0, 15.0], "flow_c": list(points),
                        "flow_at_0_c": sum(points) / 2}}))


def _lowered(rig) -> tuple[tuple[int, int], tuple[float, float]]:
    """(the owner's raw points, a curve 4 K and 2 K below them [°C])."""
    owner = (rig.sim.rw[2309], rig.sim.rw[2314])
    return owner, ((owner[0] - 40) / 10.0, (owner[1] - 20) / 10.0)


async def _just_updated(rig) -> None:
    """Return right after the simulated controller worked out its flow target."""
    steps = rig.sim.stats.steps
    await rig.until(lambda: rig.sim.stats.steps > steps, 30)


def _said(rig, text: str) -> int:
    return sum(text in line for line in rig.logs.lines(level=logging.INFO))


def test_a_controller_slower_than_the_looks_is_judged_once_it_has_worked_out_its_target(
        tmp_path):
    state = _curve_asked(tmp_path)

    async def body():
        async with daemon_rig(tmp_path, speed=SPEED) as rig:
            rig.sim.config.step_s = SLOW_STEP_S
            owner, points = _lowered(rig)
            await _just_updated(rig)
            _kept(state, points)   # set at a look before the controller's next update
            await rig.until(lambda: _said(rig, FOLLOWED) or _said(rig, NOT_FOLLOWED), 60)
            assert _said(rig, NOT_FOLLOWED) == 0, rig.logs.lines(level=logging.INFO)
            assert rig.daemon.curve.held == points
            assert (rig.sim.rw[2309], rig.sim.rw[2314]) == (owner[0] - 40, owner[1] - 20)
    run_virtual(body(), 600)


def test_the_owners_points_put_back_just_before_the_curve_is_set_again_are_not_its_baseline(
        tmp_path):
    state = _curve_asked(tmp_path)

    async def body():
        async with daemon_rig(tmp_path, speed=SPEED) as rig:
            owner, points = _kept_quick(rig, state)
            await rig.until(lambda: _said(rig, FOLLOWED) or _said(rig, NOT_FOLLOWED), 60)
            assert _said(rig, FOLLOWED) == 1 and _said(rig, NOT_FOLLOWED) == 0
            # from now on the controller works its target out each 4 minutes: the owner's
            # points go back and the curve is asked for again between two of its updates
            rig.sim.config.step_s = SLOW_STEP_S
            await _just_updated(rig)
            set_intent(state, False, "impctl curve --restore")
            await rig.until(lambda: rig.daemon.curve.held is None
                            and (rig.sim.rw[2309], rig.sim.rw[2314]) == owner, 30)
            set_intent(state, True, "impctl curve --apply")
            await rig.until(lambda: _said(rig, FOLLOWED) == 2 or _said(rig, NOT_FOLLOWED), 60)
            assert _said(rig, NOT_FOLLOWED) == 0, rig.logs.lines(level=logging.INFO)
            assert rig.daemon.curve.held == points
            assert (rig.sim.rw[2309], rig.sim.rw[2314]) == (owner[0] - 40, owner[1] - 20)
    run_virtual(body(), 600)


def test_a_setpoint_changed_before_the_verdict_voids_the_check_instead_of_failing_it(tmp_path):
    """The owner raises the loop-1 setpoint 2.5 K right after impctl sets its curve: the
    controller's flow target moves with the setpoint as well as with the points, so the move
    says nothing of whether it follows them — the check is not judged, the curve stays."""
    state = _curve_asked(tmp_path)

    async def body():
        async with daemon_rig(tmp_path, speed=SPEED) as rig:
            owner, points = _kept_quick(rig, state)
            await rig.until(lambda: (rig.sim.rw[2309], rig.sim.rw[2314])
                            == (owner[0] - 40, owner[1] - 20), 60)
            # the owner's panel: the setpoint and the plant it drives (not a Modbus write)
            rig.sim.rw[2187] += 25
            rig.sim.plant.setpoint_c = rig.sim.rw[2187] / 10.0
            await rig.until(lambda: _said(rig, "follow check not judged")
                            or _said(rig, FOLLOWED) or _said(rig, NOT_FOLLOWED), 60)
            assert _said(rig, NOT_FOLLOWED) == 0, rig.logs.lines(level=logging.INFO)
            assert _said(rig, "follow check not judged") == 1
            assert rig.daemon.curve.held == points
            assert (rig.sim.rw[2309], rig.sim.rw[2314]) == (owner[0] - 40, owner[1] - 20)
    run_virtual(body(), 600)
