"""The two ideal households the fleet's tests fit (``test_fleet``, ``test_fleet_guards``)."""

from __future__ import annotations

import numpy as np

from impctl.model import HouseParameters

HOUSES = HouseParameters(
    floor_area=np.array([120.0, 170.0]), wall_height=np.array([2.6, 2.7]),
    walls_area=np.array([160.0, 200.0]), windows_area=np.array([25.0, 30.0]),
    c_f=np.array([2.2, 1.2]), u_walls=np.array([0.5, 0.9]), u_windows=np.array([1.3, 1.8]),
    ach_vent=np.zeros(2), ach_infl=np.full(2, 0.01))


def two_households_nights() -> list:
    """Each house's IMP nights: 2 constrained and 3 normal, 15-min samples."""
    from impctl.population.imp_run.synth import imp_schedule, run_schedule, sample_nights

    sched = imp_schedule(2, n_constrained=2, n_normal=3, seed=5)
    sim, sp = run_schedule(HOUSES, sched)
    return [sample_nights(sim, sp, sched, i, sample_step_s=900.0, seed=i) for i in range(2)]
