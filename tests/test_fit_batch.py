"""Households fitted together (impctl.fit.optim.batch) give each household its single fit's numbers,
in fewer optimiser calls; one unusable household does not stop the others."""

from __future__ import annotations

import numpy as np
import pytest

from impctl.errors import InputError
from impctl.fit.estimator import NightFit
from impctl.fit.optim import lm
from impctl.fit.optim.batch import fit_households
from impctl.model import HouseParameters
from impctl.population.imp_run.synth import imp_schedule, run_schedule, sample_nights

HOUSES = HouseParameters(
    floor_area=np.array([110.0, 180.0, 140.0]), wall_height=np.array([2.6, 2.7, 2.5]),
    walls_area=np.array([150.0, 210.0, 170.0]), windows_area=np.array([20.0, 35.0, 25.0]),
    c_f=np.array([1.2, 2.6, 1.8]), u_walls=np.array([0.5, 0.35, 0.8]),
    u_windows=np.array([1.4, 1.1, 2.0]), ach_vent=np.zeros(3), ach_infl=np.full(3, 0.01))
PARAMS = {"n_starts": 2, "max_iter": 25}


@pytest.fixture(scope="module")
def fleet():
    sched = imp_schedule(3, n_constrained=2, n_normal=3, seed=3)
    sim, sp = run_schedule(HOUSES, sched)
    nights = [sample_nights(sim, sp, sched, i, sample_step_s=900.0, seed=i) for i in range(2)]
    # the third household logs hourly: its grid is not nested in the others', so it gets its
    # own merged call instead of being integrated on a finer grid than when alone
    nights.append(sample_nights(sim, sp, sched, 2, sample_step_s=3600.0, seed=2))
    ranges = [{"floor_area": (100.0, 200.0), "c_f": (0.8, 1.65), "u_walls": (0.2, 1.0)},
              None, None]
    return nights, ranges


@pytest.fixture
def lm_calls(monkeypatch):
    """The problem count of every Levenberg–Marquardt call made while the test runs."""
    calls = []
    real = lm.levenberg_marquardt

    def counted(ctx, rows, *a, **kw):
        calls.append(rows.n_problems)
        return real(ctx, rows, *a, **kw)

    monkeypatch.setattr(lm, "levenberg_marquardt", counted)
    return calls


def test_batch_matches_single_fits_with_fewer_optimiser_calls(fleet, lm_calls):
    nights, ranges = fleet
    calls = lm_calls
    alone = [NightFit(**PARAMS).fit(n, r) for n, r in zip(nights, ranges, strict=True)]
    alone_calls, alone_largest = len(calls), max(calls)
    calls.clear()
    # an unusable household in the middle: no night longer than the 3 h minimum
    short = [n.__class__(**{**n.__dict__, "time_s": n.time_s[:3], "t_air_c": n.t_air_c[:3],
                            "t_out_c": n.t_out_c[:3], "q_hc_w": n.q_hc_w[:3]})
             for n in nights[0]]
    results, stats = fit_households([nights[0], short, nights[1], nights[2]],
                                    [ranges[0], None, ranges[1], ranges[2]], **PARAMS)
    assert isinstance(results[1], InputError) and "no usable night" in str(results[1])
    batched = [results[0], results[2], results[3]]
    for a, b in zip(alone, batched, strict=True):
        assert isinstance(b, NightFit)
        for key in ("hlc", "c_m", "tau"):
            ea, eb = a.lumped_[key], b.lumped_[key]
            # each household stops where it stops alone: equal up to rounding, magnified by
            # the forward-difference Jacobian and the nuisance-term refits (~1e-5 seen)
            assert eb.value == pytest.approx(ea.value, rel=1e-4)
            assert eb.low == pytest.approx(ea.low, rel=1e-4)
            assert eb.high == pytest.approx(ea.high, rel=1e-4)
        assert b.n_iter_ == a.n_iter_
        assert b.class_check_["rejected"] == a.class_check_["rejected"]
        assert b.determined_ == a.determined_
    # the two 15-min households shared their calls: fewer optimiser calls than the single
    # fits made, and one call held more problems than any single fit
    assert stats.merged_calls == len(calls) < alone_calls
    assert max(calls) > alone_largest



