"""The season model's search: variable projection over θ, least squares for β.

For each θ (:data:`~.columns.THETA`) the linear parameters β come from a ridge least-squares
solve (the daily sun amplitudes are shrunk towards their mean: a cloudy week leaves few blocks to
tell them apart); the search over θ — five numbers in transformed coordinates — is a bounded
trust-region least squares on the projected residual, started from a small grid, with the
projection's own Jacobian (:mod:`.jacobian`). No torch.

The search solves from the normal equations' parts (:mod:`.normal`) and never forms X;
:func:`project` forms it — the straightforward computation the tests hold the search to.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_factor, cho_solve
from scipy.optimize import OptimizeResult, leastsq

from .columns import BETA, Design, column_names, columns, gain_family
from .gram import gain_sum_sq
from .jacobian import projected_jacobian
from .normal import normal_equations

Array = NDArray[np.float64]

#: Bounds of θ in physical units: τ_mm [s], w [-], τ_e [s], f_sun [-], τ_r [s]. The room's lag
#: stops at 30 min: a sensor in its housing lags 5–15 min, the air and furniture add minutes;
#: up to 60 min it traded against the emitter (τ 5.4 → 6.5 % on the development households).
THETA_BOUNDS = ((1.0 * 3600, 400.0 * 3600), (0.02, 0.995), (60.0, 3.0 * 3600), (0.02, 0.98),
                (10.0, 1800.0))
#: Start grid of (τ_mm [h], w): the search starts from the best few.
START_GRID = tuple((t, w) for t in (3.0, 8.0, 24.0, 80.0) for w in (0.7, 0.9, 0.97))
#: τ_e [s] and f_sun [-] of the start grid's points. The grid's costs rank τ_mm and w at each
#: τ_e, and the search starts from the best point of each: the emitter's lag has two basins —
#: near 2–3 h where most realistic houses end (a screed, the furniture and the air's capacity
#: read as lag), and near zero (radiators, ISO 13790's own model, which has no emitter). From
#: 2 h alone, houses of the second kind stuck with τ_e at hours and τ up to 3× the truth.
#: Under a bound from the water's fade (0.5–8 h) the near-zero start's grid point never ranked
#: first (0 of 100 households): the search then starts from the first τ_e alone.
#: f_sun ≲ 0.1 — from 0.3 the ranking sent some houses into a corner (w at its bound, τ 10×
#: off) whose cost was 3× the best.
START_TAU_E_S, START_F_SUN = (7200.0, 300.0), 0.05
#: τ_r [s] of the start grid's points: a sensor's typical lag.
START_TAU_R_S = 300.0
#: Ridge weight of the daily sun amplitudes about their mean, per block [-].
SUN_RIDGE = 0.05
#: Weight of the slow gain's day-to-day steps, per block [-]: its random-walk prior. Set on
#: simulated seasons the bench does not use (0.2–20 tried; 1–5 best, HLC's P90 32 → 24 %).
GAIN_RW = 5.0
#: Relative step of the search's forward differences in the transformed θ [-].
SEARCH_FD_STEP = 1e-4
#: Residual scale [W] (the search is scale-free; this keeps the numbers near 1).
W_SCALE = 100.0
#: The full search stops when a step changes the cost or θ (transformed) by less than this
#: share. MINPACK's default of 1e-8 took 13–14 % more CPU per household at 14–28 owner
#: nights for the same medians, P90 and coverage (500 households; decision record 0031); at
#: 1e-5 one house in 60 stopped in another basin (HLC 21 % apart).
FULL_TOL = 1e-6
#: … and a warm search (from an earlier fit's θ) by less than this one. From one start
#: there is no other start to overtake it: on 192 households a morning's values stayed within
#: 0.4 % of the 1e-8 ones, at 10 % less CPU per household (decision record 0031).
WARM_TOL = 1e-6
#: MINPACK's first step bound, as a multiple of |u| (transformed θ): 100 (its default) from the
#: grid's coarse start; 1 from an earlier fit's θ, already near the new optimum. On 192
#: households' morning (decision record 0031): 25 % fewer residual evaluations, and the values
#: closer to a full fit's (largest HLC difference 6.8 → 1.6 %, τ 13 → 4 %).
FULL_STEP, WARM_STEP = 100.0, 1.0


def bounds_for(tau_e_max_s: float) -> tuple[tuple[float, float], ...]:
    """:data:`THETA_BOUNDS` with the emitter's lag up to ``tau_e_max_s`` [s]."""
    b = list(THETA_BOUNDS)
    b[2] = (b[2][0], float(tau_e_max_s))
    return tuple(b)


