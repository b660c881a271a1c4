"""The noise weights of one :class:`~impctl.fit.NightFit`: the σ each residual is divided by.

The first optimisation weighs the rows by a data-only guess of the noise per residual group
(:func:`..nights.data.noise_levels`). Its residuals then give the σ the intervals are scaled
with, and the joint problems are refitted with it: per night (``noise="night"``, iteratively
reweighted least squares, whose fixed point is the maximum-likelihood fit with an unknown
variance per night) or per group when it is far from the guess (``noise="kind"``, eq. 5 rows
carry the power noise). A population prior is tempered for those refits as the intervals
weigh the data, so that the optimum is the mode of the posterior the Laplace intervals describe
(:meth:`~impctl.fit.prior.PopulationPrior.tempered`).

The state is a frozen :class:`Weights`, handed in and returned; the one thing changed in place
is the optimiser's result, whose joint problems are replaced by their refits.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import torch

from ..intervals.uncertainty import inflation
from ..layout import best_of, night_sigma, residual_sigma
from ..nights.data import noise_levels
from ..optim import lm
from .problems import Problems

#: Most refits of the joint problems while the per-night σ settle (``noise="night"``), and
#: the largest relative change of any night's σ at which they count as settled.
NOISE_PASSES = 3
NOISE_RTOL = 0.1

_GROUPS = ("constrained_t_air_k", "normal_t_air_k", "normal_power_w")

#: An optimiser call (rows, u0, θ_m,0, groups) → result: the estimator's own, so that the
#: fleet's batched estimator (:mod:`..optim.batch`) merges the refits too.
Optimise = Callable[[lm.Rows, torch.Tensor, torch.Tensor, torch.Tensor], lm.LMResult]


@dataclass(frozen=True)
class Weights:
    """The σ the joint problems were last fitted with."""

    guess: dict[str, float]             # data-only σ per group (K, K, W): ``noise_``
    sigma: dict[str, float]             # σ per group from the fit's residuals: ``sigma_``
    sigma_n: torch.Tensor | None = None  # per packed night (K or W), when ``noise="night"``
    tempering: float = 1.0              # the prior's precision factor during the refits
    n_iter: int = 0                     # optimiser iterations the refits took

    @classmethod
    def guessed(cls, problems: Problems) -> Weights:
        """Before any fit: the data-only noise levels of the fitted nights."""
        sigma = noise_levels(problems.kept)
        return cls(dict(sigma), sigma)

    def rows(self, problems: Problems, only: list[int] | None = None) -> lm.Rows:
        return problems.rows(self.sigma, self.sigma_n, only)

    def per_night(self, problems: Problems) -> dict[str, float]:
        """Night id → the σ its residuals were weighted with (``sigma_night_``)."""
        sigma_n = (self.sigma_n if self.sigma_n is not None
                   else torch.tensor([self.sigma[k] for k in _GROUPS])[problems.group_n])
        return dict(zip(problems.packed.night_ids, sigma_n.tolist(), strict=True))


def settle(problems: Problems, weights: Weights, rows: lm.Rows, result: lm.LMResult,
           optimise: Optimise, noise: str) -> Weights:
    """The weights after the first optimisation (``result`` of ``rows``, weighted by
    ``weights``), its joint problems refitted with them (in ``result``)."""
    lay, ctx, prior = problems.lay, problems.ctx, problems.prior
    weights = _fitted_sigma(problems, weights, rows, result, best_of(result, lay, 0))
    refit = False
    if prior is not None:
        # (the lower of the class and the prior box: a box the data contradict leaves a
        # misfit whose autocorrelation is not the noise's)
        weights = replace(weights, tempering=min(
            inflation(ctx, weights.rows(problems), result, best_of(result, lay, g),
                      problems.group_n) for g in ((0, 1) if lay["prior"] else (0,))))
        ctx.prior = prior.tempered(weights.tempering)
        refit = True
    try:
        if noise == "night":
            # the per-night weights' refits carry the tempered prior too
            weights = _reweight_nights(problems, weights, result, optimise)
        else:
            ratio = [weights.sigma[k] / weights.guess[k] for k in weights.guess]
            if refit or max(ratio) > 1.4 or min(ratio) < 0.7:
                weights = _refit_joint(problems, weights, result, optimise)
    finally:
        ctx.prior = prior   # the intervals divide the data by the inflation themselves
    return weights


def _fitted_sigma(problems: Problems, weights: Weights, rows: lm.Rows, result: lm.LMResult,
                  best: int) -> Weights:
    return replace(weights, sigma=residual_sigma(problems.ctx, rows, result, best,
                                                 problems.packed.mask, problems.group_n,
                                                 weights.sigma))


def _reweight_nights(problems: Problems, weights: Weights, result: lm.LMResult,
                     optimise: Optimise) -> Weights:
    """Refit the joint problems with each night weighted by its own RMS residual
    (:func:`..layout.night_sigma`) until no night's σ moves by more than :data:`NOISE_RTOL`
    (at most :data:`NOISE_PASSES` refits)."""
    for _ in range(NOISE_PASSES):
        new = night_sigma(problems.ctx, weights.rows(problems), result,
                          best_of(result, problems.lay, 0), problems.group_n)
        old = weights.sigma_n
        if old is not None and float((new / old - 1.0).abs().max()) < NOISE_RTOL:
            break
        weights = _refit_joint(problems, replace(weights, sigma_n=new), result, optimise)
    return weights


def _refit_joint(problems: Problems, weights: Weights, result: lm.LMResult,
                 optimise: Optimise) -> Weights:
    """Refit the joint problems (class, simple, prior) from where they are, with ``weights``;
    their new optimum replaces theirs in ``result``."""
    lay = problems.lay
    joint = lay["class"] + lay["simple"] + lay["prior"]
    rows = weights.rows(problems, joint)
    sel = torch.isin(lay["row_problem"], torch.tensor(joint))
    second = optimise(rows, result.u[joint], result.t_m0[sel], lay["group"][joint])
    result.u[joint], result.t_m0[sel], result.loss[joint] = second.u, second.t_m0, second.loss
    if result.terms is not None and second.terms is not None:
        result.terms.put(sel, second.terms)
    else:
        result.terms = None
    weights = replace(weights, n_iter=weights.n_iter + second.n_iter)
    return _fitted_sigma(problems, weights, rows, second,
                         int(torch.argmin(second.loss[:len(lay["class"])])))
