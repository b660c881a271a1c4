"""``NightController.abort``: the household's stop (issue 17) ends a night at once, mid-sleep,
and restores the owner's settings — on the real simulator and store."""

from __future__ import annotations

import asyncio
import time

from test_controller_aborts import Rig, _rig


def test_abort_wakes_a_long_sleep_and_restores(tmp_path):
    async def body(rig: Rig):
        assert rig.ctl.abort("nobody home") is False  # no night running: nothing to do
        req = rig.request("constrained", preheat_min=31.0)
        task = asyncio.create_task(rig.ctl.run(req))
        # Preheat written (T_max = 22.5 °C); the controller now sleeps 3 h = 1.5 s real.
        while rig.sim.plant.setpoint_c != 22.5:
            await asyncio.sleep(0.01)
        await asyncio.sleep(0.2)
        t0 = time.monotonic()
        assert rig.ctl.abort("aborted on request (mqtt)") is True
        night = await task
        assert time.monotonic() - t0 < 1.0  # woke up, did not finish the 1.5 s sleep
        assert (night.state, night.valid) == ("aborted", False)
        assert night.reasons[0] == "aborted on request (mqtt)"
        await rig.owner_state_back()
        # The next night is not aborted by the old request.
        req2 = rig.request("normal", 21.0, preheat_min=1.0, window_h=0.5)
        night2 = await rig.ctl.run(req2)
        assert night2.state == "done", night2.reasons
    _rig(tmp_path, body, sample_interval_s=3 * 3600.0)
