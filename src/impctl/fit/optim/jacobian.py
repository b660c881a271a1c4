"""The Levenberg–Marquardt normal-equation terms of rows: an analytic Jacobian, or forward
differences where it does not apply (:func:`row_terms`).

A row's residuals depend on its parameters only through a few numbers per row
(:func:`~impctl.fit.ode.node.demand_scalars`, :func:`~impctl.fit.ode.node.air_scalars`: the
rate a, the initial state, the weights of each forcing and of each output term). The night ODE
is linear, so its states are z = z0·P + Σ_f w_f·Z_f, where P and the responses Z_f to each
forcing f depend on a alone, and ∂z/∂a has a closed form (:mod:`..ode.solver`). Each Jacobian
column is then a sum of a few such responses weighted by the derivatives of the numbers.

Forward differences build and integrate every row once per parameter (8–12 copies of an
(R, K) problem). Here the rows are built and integrated once, the responses to all forcings come
out of one more pass, and only the numbers are differentiated — by central differences in u on
(·, ~10) tensors. The residuals are the same arithmetic as :func:`.problem.residuals` (bit for
bit); the Jacobian is the exact one to ≈ 1e-9 where forward differences are off by their
truncation (≈ 1e-7, ``tests/test_jacobian.py``). That difference is enough to send a household
on a flat loss surface down another path: a 1e-7 change of the forward-difference step moves
such households as much (decision record 0018).
"""

from __future__ import annotations

import torch

from ..ode.node import ROW_DEMAND, air_scalars, build_rows, demand_scalars
from ..ode.parameters import DTYPE, EMC_COLUMN, to_physical
from ..ode.solver import chain_rate_derivative, chain_responses
from .problem import Context, Rows, residuals

H_U = 1e-6     # forward-difference step in u
H_M = 1e-3     # … and in θ_m,0 [K] (the residuals are affine in it, so any step is exact)
#: central-difference step in u of the row numbers (truncation ≈ h², rounding ≈ 1e-16/h)
H_NUMBERS = 1e-5


def row_terms(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor,
              one_type: bool = False):
    """Per row: Σr², Jθᵀ Jθ, Jθᵀ r, Jθᵀ Jm, Jmᵀ Jm, Jmᵀ r. Rows all of one type
    (``one_type``) take the analytic Jacobian where it applies (:func:`analytic_row_terms`);
    the others forward differences, every perturbed copy in one batched integration."""
    if one_type:
        terms = analytic_row_terms(ctx, rows, u, t_m0, bool(rows.row_type[0] == ROW_DEMAND))
        if terms is not None:
            return terms
    n_rows = len(t_m0)
    N_PARAMS = u.shape[1]  # noqa: N806 (7, or 10 with the nuisance terms)
    eye = torch.eye(N_PARAMS, dtype=DTYPE) * H_U
    u_all = torch.cat([u] + [u + eye[j] for j in range(N_PARAMS)] + [u])
    # A parameter whose box is a point (a nuisance term switched off) has a zero Jacobian
    # column: its copy is left out for those rows (the simple and per-night problems).
    live = (rows.box[:, :, 1] > rows.box[:, :, 0])[rows.problem]          # (R, 7)
    every = slice(None)
    sel = ([every] + [every if bool(live[:, j].all()) else live[:, j].nonzero()[:, 0]
                      for j in range(N_PARAMS)] + [every])
    m_all = torch.cat([t_m0[s] for s in sel[:-1]] + [t_m0 + H_M])
    r_all = residuals(ctx, rows.copies(sel), u_all, m_all)
    r0 = r_all[:n_rows]
    ends = torch.tensor([n_rows if s is every else len(s) for s in sel]).cumsum(0).tolist()
    # (R, 7, K): each row's Jacobian transposed, contiguous for the batched products below
    jt = torch.zeros(n_rows, N_PARAMS, r0.shape[1], dtype=DTYPE)
    for j in range(N_PARAMS):
        s, part = sel[j + 1], r_all[ends[j]:ends[j + 1]]
        jt[s, j] = (part - r0[s]) / H_U
    j_m = (r_all[ends[-2]:] - r0) / H_M                                 # (R, K)
    both = torch.stack([r0, j_m], dim=2)                                 # (R, K, 2)
    jt_rm = torch.bmm(jt, both)                                          # (R, 7, 2)
    return ((r0 ** 2).sum(1), torch.bmm(jt, jt.transpose(1, 2)), jt_rm[..., 0], jt_rm[..., 1],
            (j_m ** 2).sum(1), (j_m * r0).sum(1), r0)


