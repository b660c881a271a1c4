"""The population priors of an optimiser call as one penalty (torch, float64).

A fleet batch merges many households into one Levenberg–Marquardt call, and each household
carries its own tempered prior (:class:`~impctl.fit.prior.PriorSlices`). Evaluated household
by household, the prior's share of the normal equations cost one autograd pass and one lookup
of the prior's moments per household per iteration — a quarter of a batch's optimiser time
(``bench/fleet.py --profile``). :class:`MergedPrior` looks the moments up once per call (they
depend only on each problem's box, which a call never changes) and differentiates all problems'
residuals in one pass; :func:`.lm.levenberg_marquardt` makes one of every prior it is given, a
single fit's too. The arithmetic per problem is :func:`impctl.fit.prior.penalty`'s: a single
fit's numbers are bit for bit the same; on a merged batch's larger tensors torch may round a
last bit differently, which a household on a flat loss surface can carry a little further
(``bench/fleet.py --sample --against``: 7 of 320 households moved, C_m by at most 0.27 % —
as much as main's own batches moved from run to run, decision record 0018).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..ode.parameters import lumped, to_physical
from ..prior import QUANTITIES, PopulationPrior, PriorSlices, gauss_newton


@dataclass(frozen=True)
class MergedPrior:
    """Per problem of a merged call: the prior's centre ``mu`` and SD ``sd`` of ln q (P, m),
    and whether its household has a prior at all (``live``, (P,) bool)."""

    mu: torch.Tensor
    sd: torch.Tensor
    live: torch.Tensor
    columns: tuple[int, ...]   # the quantities' columns of :func:`~..ode.parameters.lumped`

    @staticmethod
    def of(prior: PopulationPrior | PriorSlices | None, box: torch.Tensor):
        """The merged form of ``prior`` (one household's prior, or the slices of a merged
        call) for problems with boxes ``box`` (P, n, 2); ``prior`` itself when it is None or
        when its households' priors hold different quantities (then no one residual vector
        fits them all)."""
        if isinstance(prior, PopulationPrior):
            mu, sd = prior.moments(box)
            return MergedPrior(mu, sd, torch.ones(len(box), dtype=torch.bool),
                               tuple(QUANTITIES.index(q) for q in prior.quantities))
        if not isinstance(prior, PriorSlices):
            return prior
        quantities = {p.quantities for p in prior.priors if p is not None}
        if len(quantities) != 1:
            return prior
        (names,) = quantities
        n_prob = len(prior.owner)
        mu = torch.zeros(n_prob, len(names), dtype=box.dtype)
        sd = torch.ones(n_prob, len(names), dtype=box.dtype)
        live = torch.zeros(n_prob, dtype=torch.bool)
        for p, sel in prior._parts():
            mu[sel], sd[sel] = p.moments(box[sel])
            live[sel] = True
        return MergedPrior(mu, sd, live, tuple(QUANTITIES.index(q) for q in names))

    def take(self, problems: torch.Tensor) -> MergedPrior:
        """The problems ``problems`` (ids) renumbered 0…, as the optimiser takes the running
        ones (:func:`.lm._evaluate`)."""
        return MergedPrior(self.mu[problems], self.sd[problems], self.live[problems],
                           self.columns)

    def penalty(self, u: torch.Tensor, box: torch.Tensor, ach_vent: float, ach_infl: float
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(loss Σr² (P,), Jᵀ J (P, n, n), Jᵀ r (P, n)) at ``u`` (P, n); zero for problems
        without a prior."""
        n = u.shape[1]
        loss = torch.zeros(len(u), dtype=u.dtype)
        h = torch.zeros(len(u), n, n, dtype=u.dtype)
        g = torch.zeros(len(u), n, dtype=u.dtype)
        sel = self.live.nonzero()[:, 0]
        if not len(sel):
            return loss, h, g
        mu, sd, cols, live_box = self.mu[sel], self.sd[sel], list(self.columns), box[sel]

        def residuals(uu):
            q = lumped(to_physical(uu, live_box), ach_vent, ach_infl)
            return (torch.log(q[:, cols]) - mu) / sd

        loss[sel], h[sel], g[sel] = gauss_newton(residuals, u[sel])
        return loss, h, g
