"""The Levenberg–Marquardt normal-equation terms of rows: an analytic Jacobian, or forward
differences where it does not apply (:func:`row_terms`).

A row's residuals depend on its parameters only through a few numbers per row
(:func:`~impctl.fit.ode.node.row_scalars`: the rate a, the initial state, the weights of each
forcing and of each output term). The night ODE is linear, so its states are
z = z0·P + Σ_f w_f·Z_f, where P and the responses Z_f to each forcing f depend on a alone, and
∂z/∂a has a closed form (:mod:`..ode.solver`). Each Jacobian column is then a sum of a few such
responses weighted by the derivatives of the numbers.

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

from dataclasses import dataclass

import torch

from ..ode.node import ROW_DEMAND, RowModel, build_rows, interval_slope, row_scalars
from ..ode.packing import rows_at
from ..ode.parameters import DTYPE, EMC_COLUMN, to_physical
from ..ode.solver import chain_rate_derivative, chain_responses
from .problem import Context, Rows, residuals

H_U = 1e-6     # forward-difference step in u
H_M = 1e-3     # … and in θ_m,0 [K] (the residuals are affine in it, so any step is exact)
#: central-difference step in u of the row numbers (truncation ≈ h², rounding ≈ 1e-16/h)
H_NUMBERS = 1e-5


@dataclass
class Evaluated:
    """Rows of one type evaluated at a point: their scaled residuals now, the Jacobian's
    products when asked (:func:`terms`), so that an optimiser pays for the Jacobian only of
    the steps it takes."""

    rows: Rows
    t_m0: torch.Tensor                 # (R,) [°C]
    r0: torch.Tensor                   # (R, K) scaled residuals
    demand: bool | None = None         # the rows' type for the analytic Jacobian, or None
    model: RowModel | None = None      # … and the built rows and their states
    z: torch.Tensor | None = None
    fd: tuple | None = None            # forward differences: every term, already
    numbers: _Numbers | None = None    # the row numbers at u, shared by the point's row types

    def take(self, sel: torch.Tensor) -> Evaluated:
        """The rows ``sel`` (indices; problems keep their numbers)."""
        if self.fd is not None:
            return Evaluated(self.rows.at(sel), self.t_m0[sel], self.r0[sel],
                             fd=tuple(x[sel] for x in self.fd))
        return Evaluated(self.rows.at(sel), self.t_m0[sel], self.r0[sel], self.demand,
                         self.model.take(sel), self.z[sel], numbers=self.numbers)


class _Numbers:
    """Per problem, the row numbers of every row type at one point u and their Jacobian in u
    (:func:`_numbers`), computed once for all the point's rows (callers pass that point's u):
    the numbers' small tensors cost a fixed few hundred operations per call, a large share of
    a small batch's iteration."""

    def __init__(self, kinds: tuple[bool, ...]):
        self.kinds, self.value = kinds, None

    def get(self, ctx: Context, u: torch.Tensor, box: torch.Tensor, demand: bool):
        if self.value is None:
            self.value = _numbers(ctx, u, box, None, self.kinds)
        return self.value[demand]


def evaluate(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor
             ) -> list[tuple[torch.Tensor | None, Evaluated]]:
    """The rows' residuals at (u, t_m0), each row type on its own rows (build_rows skips the
    other type's arithmetic): [(row ids, or None for all rows, :class:`Evaluated`)]."""
    demand = rows.row_type == ROW_DEMAND
    if bool(demand.all()) or not bool(demand.any()):
        kind = bool(demand[0]) if len(demand) else None
        return [(None, _evaluate_one(ctx, rows, u, t_m0, kind, _Numbers((kind,))))]
    idx = [demand.nonzero()[:, 0], (~demand).nonzero()[:, 0]]
    numbers = _Numbers((True, False))
    return [(i, _evaluate_one(ctx, rows.at(i, phi=j == 1), u, t_m0[i], j == 0, numbers))
            for j, i in enumerate(idx)]


