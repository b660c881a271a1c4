"""The season search's normal equations from the regressors' structure against X itself.

The search never forms X (:mod:`impctl.season.projection.normal`); these tests form it
(:func:`impctl.season.projection.columns.columns`) and check that the products, the fitted
values, the
projected residual and the fit's result are those of the straightforward computation — on the
run's short winter (``winter_season``), with the household electricity measured (a dense
row), with a week the gateway did not record (several stretches of the heat store) and with
rows 10 min apart (three steps per block).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.optimize import least_squares

from impctl.population.season_run.nights import household_nights
from impctl.season import record_from_nights
from impctl.season.projection.columns import Design, columns, lumped
from impctl.season.projection.normal import fitted, normal_equations
from impctl.season.projection.solve import (
    SEARCH_FD_STEP,
    W_SCALE,
    _jacobian,
    _residual,
    beta_dict,
    from_u,
    project,
    projected_residual,
    search,
    to_u,
)

#: θ across the search's bounds: (τ_mm [s], w, τ_e [s], f_sun, τ_r [s]).
THETAS = ((36 * 3600.0, 0.9, 3600.0, 0.3, 300.0), (1.2 * 3600.0, 0.03, 70.0, 0.02, 12.0),
          (390 * 3600.0, 0.99, 10000.0, 0.97, 1700.0), (8 * 3600.0, 0.7, 300.0, 0.05, 300.0))


def _thinned(night, every: int):
    n = len(night.time_s)
    fields = {f.name: getattr(night, f.name) for f in dataclasses.fields(night)}
    return dataclasses.replace(night, **{
        k: np.asarray(v)[::every] for k, v in fields.items()
        if isinstance(v, np.ndarray) and v.ndim == 1 and len(v) == n})


@pytest.fixture(scope="module")
def designs(winter_season):
    """Designs of the winter's households: as exported, a week left out, 10-min rows."""
    out = {}
    for h in range(2):
        nights = household_nights(winter_season, h)
        first = nights[0].start.normalize()
        gap = [n for n in nights
               if n.kind != "owner" or not 5 <= (n.start.normalize() - first).days < 12]
        out[f"house {h}"] = Design.of(record_from_nights(nights))
        out[f"house {h}, a week not recorded"] = Design.of(record_from_nights(gap))
    out["house 0, 10-min rows"] = Design.of(record_from_nights(
        [_thinned(n, 2) for n in household_nights(winter_season, 0)]))
    return out


def test_the_designs_cover_the_structures_the_products_handle(designs):
    d = designs["house 1, a week not recorded"]
    assert len(d.block_runs) > 1                       # the tails restart per stretch
    assert np.isfinite(d.rec.p_house_w).any() and d.gains_b[-1].any()   # a dense row
    assert designs["house 0, 10-min rows"].rec.per_block == 3


def test_the_normal_equations_from_the_parts_are_those_of_x(designs):
    rng = np.random.default_rng(5)
    for name, d in designs.items():
        for theta in THETAS:
            X, y, _ = columns(theta, d)
            ne = normal_equations(theta, d)
            xtx = np.empty_like(ne.xtx)
            xtx[np.ix_(ne.perm, ne.perm)] = ne.xtx
            xty = np.empty_like(ne.xty)
            xty[ne.perm] = ne.xty
            ref = X.T @ X
            assert np.abs(xtx - ref).max() <= 1e-11 * np.abs(ref).max(), (name, theta)
            assert np.abs(xty - X.T @ y).max() <= 1e-11 * np.abs(X.T @ y).max(), (name, theta)
            np.testing.assert_array_equal(ne.y, y)
            beta = rng.normal(size=X.shape[1]) * 100.0
            y2, fit = fitted(theta, d, beta)
            np.testing.assert_array_equal(y2, y)
            # what the sandwich's Jacobian is taken from: y − X·β at each step of θ
            np.testing.assert_allclose(fit, X @ beta, rtol=0,
                                       atol=1e-11 * np.abs(X @ beta).max())


