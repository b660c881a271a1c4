"""The least-squares problems the optimisers solve: their rows (:class:`Rows`), what they
share (:class:`Context`) and their residuals, one batched integration per call (torch,
float64)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..ode.node import ROW_DEMAND, build_rows
from ..ode.packing import PackedNights, rows_at
from ..ode.parameters import to_physical


@dataclass
class Rows:
    """The rows of a batch of problems (R rows, K grid nodes, P problems)."""

    problem: torch.Tensor      # (R,) long
    night: torch.Tensor        # (R,) long, index into the packed nights
    row_type: torch.Tensor     # (R,) ROW_AIR / ROW_DEMAND
    phi_w: torch.Tensor        # (R, K) heat input of AIR rows at the nodes [W]
    phi_in_w: torch.Tensor     # (R, K) … on the intervals [W]
    scale: torch.Tensor        # (R,) sqrt(weight)/σ of the row's residuals
    box: torch.Tensor          # (P, 7, 2) search box of each problem
    n_problems: int

    def repeat(self, copies: int) -> Rows:
        p = self.n_problems

        def rep(x):  # an expanded (zero-stride) input stays one row in memory
            return (x[:1].expand(copies * len(x), -1) if x.stride(0) == 0 and len(x)
                    else x.repeat(copies, 1))

        return Rows(
            problem=torch.cat([self.problem + c * p for c in range(copies)]),
            night=self.night.repeat(copies), row_type=self.row_type.repeat(copies),
            phi_w=rep(self.phi_w), phi_in_w=rep(self.phi_in_w),
            scale=self.scale.repeat(copies), box=self.box.repeat(copies, 1, 1),
            n_problems=p * copies,
        )

    def copies(self, sel: list[torch.Tensor]) -> Rows:
        """Copy c of the problems holds the rows ``sel[c]`` (indices, or ``slice(None)`` for
        all), as problems c·P…c·P + P − 1 (:meth:`repeat` when every one is all rows)."""
        p = self.n_problems
        n = [len(self.problem[s]) for s in sel]

        def cat(x):  # an expanded (zero-stride) input stays one row in memory
            if x.stride(0) == 0 and len(x):
                return x[:1].expand(sum(n), -1)
            return torch.cat([x[s] for s in sel])

        return Rows(torch.cat([self.problem[s] + c * p for c, s in enumerate(sel)]),
                    cat(self.night[:, None])[:, 0], cat(self.row_type[:, None])[:, 0],
                    cat(self.phi_w), cat(self.phi_in_w), cat(self.scale[:, None])[:, 0],
                    self.box.repeat(len(sel), 1, 1), p * len(sel))

    def at(self, idx: torch.Tensor, phi: bool = True) -> Rows:
        """The rows ``idx`` (problems keep their numbers); ``phi=False`` for rows that do not
        read Φ_HC (DEMAND rows): their heat-input columns become one expanded zero row."""
        def take(x):
            return x[idx] if phi else x.new_zeros(1, x.shape[1]).expand(len(idx), -1)

        return Rows(self.problem[idx], self.night[idx], self.row_type[idx], take(self.phi_w),
                    take(self.phi_in_w), self.scale[idx], self.box, self.n_problems)

    def subset(self, sel: torch.Tensor) -> Rows:
        """The rows ``sel`` (bool, R) of one problem, renumbered as problem 0."""
        problem = self.problem[sel]
        return Rows(torch.zeros_like(problem), self.night[sel], self.row_type[sel],
                    self.phi_w[sel], self.phi_in_w[sel], self.scale[sel],
                    self.box[problem[:1]], 1)


@dataclass
class Context:
    packed: PackedNights
    ach_vent: float
    ach_infl: float
    ridge: float = 1e-2
    solver: str = "exact"   # NightODE method: "exact" or "rk4" (torchdiffeq)
    prior: object = None    # a ..prior.PopulationPrior: its residuals join the ridge (MAP)
    #: (mean, SD) [W] of a Gaussian prior on a fitted night gain (impctl.fit.gain), None: none;
    #: a residual (g − mean)/SD wherever the gain column of a problem's box is free
    gain_prior: tuple[float, float] | None = None


def raw_residuals(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor) -> torch.Tensor:
    """(model − measured) at the nodes, zero off the sample mask, (R, K), in data units."""
    params = rows_at(to_physical(u, rows.box), rows.problem)
    demand = rows.row_type == ROW_DEMAND
    if bool(demand.all()) or not bool(demand.any()):
        return _raw(ctx, rows, params, t_m0, slice(None))
    # Each row type on its own rows: build_rows then skips the other type's arithmetic.
    idx = [demand.nonzero()[:, 0], (~demand).nonzero()[:, 0]]
    out = torch.cat([_raw(ctx, rows, params, t_m0, i) for i in idx])
    return out[torch.argsort(torch.cat(idx))]


def _raw(ctx: Context, rows: Rows, params: torch.Tensor, t_m0: torch.Tensor, i) -> torch.Tensor:
    model = build_rows(ctx.packed, params[i], t_m0[i], rows.night[i], rows.row_type[i],
                       rows.phi_w[i], rows.phi_in_w[i], ctx.ach_vent, ctx.ach_infl, ctx.solver)
    return torch.where(model.mask, model.predict() - model.measured, 0.0)


def residuals(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor) -> torch.Tensor:
    """Scaled residuals (R, K): raw/σ·sqrt(weight)."""
    return raw_residuals(ctx, rows, u, t_m0) * rows.scale[:, None]


def sum_rows(values: torch.Tensor, rows: Rows) -> torch.Tensor:
    out = torch.zeros((rows.n_problems,) + values.shape[1:], dtype=values.dtype)
    return out.index_add_(0, rows.problem, values)