def loss_rows(parts: list[tuple[torch.Tensor | None, Evaluated]]) -> torch.Tensor:
    """(R,) Σ r² of each row of :func:`evaluate`'s parts."""
    if parts[0][0] is None:
        return (parts[0][1].r0 ** 2).sum(1)
    out = torch.empty(sum(len(i) for i, _ in parts), dtype=DTYPE)
    for i, ev in parts:
        out[i] = (ev.r0 ** 2).sum(1)
    return out


def assemble(ctx: Context, parts: list[tuple[torch.Tensor | None, Evaluated]],
             u: torch.Tensor, sel: torch.Tensor | None = None) -> tuple:
    """:func:`terms` of :func:`evaluate`'s parts, in row order, of the rows ``sel`` (bool, R)
    or of all rows."""
    if parts[0][0] is None:
        return terms(ctx, parts[0][1], u, None if sel is None else sel.nonzero()[:, 0])
    outs, ids = [], []
    for i, ev in parts:
        s = None if sel is None else sel[i].nonzero()[:, 0]
        if s is not None and not len(s):   # no row of this type is wanted
            continue
        outs.append(terms(ctx, ev, u, s))
        ids.append(i if s is None else i[s])
    order = torch.argsort(torch.cat(ids))
    return tuple(torch.cat(pair)[order] for pair in zip(*outs, strict=True))


def terms(ctx: Context, ev: Evaluated, u: torch.Tensor, sel: torch.Tensor | None = None
          ) -> tuple:
    """Per row of ``ev`` (or of its rows ``sel``): Σr², Jθᵀ Jθ, Jθᵀ r, Jθᵀ Jm, Jmᵀ Jm,
    Jmᵀ r, r."""
    if sel is not None:
        ev = ev.take(sel)
    if ev.fd is not None:
        return ev.fd
    out = _analytic(ctx, ev, u)
    return out if out is not None else _forward_differences(ctx, ev.rows, u, ev.t_m0)


def row_terms(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor,
              one_type: bool = False) -> tuple:
    """:func:`terms` of ``rows`` at (u, t_m0): the analytic Jacobian where the rows are all
    of one type (``one_type``) and it applies, else forward differences."""
    kind = bool(rows.row_type[0] == ROW_DEMAND) if one_type and len(t_m0) else None
    return terms(ctx, _evaluate_one(ctx, rows, u, t_m0, kind), u)


def analytic_row_terms(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor,
                       demand: bool) -> tuple | None:
    """:func:`row_terms` with the analytic Jacobian, or None where it does not apply (rk4,
    the emitter lag, a rate outside :func:`~..ode.solver.chain_responses`'s range).

    Parameters
    ----------
    ctx, rows : the problems and their rows (all ``ROW_DEMAND`` if ``demand``, else all
        ``ROW_AIR``)
    u : (P, n) unconstrained parameters
    t_m0 : (R,) initial mass temperatures [°C]
    demand : the rows' type
    """
    ev = _evaluate_one(ctx, rows, u, t_m0, demand)
    return None if ev.fd is not None else _analytic(ctx, ev, u)


def _evaluate_one(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor,
                  demand: bool | None, numbers: _Numbers | None = None) -> Evaluated:
    if demand is None or ctx.solver != "exact" or (ctx.packed.emitter_lag
                                                   and u.shape[1] > EMC_COLUMN):
        fd = _forward_differences(ctx, rows, u, t_m0)
        return Evaluated(rows, t_m0, fd[6], fd=fd)
    params = rows_at(to_physical(u, rows.box), rows.problem)
    model = build_rows(ctx.packed, params, t_m0, rows.night, rows.row_type, rows.phi_w,
                       rows.phi_in_w, ctx.ach_vent, ctx.ach_infl, ctx.solver)
    z = model.ode.integrate(model.z0)
    # the arithmetic of problem.residuals, bit for bit
    r0 = torch.where(model.mask, model.predict(z) - model.measured, 0.0) * rows.scale[:, None]
    return Evaluated(rows, t_m0, r0, demand, model, z,
                     numbers=numbers if numbers is not None else _Numbers((demand,)))