def analytic_row_terms(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor,
                       demand: bool):
    """:func:`row_terms` of rows that are all of one type, or None where this form does
    not apply (rk4, the emitter lag, a rate outside :func:`~..ode.solver.chain_responses`'s
    range): then the caller takes forward differences.

    Parameters
    ----------
    ctx, rows : the problems and their rows (all ``ROW_DEMAND`` if ``demand``, else all
        ``ROW_AIR``)
    u : (P, n) unconstrained parameters
    t_m0 : (R,) initial mass temperatures [°C]
    demand : the rows' type
    """
    packed = ctx.packed
    n = u.shape[1]
    if ctx.solver != "exact" or (packed.emitter_lag and n > EMC_COLUMN):
        return None
    night = rows.night
    params = to_physical(u, rows.box)[rows.problem]
    model = build_rows(packed, params, t_m0, night, rows.row_type, rows.phi_w, rows.phi_in_w,
                       ctx.ach_vent, ctx.ach_infl, ctx.solver)
    ode = model.ode
    forcing = _demand_forcings if demand else _air_forcings
    # The row numbers at u and at u ± h·e_j: their Jacobian (·, m, n) in u by central
    # differences (small tensors: 2n + 1 sets of m numbers, not of (R, K) rows), accurate to
    # ≈ 1e-10. They depend on the problem's parameters alone unless a night has a gain of
    # its own: then per row.
    per_row = packed.gain_w is not None
    n_set = len(night) if per_row else len(u)
    eye = torch.eye(n, dtype=DTYPE) * H_NUMBERS
    u_all = torch.cat([u] + [u + eye[j] for j in range(n)] + [u - eye[j] for j in range(n)])
    p_all = to_physical(u_all, rows.box.repeat(2 * n + 1, 1, 1))
    if per_row:
        p_all = p_all[rows.problem.repeat(2 * n + 1)
                      + torch.arange(2 * n + 1).repeat_interleave(len(night)) * len(u)]
    numbers = demand_scalars if demand else air_scalars
    sc = numbers(packed, p_all, night.repeat(2 * n + 1) if per_row else None, ctx.ach_vent,
                 ctx.ach_infl).view(2 * n + 1, n_set, -1)
    d_sc = ((sc[1:n + 1] - sc[n + 1:]) / (2 * H_NUMBERS)).permute(1, 2, 0)
    sc = sc[0]
    if not per_row:
        d_sc, sc = d_sc[rows.problem], sc[rows.problem]
    u0, u1 = forcing(packed, night, ode.h_s, sc, rows.phi_in_w)
    resp = chain_responses(ode.a_per_s, ode.h_s, u0, u1)
    if resp is None:
        return None
    p, z_f, gamma_f = resp
    z = ode.integrate(model.z0)
    scale = rows.scale[:, None]
    r0 = torch.where(model.mask, model.predict(z) - model.measured, 0.0) * scale
    m = sc.shape[1]
    cols = torch.empty(len(night), m + 2, z.shape[1], dtype=DTYPE)
    # ∂(node output)/∂(each number) in the numbers' order, then θ_m,0's column, then the
    # residuals: one (R, m + 2, K) tensor written in place
    weights = sc[:, 1:4] if demand else sc[:, 4:8]
    gamma = (weights[:, :, None] * gamma_f[:, :weights.shape[1]]).sum(1)
    dz_da = chain_rate_derivative(z, ode.a_per_s, ode.h_s, ode.u0[:, :-1], ode.u1[:, :-1],
                                  gamma, p)
    (_demand_columns if demand else _air_columns)(cols, sc, z, dz_da, p, z_f, packed, night,
                                                  model, t_m0)
    _compare(cols[:, :m + 1], model, rows.scale)
    cols[:, m + 1] = r0
    # Jθ = columns·∂numbers/∂u, so Jθᵀ Jθ = ∂ᵀ·(columnsᵀ columns)·∂ from one Gram product of
    # the few columns: cheaper than forming Jθ (R, K, n), and in float64 its rounding stays
    # far below the forward differences' truncation (≈ 1e-7 of Jθ)
    gram = torch.bmm(cols, cols.transpose(1, 2))                        # (R, m + 2, m + 2)
    d_t = d_sc.transpose(1, 2)                                          # (R, n, m)
    jtj = torch.bmm(torch.bmm(d_t, gram[:, :m, :m]), d_sc)
    jt_rm = torch.bmm(d_t, gram[:, :m, m:])                             # (R, n, 2): Jm, r
    return ((r0 ** 2).sum(1), jtj, jt_rm[..., 1], jt_rm[..., 0], gram[:, m, m],
            gram[:, m, m + 1], r0)