def to_u(theta, bounds=THETA_BOUNDS) -> Array:
    """Physical θ → unconstrained coordinates (log of the times, logit of the shares)."""
    out = []
    for (lo, hi), v in zip(bounds, theta, strict=True):
        f = (math.log(v) - math.log(lo)) / (math.log(hi) - math.log(lo)) if lo > 1 else \
            (v - lo) / (hi - lo)
        f = min(max(f, 1e-6), 1 - 1e-6)
        out.append(math.log(f / (1 - f)))
    return np.array(out)


def from_u(u: Array, bounds=THETA_BOUNDS) -> tuple[float, ...]:
    """Unconstrained coordinates → physical θ."""
    out = []
    for (lo, hi), x in zip(bounds, u, strict=True):
        f = 1.0 / (1.0 + math.exp(-min(max(float(x), -30.0), 30.0)))
        out.append(math.exp(math.log(lo) + f * (math.log(hi) - math.log(lo))) if lo > 1
                   else lo + f * (hi - lo))
    return tuple(out)  # type: ignore[return-value]


@dataclass
class Projection:
    """The linear solve at one θ."""

    beta: Array
    names: list[str]
    residual_w: Array
    X: Array | None     # None from :func:`projection` (the search's: X never formed)
    y: Array
    penalty: Array
    ridge: Array


def project(theta, d: Design) -> Projection:
    """β by ridge least squares at ``theta`` (module docstring), from X itself."""
    X, y, names = columns(theta, d)
    scale = _scale(np.einsum("ij,ij->j", X, X), len(X))
    rows = _ridge_rows(scale, d, len(y))
    Xs = X / scale
    coef, _ = _factor_solve(Xs.T @ Xs, rows.T @ rows, Xs.T @ y,
                            lambda: np.linalg.lstsq(np.concatenate([Xs, rows]),
                                                    np.r_[y, np.zeros(len(rows))],
                                                    rcond=None)[0])
    beta = coef / scale
    return Projection(beta, names, y - X @ beta, X, y, rows @ coef, rows * scale)


def _scale(sum_sq: Array, n: int) -> Array:
    """Each column's RMS over the blocks (the solve's units)."""
    scale = np.sqrt(sum_sq / n)
    # A column no usable block touches (a day's knot inside a gap of days the gateway did not
    # record, the sun of nights-only rows) keeps its natural unit: scaled by ~0 its ridge rows
    # would swamp every other column's.
    return np.where(scale > 1e-9, scale, 1.0)


def _ridge_unit(d: Design, n: int) -> Array:
    """The ridge rows for ``n`` blocks before each column's weight (:func:`_ridge_weight`):
    the daily sun amplitudes about their mean, the slow gain's steps and its knots' sum."""
    sun, gain = _kinds(d)
    p = len(sun)
    ns = int(sun.sum())
    rows = np.zeros((ns, p))
    if ns > 1:
        rows[:, sun] = math.sqrt(SUN_RIDGE * n) * (np.eye(ns) - 1.0 / ns)
    ng = int(gain.sum())
    if ng > 1 and GAIN_RW > 0:
        lam = math.sqrt(GAIN_RW * n)
        g = np.zeros((ng, p))
        g[: ng - 1, gain] = lam * (np.eye(ng - 1, ng, 1) - np.eye(ng - 1, ng))
        # the knots' mean is the gain levels' business: their sum is pulled to zero
        g[ng - 1, gain] = lam / math.sqrt(ng)
        rows = np.concatenate([rows, g])
    elif ng:
        g = np.zeros((ng, p))
        g[:, gain] = 1e3 * np.eye(ng)
        rows = np.concatenate([rows, g])
    return rows


def _kinds(d: Design) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    names = column_names(d)
    return d.once("kinds", lambda: (np.array([n.startswith("sun_") for n in names]),
                                    np.array([n.startswith("gain_") for n in names])))


def _ridge_weight(scale: Array, d: Design) -> Array:
    """Each column's factor in the ridge rows: the sun's and the slow gain's columns in their
    set's median unit (a column scaled by ~0 would otherwise swamp the others)."""
    sun, gain = _kinds(d)
    v = np.zeros(len(scale))
    if sun.sum() > 1:
        v[sun] = _median(scale[sun]) / scale[sun]
    if gain.sum() > 1 and GAIN_RW > 0:
        v[gain] = _median(scale[gain]) / scale[gain]
    elif gain.any():
        v[gain] = 1.0 / scale[gain]
    return v