def _forward_differences(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor
                         ) -> tuple:
    """:func:`terms` by forward differences, every perturbed copy in one batched call."""
    n_rows = len(t_m0)
    N_PARAMS = u.shape[1]  # noqa: N806 (7, or 10 with the nuisance terms)
    eye = torch.eye(N_PARAMS, dtype=DTYPE) * H_U
    u_all = torch.cat([u] + [u + eye[j] for j in range(N_PARAMS)] + [u])
    # A parameter whose box is a point (a nuisance term switched off) has a zero Jacobian
    # column: its copy is left out for those rows (the simple and per-night problems).
    live = rows_at(rows.box[:, :, 1] > rows.box[:, :, 0], rows.problem)          # (R, 7)
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


def _analytic(ctx: Context, ev: Evaluated, u: torch.Tensor) -> tuple | None:
    """:func:`terms` of analytically evaluated rows; None where a rate leaves
    :func:`~..ode.solver.chain_responses`'s range."""
    packed, rows, model, z, r0, demand = ctx.packed, ev.rows, ev.model, ev.z, ev.r0, ev.demand
    night = rows.night
    ode = model.ode
    forcing = _demand_forcings if demand else _air_forcings
    if packed.gain_w is None and ev.numbers is not None:   # per problem, shared
        sc, d_sc = ev.numbers.get(ctx, u, rows.box, demand)
        sc, d_sc = rows_at(sc, rows.problem), rows_at(d_sc, rows.problem)
    else:                                                  # a night's own gain: per row
        sc, d_sc = _numbers(ctx, u, rows.box, rows, (demand,))[demand]
    u0, u1 = forcing(packed, night, ode.h_s, sc, rows.phi_in_w)
    resp = chain_responses(ode.a_per_s, ode.h_s, u0, u1)
    if resp is None:
        return None
    p, z_f, gamma_f = resp
    m = sc.shape[1]
    cols = torch.empty(len(night), m + 2, z.shape[1], dtype=DTYPE)
    # ∂(node output)/∂(each number) in the numbers' order, then θ_m,0's column, then the
    # residuals: one (R, m + 2, K) tensor written in place
    weights = sc[:, 1:4] if demand else sc[:, 4:8]
    gamma = (weights[:, :, None] * gamma_f[:, :weights.shape[1]]).sum(1)
    dz_da = chain_rate_derivative(z, ode.a_per_s, ode.h_s, ode.u0[:, :-1], ode.u1[:, :-1],
                                  gamma, p)
    (_demand_columns if demand else _air_columns)(cols, sc, z, dz_da, p, z_f, packed, night,
                                                  model, ev.t_m0)
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


