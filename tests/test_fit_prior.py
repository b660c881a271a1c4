"""The population prior inside the class ranges (impctl.fit.prior, issue 14 h14z): a MAP
penalty whose information is said, never presented as measured."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from impctl.fit.estimator import NightFit
from impctl.fit.nights.data import search_bounds
from impctl.fit.ode.parameters import DTYPE, bounds_tensor
from impctl.fit.optim import lm
from impctl.fit.prior import PopulationPrior
from impctl.fit.result.report import fit_to_dict
from impctl.model import HouseParameters
from impctl.population.households import sample_population
from impctl.population.imp_run.synth import synth_nights

HOUSE = HouseParameters(floor_area=150.0, wall_height=2.6, walls_area=200.0, windows_area=30.0,
                        c_f=1.65, u_walls=0.6, u_windows=1.4, ach_vent=0.0, ach_infl=0.01)
RANGES = {"floor_area": (100.0, 200.0), "c_f": (0.8, 1.65), "u_walls": (0.2, 1.0)}
IDEAL = {"night_gain_w": 0.0, "model_error": None, "sensor_offsets_k": (0.0, 0.0)}


@pytest.fixture(scope="module")
def nights():
    return synth_nights(HOUSE, seed=4, sample_step_s=900.0, n_normal=4,
                        setpoints_c=(22.0, 23.0, 24.0), constrained_setpoint_c=None)


def _box(ranges):
    return bounds_tensor(search_bounds(ranges))[None]


def test_the_prior_is_the_populations_distribution_inside_the_box():
    prior = PopulationPrior(n_households=4000)
    mu, sd = prior.moments(_box(RANGES))
    table = sample_population(4000, 0)
    inside = ((table.floor_area >= 100) & (table.floor_area <= 200)
              & (table.c_f >= 0.8) & (table.c_f <= 1.65) & (table.u_walls <= 1.0))
    log_cm = np.log(table.c_m_j_per_k[inside].to_numpy())
    assert float(mu[0, 0]) == pytest.approx(log_cm.mean(), rel=1e-9)
    assert float(sd[0, 0]) == pytest.approx(log_cm.std(), rel=1e-9)
    # the whole population is wider than one class
    _, sd_all = prior.moments(_box(None))
    assert float(sd_all[0, 0]) > 1.5 * float(sd[0, 0])
    # a mixture that puts every probability on one class is that class's prior
    sure = PopulationPrior.of_classes(
        {"floor_area": [((60.0, 100.0), 0.0), ((100.0, 200.0), 1.0), ((200.0, 300.0), 0.0)],
         "c_f": [((0.8, 1.65), 1.0), ((1.65, 3.7), 0.0)],
         "u_walls": [((0.2, 1.0), 1.0), ((1.0, 2.0), 0.0)]}, n_households=4000)
    assert sure == PopulationPrior.of_labels(      # the classifiers' form
        {"floor_area": {"60-100": 0.0, "100-200": 1.0, "200-300": 0.0},
         "c_f": {"0.8-1.65": 1.0, "1.65-3.7": 0.0}, "u_walls": {"0.2-1": 1.0, "1-2": 0.0}},
        n_households=4000)
    mu_mix, sd_mix = sure.moments(_box(None))
    assert float(mu_mix[0, 0]) == pytest.approx(float(mu[0, 0]), abs=1e-9)
    assert float(sd_mix[0, 0]) == pytest.approx(float(sd[0, 0]), abs=1e-9)


def test_the_penalty_is_the_gradient_of_the_prior_loss():
    prior = PopulationPrior(quantities=("c_m", "tau"), n_households=4000)
    ctx = lm.Context(None, 0.0, 0.01, ridge=1e-2, prior=prior)
    box = _box(RANGES).expand(3, -1, -1)
    u = torch.tensor(np.random.default_rng(1).normal(size=(3, 7)), dtype=DTYPE)
    loss, h, g = lm.penalty(ctx, u, box)
    uu = u.clone().requires_grad_(True)
    direct = (prior.residuals(uu, box, 0.0, 0.01) ** 2).sum(1) + 1e-2 * (uu ** 2).sum(1)
    grad = torch.autograd.grad(direct.sum(), uu)[0]
    assert torch.allclose(loss, direct.detach())
    assert torch.allclose(2.0 * g, grad, rtol=1e-6, atol=1e-9)
    assert torch.all(torch.linalg.eigvalsh(h) > 0)


def test_nights_without_c_m_give_the_prior_centre_and_say_so(nights):
    # constrained nights alone carry τ but no absolute scale (identifiability §3): C_m is
    # the prior's, and the fit says so instead of presenting it as measured
    cons = [n for n in nights if n.kind == "constrained"]
    prior = PopulationPrior(n_households=4000)
    centre = float(torch.exp(prior.moments(_box(RANGES))[0][0, 0]))
    with_prior = NightFit(**IDEAL, n_starts=2, per_night=False, prior=prior).fit(cons, RANGES)
    without = NightFit(**IDEAL, n_starts=2, per_night=False, prior=None).fit(cons, RANGES)
    c_m = with_prior.lumped_["c_m"].value
    assert abs(np.log(c_m / centre)) < 0.02
    assert abs(np.log(without.lumped_["c_m"].value / centre)) > 0.1   # 0.32 here
    said = with_prior.prior_["parameters"]["c_m"]
    assert said["prior_dominated"]
    assert said["posterior_to_prior_sd"] > 0.9
    assert not with_prior.lumped_["c_m"].determined
    # τ still comes from the nights
    assert abs(with_prior.lumped_["tau"].value / HOUSE.tau_h - 1.0) < 0.05
    out = json.loads(json.dumps(fit_to_dict(with_prior)))
    assert out["prior"]["parameters"]["c_m"]["centre"] == pytest.approx(centre, rel=1e-6)
    assert out["prior"]["parameters"]["c_m"]["prior_dominated"] is True
    assert any("c_m is prior-dominated" in n for n in out["notes"])
    assert json.loads(json.dumps(fit_to_dict(without)))["prior"] is None


def test_nights_that_carry_c_m_are_not_prior_dominated(nights):
    fit = NightFit(**IDEAL, n_starts=2, per_night=False).fit(nights, RANGES)   # the default
    said = fit.prior_["parameters"]["c_m"]
    assert not said["prior_dominated"]
    assert said["posterior_to_prior_sd"] < 0.5
    assert abs(fit.lumped_["c_m"].value / HOUSE.c_m_j_per_k - 1.0) < 0.10
    assert fit.lumped_["c_m"].determined


def test_an_unknown_prior_is_refused(nights):
    with pytest.raises(ValueError, match="prior"):
        NightFit(prior="flat").fit(nights, RANGES)
    with pytest.raises(ValueError, match="quantities"):
        PopulationPrior(quantities=("u_walls",))


def test_the_table_says_where_c_m_comes_from(nights):
    from impctl.fit.result.table import format_table

    cons = [n for n in nights if n.kind == "constrained"]
    fit = NightFit(**IDEAL, n_starts=2, per_night=False).fit(cons, RANGES)
    text = format_table(fit_to_dict(fit))
    assert "prior on c_m: population inside the class ranges" in text
    assert "prior-dominated, not measured" in text