def test_the_search_residual_is_the_projection_on_x(designs):
    for name, d in designs.items():
        for theta in THETAS:
            pr = project(theta, d)
            ref = np.concatenate([pr.residual_w, pr.penalty])
            fast = projected_residual(theta, d)
            assert np.abs(fast - ref).max() <= 1e-8 * np.abs(ref).max(), (name, theta)


def _on_x(u, d):
    p = project(from_u(u), d)
    return np.concatenate([p.residual_w, p.penalty]) / W_SCALE


def _jacobian_on_x(u, d):
    """The variable projection's Jacobian (Golub and Pereyra) formed from X itself: the
    augmented regressors X̃ = [X; −ridge rows], ỹ = [y; 0], their forward differences in the
    search's steps, and the search's own solve (columns at unit RMS, the diagonal raised by
    1e-10 of its mean: β̂ = (X̃ᵀX̃ + εI)⁻¹X̃ᵀỹ), whose derivative gives
    ∂r = m − X̃ (X̃ᵀX̃ + εI)⁻¹ (X̃ᵀm + ∂X̃ᵀ r̃) with m = ∂(ỹ − X̃β̂) at fixed β̂."""
    def augmented(theta):
        X, y, _ = columns(theta, d)
        p = project(theta, d)
        return np.concatenate([X, -p.ridge]), np.r_[y, np.zeros(len(p.ridge))], p.beta

    xa, ya, beta = augmented(from_u(u))
    n = len(columns(from_u(u), d)[1])
    scale = np.sqrt((xa[:n] ** 2).sum(0) / n)
    scale = np.where(scale > 1e-9, scale, 1.0)
    xs = xa / scale
    ata = xs.T @ xs
    ata[np.diag_indices_from(ata)] += 1e-10 * np.trace(ata) / len(ata)
    r = ya - xa @ beta
    out = np.empty((len(r), len(u)))
    for k in range(len(u)):
        h = SEARCH_FD_STEP * (1.0 if u[k] >= 0 else -1.0) * max(1.0, abs(u[k]))
        uk = u.copy()
        uk[k] += h
        xk, yk, _ = augmented(from_u(uk))
        dx, dy = (xk - xa) / h, (yk - ya) / h
        moved = dy - dx @ beta
        out[:, k] = moved - xs @ np.linalg.solve(ata, (xa.T @ moved + dx.T @ r) / scale)
    return out / W_SCALE


def test_the_search_jacobian_is_the_variable_projections_on_x(designs):
    """The search's Jacobian, from the structure at fixed β (:mod:`.jacobian`), against the
    variable projection's formed from X: the same columns; and its gradient Jᵀr against the
    cost's own central differences."""
    for name in ("house 0", "house 1, a week not recorded", "house 0, 10-min rows"):
        d = designs[name]
        for theta in THETAS:
            u = to_u(theta)
            jac, ref = _jacobian(u, d), _jacobian_on_x(u, d)
            assert np.abs(jac - ref).max() <= 1e-6 * np.abs(ref).max(), (name, theta)
            r = _residual(u, d)
            grad = np.empty(len(u))
            for k in range(len(u)):
                e = np.zeros(len(u))
                e[k] = 1e-6 * max(1.0, abs(u[k]))
                grad[k] = (np.sum(_residual(u + e, d) ** 2)
                           - np.sum(_residual(u - e, d) ** 2)) / (4 * e[k])
            np.testing.assert_allclose(jac.T @ r, grad, rtol=0,
                                       atol=1e-3 * np.abs(grad).max())