def _numbers(ctx: Context, u: torch.Tensor, box: torch.Tensor, rows: Rows | None,
             kinds: tuple[bool, ...]) -> dict:
    """Row type → (the row numbers (·, m), their Jacobian in u (·, m, n)) at u, per problem
    (``rows`` None: where no night has a gain of its own) or per row of ``rows``; the
    Jacobian by central differences on these small tensors (2n + 1 sets of m numbers, not of
    (R, K) rows), accurate to ≈ 1e-10."""
    n = u.shape[1]
    eye = torch.eye(n, dtype=DTYPE) * H_NUMBERS
    u_all = torch.cat([u] + [u + eye[j] for j in range(n)] + [u - eye[j] for j in range(n)])
    p_all = to_physical(u_all, box.repeat(2 * n + 1, 1, 1))
    night = None
    if rows is not None:
        p_all = p_all[rows.problem.repeat(2 * n + 1)
                      + torch.arange(2 * n + 1).repeat_interleave(len(rows.night)) * len(u)]
        night = rows.night.repeat(2 * n + 1)
    out = {}
    for kind, sc in row_scalars(ctx.packed, p_all, night, ctx.ach_vent, ctx.ach_infl,
                                kinds).items():
        sc = sc.view(2 * n + 1, len(sc) // (2 * n + 1), -1)
        out[kind] = sc[0], ((sc[1:n + 1] - sc[n + 1:]) / (2 * H_NUMBERS)).permute(1, 2, 0)
    return out


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


def _demand_forcings(packed, night, h, sc, phi_in_w):
    """(u0, u1) (R, 3, K−1) of T_air, T_out and a constant [per unit weight]."""
    ta, te = rows_at(packed.t_air_in_c, night)[:, :-1], rows_at(packed.t_out_c, night)[:, :-1]
    u0 = torch.stack([ta, te, torch.ones_like(ta)], dim=1)
    u1 = torch.stack([rows_at(packed.t_air_in_slope, night)[:, :-1],
                      rows_at(packed.t_out_slope, night)[:, :-1], torch.zeros_like(ta)], dim=1)
    return u0, u1


def _demand_columns(cols, sc, z, dz_da, p, z_f, packed, night, model, t_m0):
    """DEMAND rows: Φ_HC = c_m·z + c_air·T_air + c_e·T_out − gain_heat + C_fur·dT_fur/dt."""
    c_m = sc[:, 4:5]
    torch.mul(dz_da, c_m, out=cols[:, 0])
    torch.mul(z_f, c_m[:, :, None], out=cols[:, 1:4])
    cols[:, 4] = z
    cols[:, 5] = rows_at(packed.t_air_in_c, night)
    cols[:, 6] = rows_at(packed.t_out_c, night)
    cols[:, 7] = -1.0
    cols[:, 8] = rows_at(packed.t_fur_slope, night)
    torch.mul(p, c_m, out=cols[:, 9])


def _air_forcings(packed, night, h, sc, phi_in_w):
    """(u0, u1) (R, 7, K−1) of T_out, dT_out/dt, the heat input (with the release x), a
    constant, the release's shape E, its ∂E/∂τ and the furniture's dT_fur/dt."""
    grid = rows_at(packed.grid_s, night)
    t = grid - grid[:, :1]
    em_w, tau, c_fur = sc[:, 9:10], sc[:, 10:11], sc[:, 11:12]
    cons = rows_at(packed.constrained, night)[:, None]
    e = torch.where(cons, torch.exp(-t / tau), 0.0)
    fur = rows_at(packed.t_fur_slope, night)
    x = em_w * e - c_fur * fur
    te = rows_at(packed.t_out_c, night)
    v = torch.stack([te, rows_at(packed.t_out_slope, night), phi_in_w + x, torch.ones_like(te), e,
                     e * t / (tau * tau), fur], dim=1)
    # within an interval the heat input is constant and only x has a slope (build_rows)
    u1 = torch.zeros_like(v[..., :-1])
    u1[:, 0] = rows_at(packed.t_out_slope, night)[:, :-1]
    u1[:, 2] = interval_slope(x, h)
    u1[:, 4:] = interval_slope(v[:, 4:], h[:, None])
    return v[..., :-1], u1


def _air_columns(cols, sc, z, dz_da, p, z_f, packed, night, model, t_m0):
    """AIR rows: T_air = z + k_Φ·(Φ_HC + x), x = emitter_w·E(τ) − C_fur·dT_fur/dt."""
    coef, k_phi, em_w, tau = sc[:, 6:7], sc[:, 8:9], sc[:, 9:10], sc[:, 10:11]
    grid = rows_at(packed.grid_s, night)
    t = grid - grid[:, :1]
    e = torch.where(rows_at(packed.constrained, night)[:, None], torch.exp(-t / tau), 0.0)
    cols[:, 0] = dz_da
    torch.mul(p, t_m0[:, None], out=cols[:, 1])
    torch.mul(p, rows_at(packed.t_out_c, night)[:, :1], out=cols[:, 2])
    cols[:, 3] = p
    cols[:, 4:8] = z_f[:, :4]
    # k_Φ's column: the whole heat input at the nodes (model.out_v = k_Φ·(Φ_HC + x))
    torch.div(model.out_v, k_phi, out=cols[:, 8])
    cols[:, 9] = coef * z_f[:, 4] + k_phi * e
    cols[:, 10] = em_w * (coef * z_f[:, 5] + k_phi * e * t / (tau * tau))
    cols[:, 11] = -(coef * z_f[:, 6] + k_phi * rows_at(packed.t_fur_slope, night))
    torch.mul(p, sc[:, 1:2], out=cols[:, 12])
