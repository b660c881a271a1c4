"""The projected residual's Jacobian in θ without solving β again at every step.

The search's residual is r(θ) = ỹ − X̃β̂(θ): the data and the ridge rows (X̃ = [X; −ridge
rows], ỹ = [y; 0]) less their ridge least-squares fit β̂ = (X̃ᵀX̃ + εI)⁻¹X̃ᵀỹ. A
finite-difference Jacobian solves that fit again for each of θ's five coordinates: the normal
equations at each moved θ (for τ_mm the gains' Gram products, the largest piece of an
evaluation) and their Cholesky solve. Differentiating the solve instead (Golub and Pereyra
1973, *SIAM J. Numer. Anal.* 10:413) gives, per coordinate,

    ∂r/∂θ_k = m_k − X̃ (X̃ᵀX̃ + εI)⁻¹ (X̃ᵀm_k + ∂X̃ᵀr),   m_k = ∂(ỹ − X̃β̂)/∂θ_k at fixed β̂,

which needs only the regressors at the moved θ times β̂ (:func:`~.normal.fitted`: the filtered
series, no products), ∂X̃ᵀr from the products of the one residual with the moved regressors
(a step that keeps τ_mm changes only the gains' coefficients), and, for all five at once, one
product with X, one solve with the factor already made and one product of X with the
solutions. m_k and ∂X̃ᵀr are forward differences in the steps the finite differences took,
so the columns are theirs to their own rounding (the tests: 1e-6). Kaufman's shortcut (1975),
m_k projected alone, gave the search the same gradient but a Gauss–Newton matrix 0.2–1.0 ×
the true one: its longer steps ended 5 of 64 full searches in a corner of higher cost.
The ridge rows' weights on β move with θ too (each set's median column scale,
:mod:`.solve`): they are part of X̃ here.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_solve

from .normal import fitted, x_products

Array = NDArray[np.float64]


def projected_jacobian(u: Array, steps: Array, solved, theta_of, d, ridge_scale) -> Array:
    """(rows, len(u)): the Jacobian of the projected residual (data rows, then ridge rows;
    in the search's units before its scale) at the transformed θ ``u``.

    ``solved``: the ridge least squares at ``u`` (:func:`~.solve._solve_parts`: normal
    equations, scaled coefficients in their order, column scales, ridge weights, ridge rows'
    unit, Cholesky factor); ``theta_of(u)``: the physical θ; ``steps``: each coordinate's
    forward difference in ``u`` of the regressors at fixed β; ``ridge_scale(θ)``: each
    column's weight in the ridge rows times its scale (the weight on β) at θ."""
    ne, coef, scale, v, unit, factor = solved
    theta = theta_of(u)
    beta_p = coef / scale                            # in the solve's order
    beta = np.empty_like(coef)
    beta[ne.perm] = beta_p                           # in X's
    y0, f0 = fitted(theta, d, beta)
    r0, vs0 = y0 - f0, ridge_scale(theta)
    known: dict = {}   # r0's products with the shapes and their low-pass, by τ_mm
    at_r0 = x_products(theta, d, r0[None, :], known)[0, ne.perm]
    ridge_r0 = unit.T @ (unit @ (vs0 * beta_p))     # unitᵀ × the ridge rows' residual
    moved = np.empty((len(u), len(r0)))
    moved_w = np.empty((len(u), len(beta_p)))
    turned = np.empty((len(u), len(beta_p)))        # ∂X̃ᵀ r̃ at fixed r̃ (Golub–Pereyra)
    for k in range(len(u)):
        uk = u.copy()
        uk[k] += steps[k]
        theta_k = theta_of(uk)
        yk, fk = fitted(theta_k, d, beta)
        moved[k] = ((yk - fk) - r0) / steps[k]
        dvs = (ridge_scale(theta_k) - vs0) / steps[k]
        moved_w[k] = dvs * beta_p
        turned[k] = (x_products(theta_k, d, r0[None, :], known)[0, ne.perm] - at_r0) \
            / steps[k] \
            - dvs * ridge_r0
    moved_ridge = moved_w @ unit.T
    # ĉ = A⁻¹ (X̃ᵀ[moved; moved ridge] + ∂X̃ᵀ r̃) in the solve's scaled columns (order
    # ``ne.perm``), X̃ = [X/scale; −ridge rows]: the column is [moved − X ĉ/scale;
    # moved ridge + rows ĉ]
    rows = unit * v
    xt = (x_products(theta, d, moved)[:, ne.perm] + turned) / scale - moved_ridge @ rows
    c = cho_solve(factor, xt.T, check_finite=False).T          # (k, p) scaled
    data = moved - ne.fitted_many(c / scale, d)
    ridge = moved_ridge + c @ rows.T
    return np.concatenate([data, ridge], axis=1).T

