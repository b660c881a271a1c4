"""The season fit's uncertainty: the covariance of (θ, β) and the lumped quantities' errors.

:func:`covariance` is the day-clustered sandwich of the search's optimum (:mod:`.solve`),
from the normal equations' parts (:mod:`.normal`: X never formed); :func:`lumped_log_se`
carries it to log HLC, log τ and log C_m by the delta method.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .columns import Design, lumped
from .normal import fitted, normal_equations, x_products
from .solve import THETA_BOUNDS, Projection, from_u

Array = NDArray[np.float64]

#: Finite-difference step in the transformed θ coordinates for the Jacobian [-].
FD_STEP = 1e-4


def _fixed_residual(u: Array, beta: Array, d: Design, bounds=THETA_BOUNDS) -> Array:
    y, fit = fitted(from_u(u, bounds), d, beta)
    return y - fit


def covariance(u: Array, pr: Projection, d: Design, bounds=THETA_BOUNDS) -> Array:
    """Covariance of (u, β) by the day-clustered sandwich: the bread from the Jacobian of the
    block residuals (the ridge rows included), the meat from each local day's summed scores —
    residuals of one day share its weather, its sun and its owner, so they are not independent.
    The Jacobian J = [∂r/∂u, −X] enters as JᵀJ and per-day sums of J·r only: from the normal
    equations' parts (:mod:`.normal`), X never formed."""
    theta = from_u(u, bounds)
    r0 = _fixed_residual(u, pr.beta, d, bounds)
    ju = np.empty((len(r0), len(u)))
    for k in range(len(u)):
        du = np.zeros_like(u)
        du[k] = FD_STEP
        ju[:, k] = (_fixed_residual(u + du, pr.beta, d, bounds) - r0) / FD_STEP
    ne = normal_equations(theta, d)
    xtx = np.empty_like(ne.xtx)
    xtx[np.ix_(ne.perm, ne.perm)] = ne.xtx
    xt_ju = x_products(theta, d, ju.T).T
    jtj = np.block([[ju.T @ ju, -xt_ju.T], [-xt_ju, xtx]])
    nu = len(u)
    if pr.penalty.shape[0]:
        ridge = _penalty_rows(pr)
        jtj[nu:, nu:] += ridge.T @ ridge
    bread = np.linalg.pinv(jtj)
    days, which = np.unique(d.block_day(), return_inverse=True)
    on_day = np.zeros((len(days), len(r0)))         # each day's residuals, 0 elsewhere
    on_day[which, np.arange(len(r0))] = r0
    g = np.concatenate([on_day @ ju, -x_products(theta, d, on_day)], axis=1)  # day's scores
    n_c = len(days)
    return bread @ (g.T @ g) @ bread * (n_c / max(n_c - 1, 1))


def _penalty_rows(pr: Projection) -> Array:
    """The ridge rows in β's own scale (their residual is rows @ β)."""
    return pr.ridge


#: The lumped quantities the intervals are given for.
LUMPED = ("hlc_w_per_k", "tau_h", "c_m_j_per_k")


def lumped_log_se(u: Array, pr: Projection, cov: Array,
                  bounds=THETA_BOUNDS) -> dict[str, float]:
    """Standard errors of log HLC, log τ and log C_m by the delta method (finite differences
    over θ's coordinates and the two conductances; every other β enters none of them)."""
    ia, im = pr.names.index("k_ao_w_per_k"), pr.names.index("k_am_w_per_k")
    nu = len(u)
    idx = list(range(nu)) + [nu + ia, nu + im]

    def f(p: Array) -> Array:
        L = lumped(from_u(p[:nu], bounds), p[nu], p[nu + 1])
        return np.log(np.maximum([L[k] for k in LUMPED], 1e-12))

    p0 = np.r_[u, pr.beta[ia], pr.beta[im]]
    f0 = f(p0)
    G = np.empty((len(LUMPED), len(p0)))
    for k in range(len(p0)):
        h = FD_STEP * max(1.0, abs(p0[k])) if k >= nu else FD_STEP
        dp = np.zeros_like(p0)
        dp[k] = h
        G[:, k] = (f(p0 + dp) - f0) / h
    sub = cov[np.ix_(idx, idx)]
    var = np.einsum("ij,jk,ik->i", G, sub, G)
    return {k: float(np.sqrt(max(v, 0.0))) for k, v in zip(LUMPED, var, strict=True)}
