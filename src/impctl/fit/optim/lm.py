"""Batched least squares over many independent fit problems at once (torch, float64).

A *problem* is one parameter set u (7 unconstrained values, :mod:`..ode.parameters`) shared by
its rows; each row (one night) also has its own initial mass temperature θ_m,0. Every start of
the joint fit, every start of every per-night fit and every bootstrap replicate is a problem, and
all of them are integrated together in one ``odeint`` call per iteration.

Two optimisers on the same residuals:

* :func:`levenberg_marquardt` (the default): the Jacobian is analytic — the night ODE is linear,
  so each column is a sum of a few responses of the one integration (:mod:`.jacobian`; forward
  differences whose copies ride in the same batched call where that form does not apply). The
  per-row θ_m,0 are eliminated by a Schur complement (a block-arrow system),
  so problems with any number of nights share one vectorised 7×7 solve.
* :func:`adam`: the paper's way — Adam on the loss with gradients by direct backpropagation
  through the solver (no adjoint). Kept for comparison; it needs hundreds of iterations where
  Levenberg–Marquardt needs tens (see ``bench/fit.py``).

The loss of a problem is Σ_rows weight·Σ_k ((model − measured)/σ_row)² + ridge·‖u‖². The small
ridge is a weak prior at the centre of each search range: it decides only the directions the data
leaves exactly flat (u_walls ↔ walls_area), where any value fits equally well. The problems,
their rows and their residuals: :mod:`.problem`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import torch

from ..ode.parameters import DTYPE, PARAM_NAMES
from ..prior import penalty as prior_penalty
from .jacobian import assemble, evaluate, loss_rows
from .priors import MergedPrior
from .problem import Context, Rows, residuals, sum_rows

N_PARAMS = 7
_MAX_STEP_U = 2.0
_U_LIMIT = 8.0


@dataclass
class _Normal:
    """Normal-equation pieces at one point: per problem (θ block) and per row (θ_m,0)."""

    loss: torch.Tensor   # (P,)
    h: torch.Tensor      # (P, 7, 7)  Σ Jθᵀ Jθ + ridge·I
    g: torch.Tensor      # (P, 7)     Σ Jθᵀ r + ridge·u
    c: torch.Tensor      # (R, 7)     Jθᵀ Jm
    d: torch.Tensor      # (R,)       Jmᵀ Jm
    gm: torch.Tensor     # (R,)       Jmᵀ r
    g_rows: torch.Tensor | None = None  # (R, 7) Jθᵀ r per row (for the sandwich covariance)
    r: torch.Tensor | None = None       # (R, K) scaled residuals
    jtj: torch.Tensor | None = None     # (R, 7, 7) Jθᵀ Jθ per row
    #: (P, 7, 7) the share of ``h`` that is not the rows' (the ridge and the priors,
    #: :func:`penalty`): the data's own curvature is ``h`` without it. Set where the normal
    #: equations are built at one point (:func:`_normal_equations`, :meth:`RowTerms.normal`);
    #: None in the optimiser's trial states, whose problems come from different points
    penalty_h: torch.Tensor | None = None


@dataclass
class RowTerms:
    """Per row, the residuals and Jacobian products at the optimum, as the optimiser last
    evaluated them (at row scale ``scale``): the intervals and the σ update reuse them instead
    of integrating the rows again. Residuals and Jacobian are linear in the row scale, so a
    new σ only rescales them (:meth:`normal`)."""

    r: torch.Tensor       # (R, K) scaled residuals
    jtj: torch.Tensor     # (R, 7, 7)
    g: torch.Tensor       # (R, 7)  Jθᵀ r
    c: torch.Tensor       # (R, 7)  Jθᵀ Jm
    d: torch.Tensor       # (R,)    Jmᵀ Jm
    gm: torch.Tensor      # (R,)    Jmᵀ r
    scale: torch.Tensor   # (R,)    the row scale they were computed with

    def take(self, sel) -> RowTerms:
        return RowTerms(*(x[sel] for x in (self.r, self.jtj, self.g, self.c, self.d, self.gm,
                                           self.scale)))

    def trimmed(self, k: int) -> RowTerms:
        """The first ``k`` nodes (a household's own grid out of a merged, padded batch; the
        padding's residuals are zero)."""
        return RowTerms(self.r[:, :k].clone(), self.jtj.clone(), self.g.clone(), self.c.clone(),
                        self.d.clone(), self.gm.clone(), self.scale.clone())

    def put(self, sel, other: RowTerms) -> None:
        """Rows ``sel`` replaced by ``other`` (a later optimiser call on those rows)."""
        for name in ("r", "jtj", "g", "c", "d", "gm", "scale"):
            getattr(self, name)[sel] = getattr(other, name)

    def raw(self) -> torch.Tensor:
        """(model − measured) in data units, (R, K): what :func:`~.problem.raw_residuals` gives."""
        return self.r / self.scale[:, None]

    def normal(self, rows: Rows, u: torch.Tensor, ctx: Context) -> _Normal:
        """:func:`_normal_equations` of ``rows`` (these rows, at ``rows.scale``) at ``u``."""
        f = (rows.scale / self.scale) ** 2
        jtj, g_rows = self.jtj * f[:, None, None], self.g * f[:, None]
        p_loss, p_h, p_g = penalty(ctx, u, rows.box)
        loss = sum_rows((self.r ** 2).sum(1) * f, rows) + p_loss
        h = sum_rows(jtj, rows) + p_h
        return _Normal(loss, h, sum_rows(g_rows, rows) + p_g, self.c * f[:, None],
                       self.d * f, self.gm * f, g_rows, penalty_h=p_h)


def penalty(ctx: Context, u: torch.Tensor, box: torch.Tensor):
    """The loss terms that are not rows, per problem: the ridge (a weak prior at the centre
    of each range) and the population prior's residuals when ``ctx.prior`` is set
    (:mod:`..prior`): (loss (P,), Hessian share (P, n, n), gradient share (P, n))."""
    n = u.shape[1]
    loss, h, g = (ctx.ridge * (u ** 2).sum(1),
                  ctx.ridge * torch.eye(n, dtype=DTYPE).expand(len(u), n, n), ctx.ridge * u)
    extra = (ctx.prior.penalty(u, box, ctx.ach_vent, ctx.ach_infl)
             if isinstance(ctx.prior, MergedPrior)
             else prior_penalty(ctx.prior, u, box, ctx.ach_vent, ctx.ach_infl))
    if extra is not None:
        loss, h, g = loss + extra[0], h + extra[1], g + extra[2]
    if ctx.gain_prior is not None and n > len(PARAM_NAMES):
        loss, h, g = _gain_prior(ctx.gain_prior, u, box, loss, h, g)
    return loss, h, g


def _gain_prior(prior: tuple[float, float], u: torch.Tensor, box: torch.Tensor, loss, h, g):
    """The Gaussian prior on the night gain column (where it is free) added to the penalty:
    r = (g − mean)/SD with g = lo + (hi − lo)·σ(u); its Gauss–Newton share."""
    j = len(PARAM_NAMES)
    lo, hi = box[:, j, 0], box[:, j, 1]
    free = (hi > lo).to(u.dtype)
    s = torch.sigmoid(u[:, j])
    r = free * (lo + (hi - lo) * s - prior[0]) / prior[1]
    dr = free * (hi - lo) * s * (1.0 - s) / prior[1]
    h = h.clone()
    g = g.clone()
    h[:, j, j] = h[:, j, j] + dr * dr
    g[:, j] = g[:, j] + dr * r
    return loss + r * r, h, g


def _normal_equations(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor) -> _Normal:
    sq, jtj, g_rows, c, d, gm, r0 = assemble(ctx, evaluate(ctx, rows, u, t_m0), u)
    p_loss, p_h, p_g = penalty(ctx, u, rows.box)
    loss = sum_rows(sq, rows) + p_loss
    h = sum_rows(jtj, rows) + p_h
    g = sum_rows(g_rows, rows) + p_g
    return _Normal(loss, h, g, c, d, gm, g_rows, r0, jtj, p_h)


def _take(rows: Rows, keep: torch.Tensor) -> tuple[Rows, torch.Tensor, torch.Tensor]:
    """The problems ``keep`` (bool, P) renumbered 0…: (rows, their problem ids, row ids)."""
    pk = keep.nonzero()[:, 0]
    rk = keep[rows.problem].nonzero()[:, 0]
    remap = torch.full((rows.n_problems,), -1, dtype=torch.long)
    remap[pk] = torch.arange(len(pk))
    return (Rows(remap[rows.problem[rk]], rows.night[rk], rows.row_type[rk], rows.phi_w[rk],
                 rows.phi_in_w[rk], rows.scale[rk], rows.box[pk], len(pk)), pk, rk)


def _trial(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor,
           active: torch.Tensor, current: _Normal) -> tuple[_Normal, torch.Tensor]:
    """The trial point (u, t_m0) of the ``active`` problems: its loss, and for the problems
    whose loss it lowers (``ok`` (P,), the steps taken) its normal equations; every other
    problem keeps ``current``. The Jacobian of a rejected step (a third of a fleet batch's)
    is never built, and converged problems cost nothing any more: in a merged fleet batch most
    problems are done long before the slowest one."""
    out = _Normal(*(x.clone() for x in (current.loss, current.h, current.g, current.c,
                                         current.d, current.gm, current.g_rows, current.r,
                                         current.jtj)))
    ok = torch.zeros_like(active)
    if not bool(active.any()):
        return out, ok
    sub, pk, rk = _take(rows, active)
    if hasattr(ctx.prior, "take"):   # a merged batch's per-problem priors follow the renumbering
        ctx = replace(ctx, prior=ctx.prior.take(pk))
    parts = evaluate(ctx, sub, u[pk], t_m0[rk])
    p_loss, p_h, p_g = penalty(ctx, u[pk], sub.box)
    loss = sum_rows(loss_rows(parts), sub) + p_loss
    out.loss[pk] = loss
    taken = torch.isfinite(loss) & (loss < current.loss[pk])
    ok[pk] = taken
    if not bool(taken.any()):
        return out, ok
    sel = taken[sub.problem]
    _, jtj, g_rows, c, d, gm, r0 = assemble(ctx, parts, u[pk], sel)
    problem = sub.problem[sel]
    pt, rt = pk[taken], rk[sel]
    out.h[pt] = (torch.zeros_like(p_h).index_add_(0, problem, jtj) + p_h)[taken]
    out.g[pt] = (torch.zeros_like(p_g).index_add_(0, problem, g_rows) + p_g)[taken]
    out.c[rt], out.d[rt], out.gm[rt] = c, d, gm
    out.g_rows[rt], out.r[rt], out.jtj[rt] = g_rows, r0, jtj
    return out, ok


def schur(ne: _Normal, rows: Rows, lam: torch.Tensor | None = None):
    """The θ system with θ_m,0 eliminated: (S, b, d̃); undamped when ``lam`` is None."""
    h, d = ne.h, ne.d
    if lam is not None:
        diag = torch.diagonal(h, dim1=1, dim2=2)
        floor = 1e-9 * diag.amax(1, keepdim=True).clamp_min(1e-12)
        h = h + torch.diag_embed(lam[:, None] * diag.clamp_min(floor))
        d = d * (1.0 + lam[rows.problem])
    d = d + 1e-12
    s = h - sum_rows(ne.c[:, :, None] * ne.c[:, None, :] / d[:, None, None], rows)
    b = ne.g - sum_rows(ne.c * (ne.gm / d)[:, None], rows)
    return s, b, d


def _predicted_decrease(ne: _Normal, rows: Rows, step: torch.Tensor, step_m: torch.Tensor):
    """Decrease of the Gauss–Newton model of the loss for a step (per problem)."""
    lin = (ne.g * step).sum(1) + sum_rows(ne.gm * step_m, rows)
    quad = torch.einsum("pi,pij,pj->p", step, ne.h, step) + sum_rows(
        2.0 * step_m * (ne.c * step[rows.problem]).sum(1) + ne.d * step_m ** 2, rows)
    return -(2.0 * lin + quad)


def _best_done(loss: torch.Tensor, done: torch.Tensor, groups: torch.Tensor) -> torch.Tensor:
    """(G,) bool: the group has a done problem among its lowest-loss ones, or no problem (a
    label left unused, e.g. the prior-box group of a fit without class ranges: it must not keep
    the others iterating to ``max_iter``)."""
    n_groups = int(groups.max()) + 1
    best = torch.full((n_groups,), float("inf"), dtype=loss.dtype).scatter_reduce(
        0, groups, loss, reduce="amin")
    is_best = loss == best[groups]
    empty = torch.bincount(groups, minlength=n_groups) == 0
    return empty.index_put_((groups[is_best & done],), torch.tensor(True))


def _units_done(group_done: torch.Tensor, units: torch.Tensor) -> torch.Tensor:
    """(U,) bool: every group of the unit is done (``units`` (G,) labels each group)."""
    n_units = int(units.max()) + 1
    return torch.ones(n_units, dtype=torch.bool).index_put_((units[~group_done],),
                                                            torch.tensor(False))


@dataclass
class LMResult:
    u: torch.Tensor            # (P, 7)
    t_m0: torch.Tensor         # (R,)
    loss: torch.Tensor         # (P,)
    cov_u: torch.Tensor        # (P, 7, 7) inverse of the undamped Schur complement
    fisher_u: torch.Tensor     # (P, 7, 7) the Schur complement without the ridge
    n_iter: int
    converged: torch.Tensor    # (P,) bool
    history: list[float] = field(default_factory=list)
    iterations: torch.Tensor | None = None  # (P,) iterations each problem took part in
    terms: RowTerms | None = None  # per row at the optimum (reused by σ update and intervals)


def levenberg_marquardt(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor, *,
                        groups: torch.Tensor | None = None, units: torch.Tensor | None = None,
                        max_iter: int = 60, atol: float = 1e-2) -> LMResult:
    """Minimise every problem's loss at once (see the module docstring).

    A problem is done when an accepted step lowers its loss by less than ``atol``, or when a
    nearly undamped step is predicted to lower it by less than that, or when its damping has
    grown past 1e8. The loss is a χ² in units of the residual σ: a 95 % interval spans a change
    of 3.84, so the default 0.01 is far below anything statistically visible.

    ``groups`` (P,) labels problems that are starts of the same fit: the iterations stop once, in
    every group, the start with the lowest loss is done (the others could only tie or lose
    unless they overtake it later, which is rare: then "keep the best" keeps this one).

    ``units`` (G,) labels groups that belong to one independent fit (a household of a merged
    fleet batch): a unit whose groups are all done stops there, exactly where it would stop
    alone, while the others go on. Done and stopped problems are not evaluated any more.
    """
    # the prior's moments depend only on the boxes: looked up once here, not per iteration
    ctx = replace(ctx, prior=MergedPrior.of(ctx.prior, rows.box))
    with torch.no_grad():
        u, t_m0 = u.clone(), t_m0.clone()
        ne = _normal_equations(ctx, rows, u, t_m0)
        # The residuals are affine in θ_m,0: one exact solve puts them where u wants them.
        t_m0 = t_m0 - ne.gm / (ne.d + 1e-12)
        ne = _normal_equations(ctx, rows, u, t_m0)
        n_prob = rows.n_problems
        lam = torch.full((n_prob,), 1e-3, dtype=DTYPE)
        nu = torch.full((n_prob,), 2.0, dtype=DTYPE)
        done = torch.zeros(n_prob, dtype=torch.bool)
        stopped = torch.zeros(n_prob, dtype=torch.bool)
        iterations = torch.zeros(n_prob, dtype=torch.long)
        history = [float(ne.loss.sum())]
        n_iter = 0
        for n_iter in range(1, max_iter + 1):  # noqa: B007 (the count is returned)
            s, b, d = schur(ne, rows, lam)
            step = -torch.linalg.solve(s, b)
            big = step.abs().amax(1, keepdim=True)
            step = step * torch.where(big > _MAX_STEP_U, _MAX_STEP_U / big, 1.0)
            # Past |u| = 8 the sigmoid is flat to 3e-4 of the range: stop there.
            step = (u + step).clamp(-_U_LIMIT, _U_LIMIT) - u
            step_m = -(ne.gm + (ne.c * step[rows.problem]).sum(1)) / d
            pred = _predicted_decrease(ne, rows, step, step_m)
            trial, ok = _trial(ctx, rows, u + step, t_m0 + step_m, ~done & ~stopped, ne)
            actual = ne.loss - trial.loss
            # Converged: an accepted step gained < atol, or a nearly undamped Gauss–Newton step
            # predicts < atol (then a "rejection" is only rounding), or nothing helps any more.
            done = done | (~stopped & ((ok & (actual < atol)) | ((pred < atol) & (lam < 1.0))
                                       | (lam > 1e8)))
            u = torch.where(ok[:, None], u + step, u)
            t_m0 = torch.where(ok[rows.problem], t_m0 + step_m, t_m0)
            # the trial holds the new terms where the step is taken and the old ones elsewhere
            ne = replace(trial, loss=torch.where(ok, trial.loss, ne.loss))
            # Nielsen's damping update from the gain ratio actual/predicted decrease.
            rho = (actual / pred.clamp_min(1e-300)).clamp(0.0, 1.0)
            shrink = torch.clamp(1.0 - (2.0 * rho - 1.0) ** 3, min=1.0 / 3.0)
            lam = torch.where(ok, (lam * shrink).clamp_min(1e-9), torch.where(stopped, lam,
                                                                              lam * nu))
            nu = torch.where(ok, torch.full_like(nu, 2.0), torch.where(stopped, nu, nu * 2.0))
            iterations = torch.where(stopped, iterations, n_iter)
            history.append(float(ne.loss.sum()))
            if bool(done.all()):
                break
            if groups is not None:
                group_done = _best_done(ne.loss, done, groups)
                if bool(group_done.all()):
                    break
                if units is not None:
                    stopped = _units_done(group_done, units)[units[groups]]
        s, _, _ = schur(ne, rows)
        cov = torch.linalg.pinv(s, hermitian=True)
        fisher = s - penalty(ctx, u, rows.box)[1]
    terms = RowTerms(ne.r, ne.jtj, ne.g_rows, ne.c, ne.d, ne.gm, rows.scale.clone())
    return LMResult(u, t_m0, ne.loss, cov, fisher, n_iter, done, history, iterations, terms)


def adam(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor, *, n_iter: int = 300,
         lr: float = 0.05) -> LMResult:
    """The paper's NODE training: Adam, gradients by backprop through ``odeint`` (no adjoint).

    Adam updates each coordinate on its own, so summing the losses of independent problems
    trains each of them exactly as if alone. Returns the same result type as
    :func:`levenberg_marquardt` (curvature from a final Levenberg–Marquardt-free evaluation).
    """
    u = u.clone().requires_grad_(True)
    m = t_m0.clone().requires_grad_(True)
    opt = torch.optim.Adam([u, m], lr=lr)
    history = []
    for _ in range(n_iter):
        opt.zero_grad()
        r = residuals(ctx, rows, u, m)
        loss = (r ** 2).sum() + ctx.ridge * (u ** 2).sum() + _prior_loss(ctx, rows, u)
        loss.backward()
        opt.step()
        history.append(float(loss.detach()))
    with torch.no_grad():
        ne = _normal_equations(ctx, rows, u.detach(), m.detach())
        s, _, _ = schur(ne, rows)
    return LMResult(u.detach(), m.detach(), ne.loss, torch.linalg.pinv(s, hermitian=True),
                    s - penalty(ctx, u.detach(), rows.box)[1], n_iter,
                    torch.zeros(rows.n_problems, dtype=torch.bool), history)


def loss_gradient(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor):
    """(loss, ∂loss/∂u, ∂loss/∂θ_m,0) by backprop through the solver — for checks and tests."""
    u = u.clone().requires_grad_(True)
    m = t_m0.clone().requires_grad_(True)
    r = residuals(ctx, rows, u, m)
    loss = (r ** 2).sum() + ctx.ridge * (u ** 2).sum() + _prior_loss(ctx, rows, u)
    gu, gm = torch.autograd.grad(loss, [u, m])
    return loss.detach(), gu, gm


def _prior_loss(ctx: Context, rows: Rows, u: torch.Tensor) -> torch.Tensor | float:
    """The population prior's Σr², differentiable (0 without a prior)."""
    if ctx.prior is None:
        return 0.0
    return (ctx.prior.residuals(u, rows.box, ctx.ach_vent, ctx.ach_infl) ** 2).sum()
