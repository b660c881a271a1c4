"""The daemon's stop ends inside the unit's ``TimeoutStopSec``: one budget for the night's own
restore, the owner recording's last row and the stop's own restore, so that systemd never has
to kill a stop that is still working, and what is left pending stays in the journal for the
unit's ``ExecStopPost`` (``impctl restore``).

On a virtual-time event loop (:func:`~reliability_fixtures.run_virtual`) at the real clock's
speed: the minutes a lost link makes the stop wait pass at once, and are measured on the loop's
clock, the one the budget is counted on.
"""

from __future__ import annotations

import asyncio
import re
from pathlib import Path

from reliability_fixtures import QUICK_LINK, daemon_rig, run_virtual

from impctl.daemon import stopping
from impctl.store import Store

ROOT = Path(__file__).resolve().parents[1]


def _unit_stop_timeout_s() -> float:
    text = (ROOT / "deploy" / "impctl.service").read_text()
    found = re.search(r"^TimeoutStopSec=(\d+)s$", text, re.MULTILINE)
    assert found, "deploy/impctl.service sets no TimeoutStopSec in seconds"
    return float(found.group(1))


def test_the_stop_budget_fits_inside_the_units_stop_timeout():
    from impctl.mqtt.bridge import STOP_TIMEOUT_S

    # after the budget: a last Modbus try running over it, the MQTT "offline", the closes
    assert stopping.STOP_BUDGET_S + STOP_TIMEOUT_S + 10.0 <= _unit_stop_timeout_s()
    # the night's share leaves the recorder's last row and a real restore try
    assert stopping.AFTER_NIGHT_S >= 2 * stopping.RESTORE_MIN_S
    assert stopping.STOP_BUDGET_S - stopping.AFTER_NIGHT_S >= 30.0  # the night's own restore


def test_a_stop_while_the_link_is_down_ends_within_its_budget_and_keeps_the_journal(tmp_path):
    """The gateway goes away mid constrained night, then the daemon is told to stop: the
    night's own restore retries (its own limit is an hour) and the owner recording waits on
    the link too. The stop gives up at its budget — not 80 + 30 + 60 s later, past systemd's
    kill — and the owner's settings stay journaled for ``impctl restore``."""

    async def body() -> None:
        loop = asyncio.get_running_loop()
        async with daemon_rig(tmp_path, speed=1.0, name="stop", heatpump=QUICK_LINK,
                              night={"window": "22:00-02:00", "link_lost_limit_s": 3600}
                              ) as rig:
            nid = await rig.trigger("constrained")
            await rig.until(lambda: rig.switched_off(nid), timeout_s=3 * 3600)
            await rig.sim_minutes(5, timeout_s=600)
            rig.proxy.set("down")
            await rig.sim_minutes(2, timeout_s=600)
            mark = rig.logs.mark()
            started = loop.time()
            rig.daemon.stop.set()
            await asyncio.wait_for(rig.task, 3600)
            took = loop.time() - started
            assert took <= stopping.STOP_BUDGET_S + 10.0, took
            # it did wait for the night's restore, as long as the budget lets it
            assert took >= stopping.STOP_BUDGET_S - stopping.AFTER_NIGHT_S - 1.0, took
            assert rig.sim.plant.loop_mode == 0   # nothing could reach the heat pump
            lines = rig.logs.lines(mark)
            assert any("night did not finish cleanly on stop" in line for line in lines), lines
            assert any("restore incomplete" in line for line in lines), lines
        with Store(tmp_path / "state" / "impctl.db") as store:  # the daemon closed its own
            registers = {e.register for e in store.journal_pending()}
        assert {"loop1_mode", "loop1_setpoint"} <= registers, registers

    run_virtual(body(), 6 * 3600)