def test_the_search_lands_where_the_search_on_x_lands(designs):
    """The search from the structure against the same least squares on X's own projection
    and Jacobian, from the same start: θ and HLC, τ and C_m agree far inside the 0.5 % the
    speed-up may move them. The start lies in a basin: from starts far up a slope (τ_mm
    8 or 20 h) on the house with a week missing, both searches run into the bounds and
    rounding decides which corner."""
    for name in ("house 0", "house 1, a week not recorded"):
        d = designs[name]
        start = (3 * 3600.0, 0.9, 7200.0, 0.05, 600.0)
        theta, pr, _ = search(d, start=start)
        ref = least_squares(_on_x, to_u(start), jac=_jacobian_on_x, args=(d,), method="lm",
                            max_nfev=60, x_scale=1.0, ftol=1e-6, xtol=1e-6)
        ref_theta = from_u(ref.x)
        ref_b = beta_dict(project(ref_theta, d))
        b = beta_dict(pr)
        got = lumped(theta, b["k_ao_w_per_k"], b["k_am_w_per_k"])
        want = lumped(ref_theta, ref_b["k_ao_w_per_k"], ref_b["k_am_w_per_k"])
        for k in ("hlc_w_per_k", "tau_h", "c_m_j_per_k"):
            assert got[k] == pytest.approx(want[k], rel=1e-3), (name, k)
        np.testing.assert_allclose(theta, ref_theta, rtol=1e-3)


def test_the_shapes_block_means_are_the_means_of_the_steps(designs):
    """Each day's sun and the slow gain's knots, summed per block without the (steps × knots)
    matrix: the block means of :func:`gain_knots` and of the day-masked sun shape."""
    from impctl.season.projection.columns import gain_knots
    from impctl.season.record import sun_shape

    for name, d in designs.items():
        rec, k = d.rec, d.rec.per_block
        nb = len(d.blocks)

        def mean(x, nb=nb, k=k):
            return x[: nb * k].reshape((nb, k) + x.shape[1:]).mean(axis=1)

        days = rec.day - rec.day.min()
        sun = np.stack([mean(np.where(days == i, sun_shape(rec.hour), 0.0))
                        for i in range(d.n_days)])
        np.testing.assert_allclose(d.gains_b[2:2 + d.n_days], sun, rtol=0, atol=1e-14,
                                   err_msg=name)
        np.testing.assert_allclose(d.gains_b[2 + d.n_days:-1], mean(gain_knots(rec)).T,
                                   rtol=0, atol=1e-14, err_msg=name)


def test_the_sandwich_is_that_of_the_jacobian_with_x(designs):
    """The covariance from the normal equations' parts against the sandwich written out with
    J = [∂r/∂u, −X] and each day's summed scores."""
    from impctl.season.projection.solve import projection
    from impctl.season.projection.uncertainty import FD_STEP, covariance

    for name in ("house 0", "house 1, a week not recorded"):
        d = designs[name]
        theta = THETAS[0]
        u = to_u(theta)
        pr = projection(theta, d)
        ref_pr = project(theta, d)
        np.testing.assert_allclose(pr.beta, ref_pr.beta, rtol=1e-7,
                                   atol=1e-9 * np.abs(ref_pr.beta).max())
        X, y, _ = columns(theta, d)
        r0 = y - X @ pr.beta
        ju = np.empty((len(r0), len(u)))
        for k in range(len(u)):
            du = np.zeros_like(u)
            du[k] = FD_STEP
            X2, y2, _ = columns(from_u(u + du), d)
            ju[:, k] = ((y2 - X2 @ pr.beta) - r0) / FD_STEP
        J = np.concatenate([ju, -X], axis=1)
        Jp = np.zeros((len(pr.penalty), J.shape[1]))
        Jp[:, len(u):] = -pr.ridge
        bread = np.linalg.pinv(J.T @ J + Jp.T @ Jp)
        day = d.block_day()
        scores = J * r0[:, None]
        meat = sum(np.outer(g, g) for g in (scores[day == c].sum(axis=0)
                                            for c in np.unique(day)))
        n_c = len(np.unique(day))
        ref = bread @ meat @ bread * (n_c / (n_c - 1))
        cov = covariance(u, pr, d)
        # the θ block and the two conductances: what the intervals are taken from
        idx = [0, 1, 2, 3, 4, len(u) + 0, len(u) + 1]
        np.testing.assert_allclose(cov[np.ix_(idx, idx)], ref[np.ix_(idx, idx)], rtol=1e-5,
                                   atol=1e-8 * np.abs(ref[np.ix_(idx, idx)]).max(),
                                   err_msg=name)
