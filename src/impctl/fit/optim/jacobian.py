"""The Levenberg–Marquardt normal-equation terms of DEMAND rows with an analytic Jacobian.

A DEMAND row's residuals depend on its parameters only through nine numbers per row
(:func:`~impctl.fit.ode.node.demand_scalars`: the rate a, the forcing weights b_air, b_e and
the gain's rate, the output weights c_m, c_air, c_e, the gain's heat and C_fur). The ODE is
linear, so the states are z = θ_m,0·P + b_air·Z_air + b_e·Z_out + gain_rate·Z_1 with P and the
Z's responses that depend on a alone, and each residual column of the Jacobian is a sum of a
few such responses weighted by the derivatives of the nine numbers. Forward differences
(:func:`.lm._row_terms`) build and integrate every row once per parameter (8–12 copies of a
(R, K) problem); here the rows are built and integrated once, the responses to three forcings
come out of one more pass, and only the nine numbers are differentiated — by the same forward
differences in u, on (R, 9) tensors. The residuals are the same arithmetic as
:func:`.problem.residuals`; the Jacobian differs from the forward differences by their own
truncation error (≈ 1e-6 relative).
"""

from __future__ import annotations

import torch

from ..ode.node import build_rows, demand_scalars
from ..ode.parameters import DTYPE, EMC_COLUMN, to_physical
from ..ode.solver import chain_rate_derivative, chain_responses
from .problem import Context, Rows


def demand_row_terms(ctx: Context, rows: Rows, u: torch.Tensor, t_m0: torch.Tensor,
                     h_u: float):
    """:func:`.lm._row_terms` of rows that are all DEMAND rows, or None where this form does
    not apply (rk4, the emitter lag, a rate outside :func:`~..ode.solver.chain_responses`'s
    range): then the caller takes forward differences.

    Parameters
    ----------
    ctx, rows : the problems and their rows (every row ``ROW_DEMAND``)
    u : (P, n) unconstrained parameters
    t_m0 : (R,) initial mass temperatures [°C]
    h_u : the forward-difference step in u of the nine numbers
    """
    packed = ctx.packed
    n = u.shape[1]
    if ctx.solver != "exact" or (packed.emitter_lag and n > EMC_COLUMN):
        return None
    params = to_physical(u, rows.box)[rows.problem]
    model = build_rows(packed, params, t_m0, rows.night, rows.row_type, rows.phi_w,
                       rows.phi_in_w, ctx.ach_vent, ctx.ach_infl, ctx.solver)
    ode = model.ode
    night = rows.night
    ta, ta_s = packed.t_air_in_c[night], packed.t_air_in_slope[night]
    te, te_s = packed.t_out_c[night], packed.t_out_slope[night]
    u0 = torch.stack([ta[:, :-1], te[:, :-1], torch.ones_like(ta[:, :-1])], dim=1)
    u1 = torch.stack([ta_s[:, :-1], te_s[:, :-1], torch.zeros_like(ta_s[:, :-1])], dim=1)
    resp = chain_responses(ode.a_per_s, ode.h_s, u0, u1)
    if resp is None:
        return None
    p, z_f, gamma_f = resp
    z = ode.integrate(model.z0)
    scale = rows.scale[:, None]
    r0 = torch.where(model.mask, model.predict(z) - model.measured, 0.0) * scale
    # the nine numbers at u and at u + h·e_j: their Jacobian (R, 9, n) in u
    eye = torch.eye(n, dtype=DTYPE) * h_u
    u_all = torch.cat([u] + [u + eye[j] for j in range(n)])
    p_all = to_physical(u_all, rows.box.repeat(n + 1, 1, 1))
    offsets = torch.arange(n + 1).repeat_interleave(len(night)) * len(u)
    sc = demand_scalars(packed, p_all[rows.problem.repeat(n + 1) + offsets],
                        night.repeat(n + 1), ctx.ach_vent, ctx.ach_infl).view(n + 1, -1, 9)
    d_sc = ((sc[1:] - sc[0]) / h_u).permute(1, 2, 0)                     # (R, 9, n)
    s0 = sc[0]
    c_m = s0[:, 4:5]
    weights = s0[:, 1:4]                                                 # b_air, b_e, gain_rate
    gamma = (weights[:, :, None] * gamma_f).sum(1)
    dz_da = chain_rate_derivative(z, ode.a_per_s, ode.h_s, ode.u0[:, :-1], ode.u1[:, :-1],
                                  gamma, p)
    # ∂(node output)/∂(each number), (R, 9, K), in demand_scalars' order
    cols = torch.stack([c_m * dz_da, c_m * z_f[:, 0], c_m * z_f[:, 1], c_m * z_f[:, 2], z, ta,
                        te, torch.full_like(z, -1.0), packed.t_fur_slope[night]], dim=1)
    both = model.observe(torch.cat([cols, (c_m * p)[:, None]], dim=1))
    both = torch.where(model.mask[:, None], both, 0.0) * scale[:, None]
    jt = torch.bmm(d_sc.transpose(1, 2), both[:, :9])                    # (R, n, K)
    j_m = both[:, 9]                                                     # (R, K)
    jt_rm = torch.bmm(jt, torch.stack([r0, j_m], dim=2))
    return ((r0 ** 2).sum(1), torch.bmm(jt, jt.transpose(1, 2)), jt_rm[..., 0], jt_rm[..., 1],
            (j_m ** 2).sum(1), (j_m * r0).sum(1), r0)