def test_an_unused_group_label_does_not_keep_the_optimiser_going():
    """Without class ranges the prior-box group (label 1) has no problem: it must count as done,
    or every fit without classifiers iterates to max_iter (it did before issue 16)."""
    import torch

    loss = torch.tensor([5.0, 3.0, 7.0, 9.0], dtype=torch.float64)
    groups = torch.tensor([0, 0, 2, 2])
    done = torch.tensor([False, True, True, False])     # each used group's best is done
    assert bool(lm._best_done(loss, done, groups).all())
    assert not bool(lm._best_done(loss, torch.tensor([True, False, True, True]), groups).all())
    # a household of a merged batch stops when all its groups are done, the others go on
    units = torch.tensor([0, 0, 1])
    assert lm._units_done(torch.tensor([True, True, False]), units).tolist() == [True, False]


def test_households_with_their_own_priors_still_share_every_call(fleet, lm_calls):
    """Each household's population prior is tempered by its own residual autocorrelation, so
    no two are equal: the merged call carries one prior per household (prior.PriorSlices), and
    every optimiser round of the two 15-min households is one call — as many calls as the
    household that needs the most makes alone — with each household's single-fit numbers."""
    nights, ranges = fleet
    calls = lm_calls
    alone, per_house = [], []
    for n, r in zip(nights[:2], ranges[:2], strict=True):
        calls.clear()
        alone.append(NightFit(**PARAMS).fit(n, r))
        per_house.append(len(calls))
    assert alone[0].prior_["tempering"] != alone[1].prior_["tempering"]
    calls.clear()
    results, stats = fit_households(nights[:2], ranges[:2], **PARAMS)
    assert stats.merged_calls == len(calls) == max(per_house)
    for a, b in zip(alone, results, strict=True):
        for key in ("hlc", "c_m", "tau"):
            assert b.lumped_[key].value == pytest.approx(a.lumped_[key].value, rel=1e-4)
        assert b.prior_["parameters"]["c_m"]["posterior_to_prior_sd"] == pytest.approx(
            a.prior_["parameters"]["c_m"]["posterior_to_prior_sd"], rel=1e-3)


def test_each_households_class_probabilities_reach_its_prior(fleet):
    """The fleet passes every household's class probabilities to its population prior, as
    ``impctl fit`` does (prior.with_class_probabilities): a household fitted in a batch gets the
    prior and the numbers of its single fit with that mixture, not the unweighted box's."""
    from impctl.fit.prior import PopulationPrior

    nights, _ = fleet
    probs = {"c_f": {"0.8-1.65": 0.9, "1.65-3.7": 0.1}}
    alone = NightFit(**PARAMS, prior=PopulationPrior.of_labels(probs)).fit(nights[1], None)
    plain = NightFit(**PARAMS).fit(nights[1], None)
    results, _ = fit_households([nights[1], nights[0]], [None, None], [probs, None], **PARAMS)
    got, other = results
    assert got.prior_["class_probabilities"] == {"c_f": [[0.8, 1.65, 0.9], [1.65, 3.7, 0.1]]}
    assert other.prior_["class_probabilities"] is None
    centre = {f: f.prior_["parameters"]["c_m"]["centre"] for f in (alone, plain, got)}
    assert centre[got] == pytest.approx(centre[alone], rel=1e-9)
    assert abs(centre[plain] / centre[alone] - 1) > 0.02   # the mixture moved the prior
    assert got.lumped_["c_m"].value == pytest.approx(alone.lumped_["c_m"].value, rel=1e-4)


def test_merged_priors_are_one_penalty_equal_to_the_households_own():
    """A merged call's priors (optim.priors.MergedPrior: moments looked up once per call, one
    autograd pass for every problem) give exactly the per-household penalty of
    prior.PriorSlices — households with different tempering, boxes, and one without a prior —
    also for the running problems the optimiser takes."""
    import torch

    from impctl.fit.layout import nuisance_boxes
    from impctl.fit.nights.data import search_bounds
    from impctl.fit.ode.parameters import bounds_tensor
    from impctl.fit.optim.priors import MergedPrior
    from impctl.fit.prior import PopulationPrior, PriorSlices, penalty

    nuisance, _ = nuisance_boxes(False, True, True, False, 250.0)
    wide = bounds_tensor(search_bounds(None, None), nuisance)
    narrow = bounds_tensor(search_bounds({"c_f": (0.8, 1.65)}, None), nuisance)
    priors = tuple(PopulationPrior().tempered(1.0 + 0.4 * i) for i in range(3)) + (None,)
    owner = torch.arange(4).repeat_interleave(5)
    box = torch.stack([narrow if i % 3 else wide for i in range(20)])
    u = torch.randn(20, box.shape[1], generator=torch.Generator().manual_seed(1),
                    dtype=torch.float64)
    slices = PriorSlices(priors, owner)
    merged = MergedPrior.of(slices, box)
    for got, want in zip(merged.penalty(u, box, 0.0, 0.01), penalty(slices, u, box, 0.0, 0.01),
                         strict=True):
        assert torch.equal(got, want)
    assert not bool(merged.penalty(u, box, 0.0, 0.01)[0][owner == 3].any())  # no prior
    keep = torch.tensor([0, 6, 7, 13, 19])
    for got, want in zip(merged.take(keep).penalty(u[keep], box[keep], 0.0, 0.01),
                         penalty(slices.take(keep), u[keep], box[keep], 0.0, 0.01), strict=True):
        assert torch.equal(got, want)


