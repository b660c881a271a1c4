"""A population prior for the night fit: empirical Bayes inside the class ranges (MAP).

The nights carry little about C_m once the constrained nights end at T_min (the accuracy page of
the documentation): inside its bounds the fit is pushed around by model error, and the class range's
midpoint beats it. What is known before the data is the virtual population the classifiers
are trained on: :class:`PopulationPrior` draws it (``impctl train``'s default seed 0, never the
bench's held-out seed) and, for any search box, takes the distribution of ln C_m (and, if
asked, ln τ, ln HLC) over the population's households whose classified parameters (floor_area,
c_f, u_walls) lie in that box — each household weighted by the classifiers' probability of its
classes when those are given (a mixture over classes; inside a box of one class per
parameter the weights are equal and it is that class's distribution). A Gaussian with that
mean and SD in log space becomes one penalty residual per quantity, (ln q − μ)/σ, added to the
least-squares objective (:func:`penalty`, called by :mod:`.optim.lm` next to its ridge): the
fit is a maximum a posteriori estimate and its Laplace intervals are posterior intervals.

What comes from the prior is said (identifiability.md): :func:`statement` reports per
quantity the prior's centre and SD, the posterior SD (Laplace curvature, the prior
included) and their ratio; a ratio above 1/√2 means the prior holds more than half of the
posterior precision — the value is *prior-dominated*, not measured.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch

from .ode.parameters import CLASSIFIED, DTYPE, PARAM_NAMES, lumped, to_physical

#: Seed and size of the population the prior is drawn from: ``impctl train``'s default seed
#: (the classifiers' training population); the bench's held-out households use seed 20260.
PRIOR_SEED = 0
PRIOR_HOUSEHOLDS = 20000
#: Lumped quantities a prior can hold, in :func:`~.ode.parameters.lumped` order.
QUANTITIES = ("hlc", "c_m", "tau")
#: Posterior/prior SD ratio above which a value is called prior-dominated: the prior then
#: holds more than half of the posterior precision (1 − ratio² < ½).
PRIOR_DOMINATED_RATIO = 2 ** -0.5

_CLASSIFIED_COLUMNS = [PARAM_NAMES.index(n) for n in CLASSIFIED]


@lru_cache(maxsize=2)
def _population(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(classified parameters (N, 3), ln of HLC [W/K], C_m [J/K], τ [h] (N, 3))."""
    from ..population.households import sample_population

    table = sample_population(n, seed)
    x = table[list(CLASSIFIED)].to_numpy(dtype=float)
    q = np.log(table[["hlc_w_per_k", "c_m_j_per_k", "tau_h"]].to_numpy(dtype=float))
    return x, q


