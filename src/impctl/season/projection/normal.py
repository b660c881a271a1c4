"""The season model's normal equations XᵀX, Xᵀy and X's products, from their parts.

:func:`~.columns.columns` builds X (blocks × regressors, about 2,800 × 160 for two months)
and the search's linear solve would form XᵀX from it at every θ: most of the fit's time.
:func:`normal_equations` assembles it from the regressors outside the gains' family (a few
dense rows) and the gains' Gram products (:mod:`.gram`) — four of five moves of θ keep
τ_mm, and with it the products; :func:`x_products` and :func:`fitted` give X's products
with series and with coefficients the same way. X is never formed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import csr_matrix

from .columns import (
    Design,
    column_names,
    dense_groups,
    gain_coefficients,
    gain_family,
    held_lowpass,
)
from .gram import cross_products, gain_gram, lowpassed

Array = NDArray[np.float64]


def _shapes_t(d: Design) -> tuple[csr_matrix, csr_matrix]:
    """The shapes, sparse, time × shape: at every block and at the usable ones."""
    return d.once("shapes_sparse", lambda: (csr_matrix(d.gains_b.T),
                                             csr_matrix(d.gains_b[:, d.blocks].T)))


def _shape_products(d: Design, rows: Array) -> Array:
    """rows·Sᵀ: products of series over the usable blocks with every shape."""
    return (_shapes_t(d)[1].T @ rows.T).T


@dataclass
class Normal:
    """The normal equations at one θ, X's columns in the order ``perm`` (the regressors
    outside the gains' family first, then the gains')."""

    xtx: Array
    xty: Array
    y: Array
    perm: NDArray[np.int64]
    theta: tuple[float, ...]
    q: Array            # (nq, blocks) the regressors outside the gains' family

    def fitted(self, coef: Array, d: Design) -> Array:
        """X·coef over the usable blocks (``coef`` in the order ``perm``)."""
        nq = len(self.q)
        return coef[:nq] @ self.q + _gains_fitted(self.theta, d, coef[nq:])

    def fitted_many(self, coefs: Array, d: Design) -> Array:
        """X·coef for each row of ``coefs`` (k × columns, in the order ``perm``): (k, blocks)."""
        nq = len(self.q)
        return coefs[:, :nq] @ self.q + _gains_fitted(self.theta, d, coefs[:, nq:])


def fitted(theta: tuple[float, ...], d: Design, coef: Array) -> tuple[Array, Array]:
    """(y, X·coef) at ``theta`` over the usable blocks, without X (``coef`` in X's order)."""
    gcols, _ = gain_family(d)
    out = _gains_fitted(theta, d, coef[gcols]).copy()
    y = None
    for _key, rows, cols in dense_groups(theta, d):
        for row, col in zip(rows, cols, strict=True):
            if col >= 0:
                out += coef[col] * row
            else:
                y = row
    return y, out


def _gains_fitted(theta: tuple[float, ...], d: Design, cg: Array) -> Array:
    """The gains' family's columns times their coefficients ``cg`` ((shapes,) → (blocks,), or
    (k, shapes) → (k, blocks)); one row remembered, read-only: the search's residual and its
    Jacobian's base point ask for the same, and so do the Jacobian's steps of the emitter's
    and the room's lags, which leave the gains' columns as they are."""
    if cg.ndim == 1:
        return d.cached(("gains fitted", theta[0], theta[1], theta[3], cg.tobytes()),
                        lambda: _readonly(_gains_fitted_new(theta, d, cg)))
    return _gains_fitted_new(theta, d, cg)


def _readonly(x: Array) -> Array:
    x.flags.writeable = False
    return x


def _gains_fitted_new(theta: tuple[float, ...], d: Design, cg: Array) -> Array:
    a, b = gain_coefficients(theta, d)
    shapes_t, used_t = _shapes_t(d)
    many = np.atleast_2d(cg)
    out = (used_t @ (a * many).T).T + held_lowpass(
        (shapes_t @ (b * many).T).T, theta[0], d.rec.per_block * d.rec.step_s,
        d.block_runs)[:, d.blocks]
    return out if cg.ndim == 2 else out[0]


def x_products(theta: tuple[float, ...], d: Design, rows: Array,
               known: dict | None = None) -> Array:
    """rows·X at ``theta`` (rows × X's columns, in X's order) for series ``rows`` over the
    usable blocks, without X. ``known``: the same rows' products with the shapes and their
    low-pass from earlier calls at other θ (filled in here): a step of θ that keeps τ_mm
    changes only the coefficients of the gains' columns."""
    known = {} if known is None else known
    if "shapes" not in known:
        known["shapes"] = _shape_products(d, rows)
    if ("lowpass", theta[0]) not in known:
        known["lowpass", theta[0]] = cross_products(lowpassed(theta[0], d), d, rows)
    gcols, _ = gain_family(d)
    a, b = gain_coefficients(theta, d)
    out = np.empty((len(rows), len(column_names(d))))
    out[:, gcols] = a * known["shapes"] + b * known["lowpass", theta[0]]
    for _key, q, cols in dense_groups(theta, d):
        keep = cols >= 0
        out[:, cols[keep]] = rows @ q[keep].T
    return out


def _products(d: Design, groups: list, keys: list[tuple], make) -> Array:
    """The groups' products (:func:`~.gram.cross_products`), those not remembered under
    ``keys`` made in one call of ``make`` on their rows."""
    new = [i for i, k in enumerate(keys) if d.remembered(k) is None]
    if new:
        made = make(np.concatenate([groups[i][1] for i in new]))
        at = 0
        for i in new:
            n = len(groups[i][1])
            d.cached(keys[i], lambda at=at, n=n: made[at:at + n])
            at += n
    return np.concatenate([d.remembered(k) for k in keys])


def normal_equations(theta: tuple[float, ...], d: Design) -> Normal:
    """XᵀX and Xᵀy of :func:`~.columns.columns` at ``theta``, from the parts (module
    docstring), X's columns in the order :attr:`Normal.perm`."""
    tau_mm = theta[0]
    gram = gain_gram(tau_mm, d)
    groups = dense_groups(theta, d)
    # products with the shapes and their low-pass: only of the groups this θ changed (a step
    # of the Jacobian moves one coordinate), in one pass each
    rs = _products(d, groups, [("S " + key[0], *key[1:]) for key, _, _ in groups],
                   lambda rows: _shape_products(d, rows))
    rg = _products(d, groups, [("G " + key[0], tau_mm, *key[1:]) for key, _, _ in groups],
                   lambda rows: cross_products(gram, d, rows))
    cols = np.concatenate([c for _, _, c in groups])
    qy = np.concatenate([rows for _, rows, _ in groups])
    iy = int(np.flatnonzero(cols < 0)[0])
    keep = cols >= 0
    q, y = qy[keep], qy[iy]
    gcols, _ = gain_family(d)
    a, b = gain_coefficients(theta, d)
    # (a step of τ_e or τ_r keeps it)
    gains = d.cached(("gains gram", tau_mm, theta[1], theta[3]), lambda: (
        np.outer(a, a) * gram.ss + np.outer(a, b) * gram.sg + np.outer(b, a) * gram.sg.T
        + np.outer(b, b) * gram.gg))
    cross = rs[keep] * a[None, :] + rg[keep] * b[None, :]                   # Qᵀ·gains
    xtx = np.block([[q @ q.T, cross], [cross.T, gains]])
    xty = np.r_[q @ y, rs[iy] * a + rg[iy] * b]
    return Normal(xtx, xty, y, np.r_[cols[keep], gcols], tuple(theta), q)
