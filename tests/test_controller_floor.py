"""The comfort floor of a normal night above the owner's setpoint.

A normal night at T_set = 24 °C with ΔT = 2 K has T_min = 22 °C; the house starts the preheat
at the owner's 21 °C. That is the owner's own comfort, not a cold house: the night must run
(regression: every such night used to abort at once with "below T_min − margin"). A house that
really falls below the owner's setpoint − ΔT − margin must still abort.
"""

from __future__ import annotations

from datetime import timedelta

from daemon_fixtures import HEAVY_HOUSE, OWNER_SETPOINT_C
from impctl_sim import SimConfig, constant_weather
from reliability_fixtures import loop_wall, run_virtual
from sim_fixtures import EPOCH, budget, client, simulator

from impctl.clock import VirtualClock
from impctl.controller import NightController, NightPolicy, NightRequest
from impctl.heatpump import WritePolicy
from impctl.store import Store


async def _night(tmp_path, setpoint_c: float):
    clock = VirtualClock(EPOCH, 7200.0, wall=loop_wall())  # on the virtual-time loop
    cfg = SimConfig(clock=clock, house=HEAVY_HOUSE, weather=constant_weather(0.0),
                    setpoint_c=OWNER_SETPOINT_C)
    policy = NightPolicy(sample_interval_s=300.0, preheat_h=1.0)
    writes = WritePolicy(loop1_setpoint_c=(16.0, 25.0), verify_delay_s=0.0)
    async with simulator(cfg) as sim, client(sim, budget=budget(tmp_path),
                                             writes=writes) as hp:
        with Store(tmp_path / "impctl.db") as store:
            start = clock.now() + timedelta(hours=1, minutes=5)
            req = NightRequest("normal", setpoint_c, start, start + timedelta(hours=3.5),
                               comfort_band_k=2.0)
            night = await NightController(hp, store, clock, policy).run(req)
            return night, store.journal_pending(), sim.plant.setpoint_c


def test_normal_night_above_owner_setpoint_is_not_aborted(tmp_path):
    night, pending, setpoint = run_virtual(_night(tmp_path, 24.0), timeout_s=60)
    assert OWNER_SETPOINT_C < 24.0 - 2.0 - 0.5  # the old rule would have aborted at once
    assert night.state == "done", night.reasons
    assert night.reasons[0] == "window ended"
    assert pending == [] and setpoint == OWNER_SETPOINT_C