def _compare(cols: torch.Tensor, model, scale: torch.Tensor) -> None:
    """Node columns (R, F, K) → what the residuals compare, masked and scaled, in place."""
    if model.lag_rate is None and model.mean_next is not None:
        # the interval mean's 0.5, the mask and the scale in one weight
        w = torch.where(model.mask, 0.5 * scale[:, None], 0.0)
        k = torch.arange(1, cols.shape[2] + 1)
        if bool(((model.mean_next == k) | ~model.mask).all()):
            # every compared node's partner is the next node (a night's samples are
            # consecutive nodes): a shifted sum instead of a gather (R, F, K)
            torch.mul(cols[..., :-1] + cols[..., 1:], w[:, None, :-1], out=cols[..., :-1])
            cols[..., -1] = 0.0
            return
        nxt = torch.gather(cols, 2, model.mean_next[:, None].expand_as(cols))
        cols.add_(nxt).mul_(w[:, None])
        return
    w = torch.where(model.mask, scale[:, None], 0.0)[:, None]
    cols.copy_(model.observe(cols) * w)


def _slope(v: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
    """Slope of node values ``v`` (R, …, K) on each interval (R, …, K−1) as build_rows takes
    it (zero on padding)."""
    return torch.where(h > 0, torch.diff(v, dim=-1) / h.clamp_min(1e-9), 0.0)


def _demand_forcings(packed, night, h, sc, phi_in_w):
    """(u0, u1) (R, 3, K−1) of T_air, T_out and a constant [per unit weight]."""
    ta, te = packed.t_air_in_c[night, :-1], packed.t_out_c[night, :-1]
    u0 = torch.stack([ta, te, torch.ones_like(ta)], dim=1)
    u1 = torch.stack([packed.t_air_in_slope[night, :-1], packed.t_out_slope[night, :-1],
                      torch.zeros_like(ta)], dim=1)
    return u0, u1


def _demand_columns(cols, sc, z, dz_da, p, z_f, packed, night, model, t_m0):
    """DEMAND rows: Φ_HC = c_m·z + c_air·T_air + c_e·T_out − gain_heat + C_fur·dT_fur/dt."""
    c_m = sc[:, 4:5]
    torch.mul(dz_da, c_m, out=cols[:, 0])
    torch.mul(z_f, c_m[:, :, None], out=cols[:, 1:4])
    cols[:, 4] = z
    cols[:, 5] = packed.t_air_in_c[night]
    cols[:, 6] = packed.t_out_c[night]
    cols[:, 7] = -1.0
    cols[:, 8] = packed.t_fur_slope[night]
    torch.mul(p, c_m, out=cols[:, 9])


def _air_forcings(packed, night, h, sc, phi_in_w):
    """(u0, u1) (R, 7, K−1) of T_out, dT_out/dt, the heat input (with the release x), a
    constant, the release's shape E, its ∂E/∂τ and the furniture's dT_fur/dt."""
    grid = packed.grid_s[night]
    t = grid - grid[:, :1]
    em_w, tau, c_fur = sc[:, 9:10], sc[:, 10:11], sc[:, 11:12]
    cons = packed.constrained[night][:, None]
    e = torch.where(cons, torch.exp(-t / tau), 0.0)
    fur = packed.t_fur_slope[night]
    x = em_w * e - c_fur * fur
    te = packed.t_out_c[night]
    v = torch.stack([te, packed.t_out_slope[night], phi_in_w + x, torch.ones_like(te), e,
                     e * t / (tau * tau), fur], dim=1)
    # within an interval the heat input is constant and only x has a slope (build_rows)
    u1 = torch.zeros_like(v[..., :-1])
    u1[:, 0] = packed.t_out_slope[night, :-1]
    u1[:, 2] = _slope(x, h)
    u1[:, 4:] = _slope(v[:, 4:], h[:, None])
    return v[..., :-1], u1


def _air_columns(cols, sc, z, dz_da, p, z_f, packed, night, model, t_m0):
    """AIR rows: T_air = z + k_Φ·(Φ_HC + x), x = emitter_w·E(τ) − C_fur·dT_fur/dt."""
    coef, k_phi, em_w, tau = sc[:, 6:7], sc[:, 8:9], sc[:, 9:10], sc[:, 10:11]
    grid = packed.grid_s[night]
    t = grid - grid[:, :1]
    e = torch.where(packed.constrained[night][:, None], torch.exp(-t / tau), 0.0)
    cols[:, 0] = dz_da
    torch.mul(p, t_m0[:, None], out=cols[:, 1])
    torch.mul(p, packed.t_out_c[night, :1], out=cols[:, 2])
    cols[:, 3] = p
    cols[:, 4:8] = z_f[:, :4]
    # k_Φ's column: the whole heat input at the nodes (model.out_v = k_Φ·(Φ_HC + x))
    torch.div(model.out_v, k_phi, out=cols[:, 8])
    cols[:, 9] = coef * z_f[:, 4] + k_phi * e
    cols[:, 10] = em_w * (coef * z_f[:, 5] + k_phi * e * t / (tau * tau))
    cols[:, 11] = -(coef * z_f[:, 6] + k_phi * packed.t_fur_slope[night])
    torch.mul(p, sc[:, 1:2], out=cols[:, 12])