@dataclass(frozen=True)
class PopulationPrior:
    """Gaussian prior in log space on lumped quantities, from the virtual population.

    Parameters
    ----------
    quantities : tuple of {"c_m", "tau", "hlc"}
        Which lumped quantities get a prior (default C_m only: the one the nights pin down
        least, identifiability.md §3).
    seed, n_households : int
        The population drawn (:func:`impctl.population.households.sample_population`).
    probabilities : tuple of (name, ((lo, hi, p), …)), optional
        The classifiers' class probabilities per classified parameter (a mixture over
        classes); None weights every household alike.
    weight : float
        Multiplies the prior's precision (1: the population's own spread).
    """

    quantities: tuple[str, ...] = ("c_m",)
    seed: int = PRIOR_SEED
    n_households: int = PRIOR_HOUSEHOLDS
    probabilities: tuple | None = None
    weight: float = 1.0

    def __post_init__(self) -> None:
        bad = [q for q in self.quantities if q not in QUANTITIES]
        if bad or not self.quantities:
            raise ValueError(f"prior quantities must be among {QUANTITIES}, got {bad or '()'}")

    @staticmethod
    def of_classes(classes: dict, **kw) -> PopulationPrior:
        """A prior mixing the classes by their probabilities ``{name: [((lo, hi), p), …]}``."""
        probs = tuple(sorted((name, tuple((float(lo), float(hi), float(p))
                                          for (lo, hi), p in rows))
                             for name, rows in classes.items()))
        return PopulationPrior(probabilities=probs, **kw)

    @staticmethod
    def of_labels(probabilities: dict[str, dict[str, float]], **kw) -> PopulationPrior:
        """:meth:`of_classes` from the classifiers' ``{name: {"lo-hi": p}}``
        (:attr:`impctl.classifiers.files.saved.ClassResult.probabilities`)."""
        return PopulationPrior.of_classes(
            {name: [(tuple(float(v) for v in label.split("-")), p) for label, p in rows.items()]
             for name, rows in probabilities.items()}, **kw)

    def _household_weights(self) -> np.ndarray:
        x, _ = _population(self.n_households, self.seed)
        w = np.ones(len(x))
        for name, rows in self.probabilities or ():
            col = x[:, list(CLASSIFIED).index(name)]
            pw = np.zeros(len(x))
            for lo, hi, p in rows:
                pw[(col >= lo) & (col < hi)] = p
            w = w * pw
        return w

    def moments(self, box: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(μ, σ) of ln q for each problem's box (P, n, 2) → two (P, m) tensors, q in
        :attr:`quantities` order; the whole population where a box holds no household."""
        keys = box[:, _CLASSIFIED_COLUMNS, :].reshape(len(box), -1)
        uniq, inverse = torch.unique(keys, dim=0, return_inverse=True)
        both = [_box_moments(self, tuple(k.tolist())) for k in uniq]
        mu = torch.as_tensor(np.array([m for m, _ in both]), dtype=DTYPE)[inverse]
        sd = torch.as_tensor(np.array([s for _, s in both]), dtype=DTYPE)[inverse]
        return mu, sd / float(np.sqrt(self.weight))

    def tempered(self, factor: float) -> PopulationPrior:
        """This prior with its precision × ``factor``. The objective counts every residual
        as independent, while the Laplace intervals divide the data's information by the
        residual autocorrelation's inflation (:func:`~.intervals.uncertainty.inflation`):
        with the prior weighted up by the same factor, the fit's optimum is the mode of the
        posterior its intervals describe (a tempered likelihood)."""
        return dataclasses.replace(self, weight=self.weight * float(factor))

    def residuals(self, u: torch.Tensor, box: torch.Tensor, ach_vent: float,
                  ach_infl: float) -> torch.Tensor:
        """(ln q(u) − μ)/σ per problem (P, m), differentiable in ``u`` (P, n)."""
        mu, sd = self.moments(box)
        q = lumped(to_physical(u, box), ach_vent, ach_infl)
        cols = [QUANTITIES.index(n) for n in self.quantities]
        return (torch.log(q[:, cols]) - mu) / sd

    def describe(self) -> dict:
        return {"kind": "population", "quantities": list(self.quantities), "seed": self.seed,
                "n_households": self.n_households, "weight": self.weight,
                "class_probabilities": (None if self.probabilities is None else
                                        {n: [[lo, hi, p] for lo, hi, p in rows]
                                         for n, rows in self.probabilities})}


@lru_cache(maxsize=64)
def _box_moments(prior: PopulationPrior, key: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean and SD of ln q over the population inside one box (``key``: lo, hi of
    each classified parameter); the optimiser asks for the same few boxes every iteration."""
    x, q = _population(prior.n_households, prior.seed)
    cols = [QUANTITIES.index(n) for n in prior.quantities]
    k = np.asarray(key).reshape(len(CLASSIFIED), 2)
    w_all = prior._household_weights()
    w = w_all * np.all((x >= k[:, 0]) & (x <= k[:, 1]), axis=1)
    if w.sum() <= 0:
        w = w_all if w_all.sum() > 0 else np.ones(len(x))
    w = w / w.sum()
    m = w @ q[:, cols]
    return m, np.sqrt(np.maximum(w @ (q[:, cols] - m) ** 2, 1e-8))


def with_class_probabilities(prior, probabilities: dict | None):
    """The estimator's ``prior`` setting for a household the classifiers gave class
    probabilities ``{name: {"lo-hi": p}}``: "population" becomes the mixture
    :meth:`PopulationPrior.of_labels`; anything else (None, a given prior) is kept. One rule
    for ``impctl fit`` and the fleet, so a household gets the same prior from both."""
    if prior == "population" and probabilities:
        return PopulationPrior.of_labels(probabilities)
    return prior


@dataclass(frozen=True)
class PriorSlices:
    """The priors of several households' problems merged into one optimiser call (the fleet's
    batches, :mod:`.optim.batch`): ``priors`` holds each household's prior (or None) and
    ``owner`` (P,) the household of each problem of the merged call. Each household's prior is
    tempered by its own residual autocorrelation, so equal priors are the exception: without
    this, every refit of a batch would be solved household by household. Only the
    Levenberg–Marquardt path takes it (:func:`penalty`); a batch's Adam fits run alone."""

    priors: tuple[PopulationPrior | None, ...]
    owner: torch.Tensor

    def take(self, problems: torch.Tensor) -> PriorSlices:
        """The priors of the problems ``problems`` (ids), renumbered 0… as the optimiser does
        when it evaluates only the problems still running."""
        return PriorSlices(self.priors, self.owner[problems])

    def _parts(self):
        for j, p in enumerate(self.priors):
            sel = (self.owner == j).nonzero()[:, 0]
            if p is not None and len(sel):
                yield p, sel


def penalty(prior: PopulationPrior | PriorSlices | None, u: torch.Tensor, box: torch.Tensor,
            ach_vent: float, ach_infl: float
            ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None:
    """The prior's share of the Gauss–Newton normal equations at ``u`` (P, n):
    (loss Σr² (P,), Jᵀ J (P, n, n), Jᵀ r (P, n)); None without a prior."""
    if prior is None:
        return None
    if isinstance(prior, PriorSlices):
        n = u.shape[1]
        loss, h, g = (torch.zeros(len(u), dtype=u.dtype), torch.zeros(len(u), n, n, dtype=u.dtype),
                      torch.zeros(len(u), n, dtype=u.dtype))
        for p, sel in prior._parts():
            loss[sel], h[sel], g[sel] = penalty(p, u[sel], box[sel], ach_vent, ach_infl)
        return loss, h, g
    return gauss_newton(lambda uu: prior.residuals(uu, box, ach_vent, ach_infl), u)


def gauss_newton(residuals, u: torch.Tensor
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(Σr² (P,), JᵀJ (P, n, n), Jᵀr (P, n)) of penalty residuals ``residuals(u)`` (P, m) at
    ``u`` (P, n), J by autograd, one pass per residual column (m is 1–3 here)."""
    with torch.enable_grad():
        uu = u.detach().clone().requires_grad_(True)
        r = residuals(uu)
        jac = torch.stack([torch.autograd.grad(r[:, j].sum(), uu, retain_graph=True)[0]
                           for j in range(r.shape[1])], dim=1)              # (P, m, n)
    r = r.detach()
    return ((r ** 2).sum(1), jac.transpose(1, 2) @ jac,
            (jac.transpose(1, 2) @ r[:, :, None])[:, :, 0])


def statement(prior: PopulationPrior, u: torch.Tensor, box: torch.Tensor, cov_u: torch.Tensor,
              ach_vent: float, ach_infl: float) -> dict:
    """Per prior quantity: the prior's centre and SD (log), the posterior value and SD
    (Laplace, prior included) and their ratio, and whether the value is prior-dominated."""
    mu, sd = prior.moments(box[None])
    uu = u.detach().clone().requires_grad_(True)
    q = lumped(to_physical(uu, box), ach_vent, ach_infl)
    out = {**prior.describe(), "parameters": {}}
    units = {"hlc": "W/K", "c_m": "J/K", "tau": "h"}
    for j, name in enumerate(prior.quantities):
        i = QUANTITIES.index(name)
        grad = torch.autograd.grad(torch.log(q[i]), uu, retain_graph=True)[0].detach()
        post = float((grad @ cov_u @ grad).clamp_min(0).sqrt())
        ratio = post / float(sd[0, j])
        out["parameters"][name] = {
            "centre": float(torch.exp(mu[0, j])), "unit": units[name],
            "prior_sd_log": float(sd[0, j]), "posterior": float(q[i].detach()),
            "posterior_sd_log": post, "posterior_to_prior_sd": ratio,
            "prior_dominated": bool(ratio > PRIOR_DOMINATED_RATIO)}
    return out


def prior_statement(prior: PopulationPrior, lumped_: dict, u: torch.Tensor, box: torch.Tensor,
                    cov_u: torch.Tensor, ach_vent: float, ach_infl: float) -> tuple[dict, dict]:
    """:func:`statement`, and ``lumped_`` with every prior-dominated quantity marked not
    determined by the data (its interval is the posterior's, but not a measurement)."""
    said = statement(prior, u, box, cov_u, ach_vent, ach_infl)
    out = dict(lumped_)
    for name, p in said["parameters"].items():
        if p["prior_dominated"] and name in out:
            out[name] = dataclasses.replace(out[name], determined=False)
    return out, said
