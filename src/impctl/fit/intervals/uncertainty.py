"""Uncertainty of the night fit: Laplace intervals and "determined by the data" flags.

Interval method (documented choice): Laplace. At the joint optimum the Gauss–Newton Hessian in
the unconstrained coordinates — per-night initial mass temperatures marginalised by the Schur
complement, residuals scaled by their fitted standard deviation per group (constrained T_air,
normal T_air, normal heat power) — is inverted into a covariance. Each group's σ is first
inflated by sqrt((1 + ρ)/(1 − ρ)), ρ its lag-1 residual autocorrelation, because quantised,
slowly varying temperatures give correlated residuals (an effective-sample-size correction).
The lumped HLC, C_m and τ get 95 % intervals by the delta method in log space (so they stay
positive). Under model error the curvature alone is too confident, so each lumped quantity's
interval is the wider of that Laplace interval and a night-clustered sandwich (robust)
interval, S⁻¹·(Σ_nights g̃·g̃ᵀ)·S⁻¹ with g̃ a night's score: it widens when the nights pull the
parameters apart more than their noise explains; with G nights it takes the Student-t quantile
with G − 1 degrees of freedom. With fewer than 3 nights (t(1) = 12.7) the sandwich is not used
and the fit says so (``interval_basis``): the interval is model-based. A bootstrap over nights
was not chosen: with two constrained nights it cannot resample the τ information meaningfully.
The model error the curvature and the nights cannot show is added by :mod:`.model_error`.

"Determined": the Fisher information of the data alone (no ridge, no bounds), expressed in the
fraction x = (θ − lo)/(hi − lo) of each parameter's search range, regularised by a N(0, 100²)
prior on x only to make the inverse exist. A parameter is
determined when its 95 % half-width from that is below 20 % of its range; structurally
non-identifiable ones (u_walls and walls_area enter only as their product) never are. A lumped
quantity is determined when its 95 % interval spans less than a factor 1.5 either way — and
HLC and C_m never without a night with heat power (temperatures alone fix no absolute scale).
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.special import stdtrit

from ..nights.data import Estimate, lag1_autocorrelation
from ..nights.quality import residual_blocks
from ..ode.parameters import DTYPE, NUISANCE_NAMES, PARAM_NAMES, lumped, to_physical
from ..optim import lm
from ..optim.problem import raw_residuals

Z95 = 1.959964
_X_PRIOR = 1e-4   # precision of the regularising prior on a range fraction (sd 100 ranges)
LUMPED_NAMES = ("hlc", "c_m", "tau")
GROUP_NAMES = ("constrained", "normal_t_air", "normal_power")
#: Fewest used nights for the night-clustered sandwich (module docstring).
MIN_SANDWICH_NIGHTS = 3


def laplace(ctx: lm.Context, sub: lm.Rows, u: torch.Tensor, t_m0: torch.Tensor,
            group_n: torch.Tensor, *, has_power: bool, summary_only: bool = False,
            terms: lm.RowTerms | None = None) -> dict:
    """Intervals and flags at the optimum ``u`` (7,) of the one problem in ``sub``.

    ``terms``: the optimiser's residuals and Jacobian products of these rows at ``u``
    (:class:`.lm.RowTerms`), reused instead of evaluating them again.

    Returns
    -------
    dict with ``inflation`` (largest variance inflation factor) and, unless ``summary_only``,
    ``lumped`` (name → Estimate), ``determined`` (name → bool), ``range_fraction_sd``,
    ``autocorrelation`` (group → ρ), ``cov_u`` (7×7)
    """
    with torch.no_grad():
        raw = (raw_residuals(ctx, sub, u[None], t_m0) if terms is None
               else terms.raw()).numpy()
    mask = ctx.packed.mask[sub.night].numpy()
    groups = group_n[sub.night]
    inflate = torch.ones(3, dtype=DTYPE)
    rhos = {}
    for g, key in enumerate(GROUP_NAMES):
        rho = lag1_autocorrelation(raw, mask & (groups == g).numpy()[:, None])
        if rho is not None:
            rhos[key] = rho
            inflate[g] = (1 + rho) / (1 - rho)
    out = {"inflation": float(inflate.max()), "autocorrelation": rhos}
    if summary_only:
        return out
    grid = ctx.packed.grid_s[sub.night].numpy()
    out["residual_blocks"] = {key: residual_blocks(raw, mask & (groups == g).numpy()[:, None],
                                                   grid)
                              for g, key in enumerate(GROUP_NAMES) if key in rhos}
    scaled = lm.Rows(sub.problem, sub.night, sub.row_type, sub.phi_w, sub.phi_in_w,
                         sub.scale / inflate[groups].sqrt(), sub.box, 1)
    with torch.no_grad():
        ne = (lm._normal_equations(ctx, scaled, u[None], t_m0) if terms is None
              else terms.normal(scaled, u[None], ctx))
        s_mat, _, _ = lm.schur(ne, scaled)
    cov = torch.linalg.pinv(s_mat[0], hermitian=True)   # posterior when ctx.prior is set
    fisher = s_mat[0] - ne.penalty_h[0]   # the data's alone
    box = sub.box[0]
    # Night-clustered sandwich: S⁻¹·(Σ_nights g̃ g̃ᵀ)·S⁻¹ with g̃ each night's score after its
    # θ_m,0 is eliminated. It grows when the nights disagree in a way the model cannot
    # reconcile (model error), which the Laplace curvature cannot see.
    n_rows = len(t_m0)
    score = ne.g_rows - ne.c * (ne.gm / (ne.d + 1e-12))[:, None]
    meat = score.T @ score * (n_rows / max(n_rows - 1, 1))
    cov_sandwich = cov @ meat @ cov

    uu = u.clone().requires_grad_(True)
    q = lumped(to_physical(uu, box), ctx.ach_vent, ctx.ach_infl)
    jac = torch.stack([torch.autograd.grad(q[i], uu, retain_graph=True)[0] for i in range(3)])
    q = q.detach()
    sd_laplace = torch.einsum("ij,jk,ik->i", jac, cov, jac).clamp_min(0).sqrt() / q
    sd_sandwich = torch.einsum("ij,jk,ik->i", jac, cov_sandwich, jac).clamp_min(0).sqrt() / q
    # A cluster-robust covariance from G nights is itself uncertain: its interval takes the
    # Student-t quantile with G − 1 degrees of freedom (the usual small-G correction) instead
    # of the normal one — about 20 % wider with 8 nights.
    sd_sandwich = sd_sandwich * float(stdtrit(max(n_rows - 1, 1), 0.975)) / Z95
    if n_rows < MIN_SANDWICH_NIGHTS:
        # With G = 2 nights the cluster covariance has one degree of freedom, t(1) = 12.7, and
        # gives intervals of hundreds of %: not a statement about the house. Model-based
        # instead (Laplace + the type-B and model-error shares added later), and said so.
        sd_sandwich = torch.zeros_like(sd_sandwich)
        basis = (f"too few nights ({n_rows}) for the night-clustered sandwich (needs "
                 f"{MIN_SANDWICH_NIGHTS}): model-based (Laplace curvature), no check of "
                 "night-to-night disagreement")
    else:
        basis = f"night-clustered sandwich over {n_rows} nights, t({n_rows - 1})"
    sd_log = torch.maximum(sd_laplace, sd_sandwich)
    estimates = {}
    for i, name in enumerate(LUMPED_NAMES):
        determined = bool(Z95 * sd_log[i] < np.log(1.5))
        if name in ("hlc", "c_m") and not has_power:
            determined = False  # temperatures alone fix no absolute scale (identifiability §3)
        estimates[name] = Estimate(float(q[i]), float(q[i] * torch.exp(-Z95 * sd_log[i])),
                                   float(q[i] * torch.exp(Z95 * sd_log[i])), determined)

    sig = torch.sigmoid(u)
    d = torch.diag(1.0 / (sig * (1 - sig)))      # du/dx
    fisher_x = d @ fisher @ d
    # Regularise only so that the inverse exists: a N(0, 100²) prior on each x — a prior on
    # one parameter must not leak into another along a null direction (u_walls ↔ walls_area).
    val, vec = torch.linalg.eigh(0.5 * (fisher_x + fisher_x.T))
    cov_x = vec @ torch.diag(1.0 / (val.clamp_min(0) + _X_PRIOR)) @ vec.T
    sd_x = cov_x.diagonal().clamp_min(0).sqrt()
    sd = dict(zip(PARAM_NAMES, sd_x[:len(PARAM_NAMES)].tolist(), strict=True))
    out.update(interval_basis=basis,
               interval_source={n: ("sandwich" if float(sd_sandwich[i]) > float(sd_laplace[i])
                                    else "laplace") for i, n in enumerate(LUMPED_NAMES)},
               lumped=estimates, determined={n: bool(Z95 * v < 0.2) for n, v in sd.items()},
               range_fraction_sd=sd, cov_u=cov)
    return out


def inflation(ctx: lm.Context, rows: lm.Rows, result: lm.LMResult, best: int,
              group_n: torch.Tensor) -> float:
    """The largest autocorrelation variance-inflation factor of problem ``best``'s residual
    groups, as :func:`laplace` applies it to the data."""
    sel = rows.problem == best
    terms = None if result.terms is None else result.terms.take(sel)
    return float(laplace(ctx, rows.subset(sel), result.u[best], result.t_m0[sel], group_n,
                         has_power=True, summary_only=True, terms=terms)["inflation"])


def offset_allowance(lumped_in: dict, nights, sensor_offsets_k,
                     meter_error: float = 0.0, gain_sd_w: float = 0.0) -> tuple[dict, dict]:
    """Widen the log-space 95 % intervals by the share of uncalibrated sensor offsets and of
    the heat meter's systematic error.

    An offset of the indoor or the outdoor sensor shifts every T_air − T_out alike; the nights
    cannot reveal it, but it moves HLC, τ and C_m by about offset/ΔT. The share
    √(σ_in² + σ_out²)/mean ΔT [K/K] is added in quadrature (a type-B component, GUM).
    A heat meter's gain error (``meter_error``, the half-width of a uniform error, e.g. 0.05
    for a class-3 meter, real-houses.md §5) scales every measured power and so HLC and C_m
    one to one (not τ), equally invisible: meter_error/√3 is added to those two.
    Unmetered night gains (sleepers, base load: 150–400 W, real-houses.md §4) are another
    intercept in Q = HLC·ΔT − G that IMP nights do not separate from the HLC (a likelihood-ratio
    test rarely keeps a gain term): ``gain_sd_w``/(HLC·mean ΔT) is added to all three.

    Returns
    -------
    (lumped with widened intervals, {"sensor_offsets_k", "mean_delta_t_k", "relative_sd",
    "meter_error", "meter_relative_sd"})
    """
    dt = np.concatenate([np.asarray(n.t_air_c) - np.asarray(n.t_out_c) for n in nights])
    mean_dt = float(np.mean(dt)) if len(dt) else float("nan")
    s_in, s_out = (float(v) for v in sensor_offsets_k)
    share = float(np.hypot(s_in, s_out) / mean_dt) if mean_dt > 1.0 else 0.0
    meter = float(meter_error) / np.sqrt(3.0)
    hlc = lumped_in["hlc"].value if "hlc" in lumped_in else float("nan")
    gain = float(gain_sd_w / (hlc * mean_dt)) if gain_sd_w > 0 and mean_dt > 1.0 else 0.0
    out = {}
    for name, e in lumped_in.items():
        lo, hi = np.log(e.value / e.low), np.log(e.high / e.value)
        sd = np.hypot(np.hypot(0.5 * (lo + hi) / Z95, share), gain)
        if name in ("hlc", "c_m"):
            sd = np.hypot(sd, meter)
        out[name] = Estimate(e.value, float(e.value * np.exp(-Z95 * sd)),
                             float(e.value * np.exp(Z95 * sd)), e.determined)
    return out, {"sensor_offsets_k": [s_in, s_out], "mean_delta_t_k": mean_dt,
                 "relative_sd": share, "meter_error": float(meter_error),
                 "meter_relative_sd": meter, "night_gain_sd_w": float(gain_sd_w),
                 "night_gain_relative_sd": gain}


def nuisance_intervals(u: torch.Tensor, box: torch.Tensor, cov_u: torch.Tensor
                       ) -> dict[str, dict | None]:
    """The nuisance terms (:data:`~impctl.fit.ode.parameters.NUISANCE_NAMES`) with 95 %
    intervals (Gauss–Newton covariance through the sigmoid map, clipped to the bounds); None for
    a term switched off."""
    out: dict[str, dict | None] = {}
    if len(u) <= len(PARAM_NAMES):
        return {name: None for name in NUISANCE_NAMES}
    x = to_physical(u, box)
    for j, name in enumerate(NUISANCE_NAMES):
        i = len(PARAM_NAMES) + j
        lo, hi = (float(v) for v in box[i])
        if hi <= lo:
            out[name] = None
            continue
        sig = torch.sigmoid(u[i])
        sd = float((hi - lo) * sig * (1 - sig) * cov_u[i, i].clamp_min(0).sqrt())
        v = float(x[i])
        out[name] = {"value": v, "low": max(lo, v - Z95 * sd), "high": min(hi, v + Z95 * sd),
                     "bounds": [lo, hi]}
    return out
