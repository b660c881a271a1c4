"""A constrained night's heated recovery after T_min as data (``NightFit(recovery=True)``):
the samples are kept, the emitter's charging hour is not compared, and cooling and recovery
share one mass state — which gives the cooling night the absolute scale (the heat) it lacks."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from impctl.fit.estimator import NightFit
from impctl.fit.nights.data import RECOVERY_CHARGING_H, prepare_nights, resume_time
from impctl.fit.ode.packing import pack_nights
from impctl.model import HouseParameters
from impctl.population.imp_run.synth import imp_schedule, run_schedule, sample_nights

#: a heavy, well-insulated house: the gateway's constrained nights reach T_min after 3–4 h
HOUSE = HouseParameters(floor_area=120.0, wall_height=2.6, walls_area=180.0, windows_area=25.0,
                        c_f=1.65, u_walls=0.3, u_windows=1.4, ach_vent=0.0, ach_infl=0.01)
RANGES = {"floor_area": (100.0, 200.0), "c_f": (0.8, 1.65), "u_walls": (0.2, 1.0)}
#: the ideal 5R1C has no gains and its simulated sensors no offsets
IDEAL = {"night_gain_w": 0.0, "sensor_offsets_k": (0.0, 0.0), "model_error": None,
         "n_starts": 2, "per_night": False, "min_night_h": 1.5}


@pytest.fixture(scope="module")
def simulated():
    sched = imp_schedule(1, seed=3, n_normal=2)
    sim, sp = run_schedule(HOUSE, sched, stop_at_t_min=True)
    return {rec: sample_nights(sim, sp, sched, 0, sample_step_s=300.0, seed=3, recovery=rec)
            for rec in (False, True)}


def _constrained(nights):
    return [n for n in nights if n.kind == "constrained"]


def test_the_recovery_is_kept_only_with_the_option(simulated):
    night = _constrained(simulated[True])[0]
    t_res = resume_time(night)
    assert 2 * 3600 < t_res < 5 * 3600          # heating resumed at T_min, well before 05:00
    (cut,), _, _ = prepare_nights([night], min_hours=1.5)
    (kept,), _, _ = prepare_nights([night], min_hours=1.5, recovery=True)
    assert cut.time_s[-1] < t_res
    assert kept.time_s[-1] == pytest.approx(night.time_s[-1])
    assert (kept.q_hc_w[kept.time_s >= t_res] > 0).all()
    # the validity rule stays on the cooling: under 3 h of it → skipped, recovery or not …
    _, _, skipped = prepare_nights([night], recovery=True)
    assert skipped and "under the 3 h minimum" in skipped[0][1]
    # … unless a shorter cooling is allowed when cooling and recovery cover the 3 h together
    kept, _, skipped = prepare_nights([night], recovery=True, min_cooling_h=1.0)
    assert len(kept) == 1 and not skipped
    kept, _, skipped = prepare_nights([night], recovery=True, min_cooling_h=t_res / 3600.0)
    assert not kept


def test_the_heat_after_the_resume_drives_the_row_and_its_charging_hours_are_not_compared(
        simulated):
    night = _constrained(simulated[True])[0]
    (kept,), offsets, _ = prepare_nights([night], min_hours=1.5, recovery=True)
    t_res = resume_time(kept)
    charging_s = RECOVERY_CHARGING_H * 3600.0
    packed = pack_nights([kept], offsets, resume_s=[t_res], charging_s=charging_s)
    t = np.asarray(kept.time_s) - offsets[0]
    resumed = packed.resumed[0].numpy()[:len(t)]
    mask = packed.mask[0].numpy()[:len(t)]
    np.testing.assert_array_equal(resumed, np.asarray(kept.time_s) >= t_res)
    stamps = np.asarray(kept.time_s)
    charging = (stamps >= t_res) & (stamps < t_res + charging_s)
    assert 0 < charging.sum() < (stamps >= t_res).sum()   # some of the recovery is compared
    np.testing.assert_array_equal(mask, ~charging)
    # without the resume the same samples are all compared and nothing resumes
    plain = pack_nights([kept], offsets)
    assert plain.resumed is None and bool(plain.mask[0, :len(t)].all())


def test_cooling_and_recovery_share_one_mass_state_and_give_the_hlc(simulated):
    # Constrained nights alone give τ but no absolute scale (no heat is metered while the
    # house cools); their recovery meters the heat into the same mass state, the QUB idea:
    # the HLC follows from one cooling and one heated phase of one night.
    fits = {rec: NightFit(**IDEAL, recovery=rec).fit(_constrained(simulated[rec]), RANGES)
            for rec in (False, True)}
    without, with_ = (fits[r].lumped_["hlc"] for r in (False, True))
    assert without.high / without.low > 2.0           # the range, not the data
    assert with_.high / with_.low < 1.3
    assert abs(with_.value / HOUSE.hlc_w_per_k - 1.0) < 0.05
    assert with_.low <= HOUSE.hlc_w_per_k <= with_.high
    assert abs(fits[True].lumped_["tau"].value / HOUSE.tau_h - 1.0) < 0.10
    # one initial mass temperature per night: the recovery is no night of its own
    assert sorted(fits[True].t_m0_c_) == sorted(n.night_id for n in _constrained(simulated[True]))


def test_with_the_held_nights_the_recovery_fit_is_as_good_on_the_ideal_5r1c(simulated):
    fits = {rec: NightFit(**IDEAL, recovery=rec).fit(simulated[rec], RANGES)
            for rec in (False, True)}
    for rec, fit in fits.items():
        for name, truth in (("hlc", HOUSE.hlc_w_per_k), ("tau", HOUSE.tau_h)):
            est = fit.lumped_[name]
            assert abs(est.value / truth - 1.0) < 0.05, (rec, name, est)
            assert est.low <= truth <= est.high


def test_a_normal_night_has_no_resume():
    night = dataclasses.replace(
        _one_normal(), q_hc_w=np.full(len(_one_normal().time_s), 3000.0))
    assert resume_time(night) == float("inf")


def _one_normal():
    sched = imp_schedule(1, seed=1, n_normal=1, n_constrained=0)
    sim, sp = run_schedule(HOUSE, sched)
    return sample_nights(sim, sp, sched, 0, seed=1)[0]


def test_the_fleet_merges_households_with_and_without_a_recovery(simulated):
    from impctl.fit.optim.batch import _merge_packed

    night = _constrained(simulated[True])[0]
    (kept,), offsets, _ = prepare_nights([night], min_hours=1.5, recovery=True)
    (cut,), offsets_cut, _ = prepare_nights([night], min_hours=1.5)
    with_ = pack_nights([kept], offsets, resume_s=[resume_time(kept)])
    without = pack_nights([cut], offsets_cut)
    merged = _merge_packed([without, with_])
    k = with_.grid_s.shape[1]
    assert merged.resumed.shape == (2, k)
    assert not merged.resumed[0].any()
    assert bool((merged.resumed[1] == with_.resumed[0]).all())