def _median(x: Array) -> float:
    """np.median's value without its overhead (the search calls it twice per θ)."""
    s = np.sort(x)
    n = len(s)
    return float((s[(n - 1) // 2] + s[n // 2]) / 2.0)


def _ridge_rows(scale: Array, d: Design, n: int) -> Array:
    """The ridge rows (their target is zero) in the columns scaled by ``scale``."""
    return _ridge_unit(d, n) * _ridge_weight(scale, d)


def _factor_solve(xtx_s: Array, rtr: Array, xty_s: Array, fallback):
    """(least squares from the scaled normal equations ``xtx_s``, ``xty_s`` with the ridge
    rows' ``rtr``, its Cholesky factor): the columns are scaled and the ridge rows keep them
    well posed, four times faster than an SVD; (``fallback()`` (an SVD), None) if they are
    singular."""
    ata = xtx_s + rtr
    ata[np.diag_indices_from(ata)] += 1e-10 * np.trace(ata) / len(ata)
    try:
        factor = cho_factor(ata, check_finite=False)
    except np.linalg.LinAlgError:
        return fallback(), None
    return cho_solve(factor, xty_s, check_finite=False), factor


def projected_residual(theta, d: Design) -> Array:
    """The block residuals and the ridge rows' of :func:`project` at ``theta`` [W], from the
    normal equations' parts (:mod:`.normal`: X is never formed)."""
    solved = _solve_parts(theta, d)
    if solved is None:
        pr = project(theta, d)
        return np.concatenate([pr.residual_w, pr.penalty])
    ne, coef, scale, v, unit, _ = solved
    return np.concatenate([ne.y - ne.fitted(coef / scale, d), unit @ (v * coef)])


def _solve_parts(theta, d: Design):
    """(normal equations, coef, scale, ridge weights, ridge rows' unit, Cholesky factor) of
    the ridge least squares at ``theta`` in the order of the normal equations' columns
    (``perm``), or None when they are singular; remembered for the next few calls (the
    search asks for the residual, then for the Jacobian at the same θ)."""
    return d.cached(("solved", *theta), lambda: _solve_new(theta, d))


def _solve_new(theta, d: Design):
    ne = normal_equations(theta, d)
    n = len(ne.y)
    unit, unit_sq = d.once("ridge_perm", lambda: _permuted_ridge(d, n, ne.perm))
    scale_p = _scale(np.diag(ne.xtx).copy(), n)
    scale = np.empty_like(scale_p)
    scale[ne.perm] = scale_p
    v = _ridge_weight(scale, d)[ne.perm]
    failed = []
    coef, factor = _factor_solve(ne.xtx / np.outer(scale_p, scale_p), unit_sq * np.outer(v, v),
                                 ne.xty / scale_p, lambda: failed.append(True))
    return None if failed else (ne, coef, scale_p, v, unit, factor)


def projection(theta, d: Design) -> Projection:
    """:func:`project` from the normal equations' parts (its ``X`` is None)."""
    solved = _solve_parts(theta, d)
    if solved is None:
        return project(theta, d)
    ne, coef, scale, v, unit, _ = solved
    beta = np.empty_like(coef)
    beta[ne.perm] = coef / scale
    rows = np.empty_like(unit)
    rows[:, ne.perm] = unit * v
    full = np.empty_like(coef)
    full[ne.perm] = coef
    scale_x = np.empty_like(scale)
    scale_x[ne.perm] = scale
    return Projection(beta, column_names(d), ne.y - ne.fitted(coef / scale, d), None, ne.y,
                      rows @ full, rows * scale_x)


def _permuted_ridge(d: Design, n: int, perm: NDArray[np.int64]) -> tuple[Array, Array]:
    unit = _ridge_unit(d, n)[:, perm]
    return unit, unit.T @ unit


def _residual(u: Array, d: Design, bounds=THETA_BOUNDS) -> Array:
    return projected_residual(from_u(u, bounds), d) / W_SCALE


def _ridge_scale(theta, d: Design, perm: NDArray[np.int64], scale_p: Array) -> Array:
    """Each column's ridge weight times its scale at ``theta`` (order ``perm``): the ridge
    rows' weight on β. Only the gains' columns' scales move it (:func:`_ridge_weight`);
    the others are kept at ``scale_p``."""
    scale = np.empty_like(scale_p)
    scale[perm] = scale_p
    gcols, _ = gain_family(d)
    scale[gcols] = _scale(gain_sum_sq(theta, d), int(d.blocks.sum()))
    return (_ridge_weight(scale, d) * scale)[perm]


def _jacobian(u: Array, d: Design, bounds=THETA_BOUNDS) -> Array:
    """The search's Jacobian (:mod:`.jacobian`): forward differences of the regressors in
    the steps MINPACK's own differences took (1e-4 relative, away from zero), the solve
    differentiated; forward differences of the residual where the solve is singular."""
    steps = SEARCH_FD_STEP * np.where(u >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(u))
    solved = _solve_parts(from_u(u, bounds), d)
    if solved is not None:
        ne, _, scale, _, _, _ = solved
        return projected_jacobian(u, steps, solved, lambda x: from_u(x, bounds), d,
                                  lambda theta: _ridge_scale(theta, d, ne.perm, scale)) / W_SCALE
    r0 = _residual(u, d, bounds)
    out = np.empty((len(r0), len(u)))
    for k, h in enumerate(steps):
        uk = u.copy()
        uk[k] += h
        out[:, k] = (_residual(uk, d, bounds) - r0) / h
    return out


def _levenberg_marquardt(u0: Array, d: Design, bounds, max_nfev: int,
                         tol: float, step: float = FULL_STEP) -> OptimizeResult:
    """MINPACK's Levenberg–Marquardt (``lmder``) from ``u0``: what ``least_squares(...,
    method="lm", x_scale=1.0)`` runs, through ``leastsq``, which does not compute the Jacobian
    once more at the end (a tenth of a warm search) — its check of the shapes at the start
    costs a residual, and its Jacobian is the one the first iteration then takes. ``step``:
    the first step's bound (MINPACK's ``factor``)."""
    x, _, info, _, status = leastsq(
        _residual, u0, args=(d, bounds), Dfun=_remembered_jacobian, full_output=True,
        ftol=tol, xtol=tol, gtol=1e-8, maxfev=max_nfev, factor=step, diag=np.ones(len(u0)))
    return OptimizeResult(x=x, cost=0.5 * float(info["fvec"] @ info["fvec"]),
                          nfev=int(info["nfev"]), njev=int(info["njev"]), status=int(status))


def _remembered_jacobian(u: Array, d: Design, bounds=THETA_BOUNDS) -> Array:
    return d.cached(("jacobian", *u.tolist(), *np.ravel(bounds).tolist()),
                    lambda: _jacobian(u, d, bounds))


def search(d: Design, max_nfev: int = 60, start: tuple | None = None,
           bounds=THETA_BOUNDS, step: float | None = None,
           one_start: bool = False) -> tuple[tuple, Projection, object]:
    """Best θ, its projection and the optimiser's result (least squares over θ); from the
    grid's best point at each of :data:`START_TAU_E_S` (``one_start``: at the first alone, the
    slow basin, clipped to the bound; for a bound on the emitter's lag its fade has set), or from
    ``start`` alone (a warm start: yesterday's θ, or the full season's for a part of it), which
    then steps shorter and stops sooner (:data:`WARM_STEP`, :data:`WARM_TOL`); ``step``: the
    first step's bound instead (:data:`FULL_STEP` for a start that may be far, e.g. under
    another bound)."""
    if start is not None:
        # a start outside these bounds (another emitter's) is moved onto them
        starts = [to_u(tuple(min(max(v, lo), hi) for v, (lo, hi) in
                             zip(start, bounds, strict=True)), bounds)]
    else:
        starts = []
        for tau_e in START_TAU_E_S[:1] if one_start else START_TAU_E_S:
            grid = [to_u((tau_h * 3600, w, tau_e, START_F_SUN, START_TAU_R_S), bounds)
                    for tau_h, w in START_GRID]
            starts.append(min(grid, key=lambda u: float(np.sum(_residual(u, d, bounds) ** 2))))
    best = None
    tol = WARM_TOL if start is not None else FULL_TOL
    if step is None:
        step = WARM_STEP if start is not None else FULL_STEP
    for u0 in starts:
        res = _levenberg_marquardt(u0, d, bounds, max_nfev, tol, step)
        if best is None or res.cost < best.cost:
            best = res
    theta = from_u(best.x, bounds)
    return theta, projection(theta, d), best


def beta_dict(pr: Projection) -> dict[str, float]:
    """The fixed linear parameters by name (:data:`~.columns.BETA`)."""
    return {n: float(b) for n, b in zip(pr.names, pr.beta, strict=True) if n in BETA}
