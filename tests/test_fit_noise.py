"""The fit's noise model: one σ per night, estimated in the likelihood (``NightFit(noise=…)``).

A held night whose heat meter reads far noisier than the others (a cycling heat pump, a
coarse meter) must weigh less than they do; with one σ per kind of residual it weighs as much
as any other held night and its noise reaches the HLC."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_fit import HOUSE, IDEAL, RANGES

from impctl.fit.estimator import NightFit
from impctl.population.imp_run.synth import synth_nights

SEEDS = range(4, 10)
#: SD of the extra power noise on the first held night, as a share of its mean power
NOISY = 0.5


def _nights(seed: int):
    nights = list(synth_nights(HOUSE, seed=seed, sample_step_s=900.0, n_normal=4,
                               setpoints_c=(22.0, 23.0, 24.0), constrained_setpoint_c=None))
    i = next(k for k, n in enumerate(nights) if n.kind == "normal")
    q = np.asarray(nights[i].q_hc_w, float)
    rng = np.random.default_rng(seed)
    noisy = np.clip(q + rng.normal(0.0, NOISY * q.mean(), len(q)), 0.0, None)
    nights[i] = dataclasses.replace(nights[i], q_hc_w=noisy)
    return nights, nights[i].night_id, float(q.mean())


@pytest.fixture(scope="module")
def fits():
    out = []
    for seed in SEEDS:
        nights, noisy_id, mean_q = _nights(seed)
        pair = {noise: NightFit(**IDEAL, n_starts=2, per_night=False, noise=noise,
                                model_error=None).fit(nights, RANGES)
                for noise in ("kind", "night")}
        out.append((pair, noisy_id, mean_q))
    return out


def test_a_noisy_held_night_gets_its_own_sigma(fits):
    for pair, noisy_id, mean_q in fits:
        sig = pair["night"].sigma_night_
        held = {k: v for k, v in sig.items() if k != noisy_id and v > 1.0}   # W, not K
        assert len(held) == 3
        # the injected noise, seen through the fit's residuals
        assert sig[noisy_id] == pytest.approx(NOISY * mean_q, rel=0.5)
        assert sig[noisy_id] > 5.0 * max(held.values())
        # one σ per kind: every held night carries the same σ
        assert len({round(v, 6) for k, v in pair["kind"].sigma_night_.items()
                    if v > 1.0}) == 1


def test_per_night_sigma_keeps_the_noisy_night_out_of_the_hlc(fits):
    err = {noise: np.array([pair[noise].lumped_["hlc"].value / HOUSE.hlc_w_per_k - 1.0
                            for pair, _, _ in fits]) for noise in ("kind", "night")}
    rms = {k: float(np.sqrt(np.mean(v ** 2))) for k, v in err.items()}
    # one σ per kind lets the noisy night move the HLC by ~10 % (RMS over the seeds)
    assert rms["kind"] > 0.06
    assert rms["night"] < 0.5 * rms["kind"]
    assert rms["night"] < 0.04


def test_an_unknown_noise_model_is_refused():
    with pytest.raises(ValueError, match="noise"):
        NightFit(noise="sample").fit([], None)


def test_the_weights_are_in_the_json(fits):
    from impctl.fit.result.report import fit_to_dict

    pair, noisy_id, _ = fits[0]
    out = fit_to_dict(pair["night"])["fit"]
    assert out["noise"] == "night"
    # the noisy night is a held one: its σ is a power [W], named so
    assert out["sigma_per_night_w"][noisy_id] == pytest.approx(
        pair["night"].sigma_night_[noisy_id])
    assert noisy_id not in out["sigma_per_night_k"]
    kinds = {n.night_id: n.kind for n in pair["night"].nights_}
    assert set(out["sigma_per_night_k"]) == {i for i, k in kinds.items() if k == "constrained"}
    assert set(out["sigma_per_night_w"]) == {i for i, k in kinds.items() if k != "constrained"}


def test_a_second_fit_of_the_same_estimator_equals_a_fresh_fit():
    # The per-night σ of one fit must not weight the next fit's first optimisation (they
    # did while the σ lived on the estimator between fits: branch h14s).
    first, _, _ = _nights(SEEDS[0])
    second, _, _ = _nights(SEEDS[1])
    est = NightFit(**IDEAL, n_starts=2, per_night=False, model_error=None).fit(first, RANGES)
    again = est.fit(second, RANGES)
    fresh = NightFit(**IDEAL, n_starts=2, per_night=False, model_error=None).fit(second, RANGES)
    assert again.loss_ == fresh.loss_ and again.n_iter_ == fresh.n_iter_
    assert again.sigma_night_ == fresh.sigma_night_
    assert again.lumped_ == fresh.lumped_