def test_a_merged_call_evaluates_its_priors_once_not_per_household(fleet, monkeypatch):
    """The merged calls of a batch evaluate every household's prior in one pass per
    iteration: the per-household prior penalty (prior.penalty, one autograd pass and one
    moments lookup per household per iteration — a quarter of a fleet batch's optimiser time
    before) is never called inside them."""
    from impctl.fit import prior as prior_module

    nights, ranges = fleet
    merged_calls, inside, per_household = [], [False], []
    real_lm, real_penalty = lm.levenberg_marquardt, prior_module.penalty

    def counted_lm(ctx, rows, *a, **kw):
        # more nights than either household has: both households' problems in one call
        merged = ctx.packed.n_nights > max(len(n) for n in nights[:2])
        merged_calls.append(merged)
        inside[0] = merged
        try:
            return real_lm(ctx, rows, *a, **kw)
        finally:
            inside[0] = False

    def counted_penalty(*a, **kw):
        if inside[0]:
            per_household.append(1)
        return real_penalty(*a, **kw)

    monkeypatch.setattr(lm, "levenberg_marquardt", counted_lm)
    monkeypatch.setattr(lm, "prior_penalty", counted_penalty)
    results, stats = fit_households(nights[:2], ranges[:2], **PARAMS)
    assert all(isinstance(r, NightFit) for r in results)
    assert any(merged_calls)
    assert per_household == []


def test_merged_calls_hold_their_households_in_batch_order(fleet, monkeypatch):
    """A merged call packs its households in batch order, not in the order their threads
    reached the rendezvous: a problem's place in the merged tensors can change the last bit
    of its rounding, so thread timing made a batch's numbers differ from run to run."""
    from impctl.fit.optim import batch

    orders = []
    real = batch._solve_group

    def recorded(group):
        orders.append([p.household for p in group])
        return real(group)

    monkeypatch.setattr(batch, "_solve_group", recorded)
    nights, ranges = fleet
    fit_households(nights[:2] * 2, ranges[:2] * 2, **PARAMS)
    assert any(len(o) > 1 for o in orders)
    assert all(o == sorted(o) for o in orders)


def test_one_household_thread_runs_at_a_time(fleet, monkeypatch):
    """Between merged calls the households' own work runs one thread at a time: torch
    releases the GIL in every operation, and many runnable threads turned each release into a
    handoff between them (half a batch's CPU). The estimator's steps here sleep, which lets
    any other runnable household in; none may be."""
    import threading
    import time

    from impctl.fit import estimator

    inside, most = [0], [0]
    lock = threading.Lock()
    real = {"prepare": estimator.prepare, "statement": estimator.statement}

    def crowded(name):
        def step(*a, **kw):
            with lock:
                inside[0] += 1
                most[0] = max(most[0], inside[0])
            time.sleep(0.02)
            try:
                return real[name](*a, **kw)
            finally:
                with lock:
                    inside[0] -= 1
        return step

    for name in real:
        monkeypatch.setattr(estimator, name, crowded(name))
    nights, ranges = fleet
    results, _ = fit_households(nights, ranges, **PARAMS)
    assert all(isinstance(r, NightFit) for r in results)
    assert most[0] == 1


def test_a_household_whose_prior_cannot_be_built_does_not_hold_up_the_batch(fleet):
    """A household that fails before its fit starts (its class probabilities name no class)
    gets its exception; the others are fitted and the batch returns."""
    import threading

    nights, ranges = fleet
    out = []
    batch = threading.Thread(target=lambda: out.append(fit_households(
        nights[:2], ranges[:2], [None, "not a mapping"], **PARAMS)), daemon=True)
    batch.start()
    batch.join(timeout=120)
    assert out, "the batch never returned"
    results, _ = out[0]
    assert isinstance(results[0], NightFit)
    assert isinstance(results[1], BaseException)
