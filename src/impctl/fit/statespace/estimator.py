"""MAP fit of the stochastic state-space night model, batched over households.

:class:`StateSpaceFit` fits one household (scikit-learn style); :func:`fit_households` fits
many in one batch (one filter call and one Newton iteration for all of them). What is reported:

* ``lumped_``: HLC [W/K], C_m [J/K], τ [h] (the 5R1C's definitions, :func:`.model.lumped`) with
  95 % intervals conditional on the data: Laplace — the inverse Hessian of the negative log
  posterior at the MAP, carried to ln HLC, ln C_m, ln τ by the delta method. The HLC and C_m are
  on the heat meter's scale; the meter's own gain error (a class-``meter_error`` meter,
  real-houses.md §5) is not in these intervals but stated beside them as a type-B relative SD
  (``meter_``) and added in quadrature in ``lumped_with_meter_``.
* ``night_gain_``: Φ_0 [W] and how it was set (declared, or estimated under its prior).
* ``adequacy_``: whiteness and variance tests of the standardised innovations (:mod:`.adequacy`).
* ``parameters_``: the nuisance terms (air/furniture and emitter capacities, τ_e, noise levels).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np
import torch

from ...imp.gain import NIGHT_GAIN_SD_W, NIGHT_GAIN_W
from ...imp.night import NightSamples
from ..nights.data import Estimate
from . import model as ssm
from .adequacy import adequacy
from .data import batch, to_series
from .optim import bfgs, newton, positive_inverse
from .posterior import (
    as_priors,
    class_prior,
    free_mask,
    neg_log_likelihood,
    neg_log_posterior,
)

Z95 = 1.959963984540054
#: The mass node's diffusion [K/√h], fixed: a random walk of the mass temperature would absorb
#: the slow trends that pin C_m and the HLC down.
SIG_M_K_PER_SQRT_H = 0.002
QUANTITIES = ("hlc", "c_m", "tau")


class StateSpaceFit:
    """Continuous–discrete stochastic state-space fit of the night (CTSM-R style).

    Parameters
    ----------
    night_gain_w : float or None
        Declared night gain [W] (known: pinned unless ``night_gain_sd_w`` > 0); None: estimated
        as a constant term under the prior N(:data:`~impctl.imp.gain.NIGHT_GAIN_W`,
        NIGHT_GAIN_SD_W² + (HLC·offset SD)²).
    night_gain_sd_w : float
        SD of a declared gain [W] (0: known exactly).
    sensor_offsets_k : (float, float)
        SD of the indoor and outdoor sensors' offsets [K], behind the estimated gain's prior.
    meter_error : float
        Half-width of the heat meter's gain error (0.05: class 3); stated, type B, SD
        meter_error/√3 on HLC and C_m.
    ach_vent, ach_infl : float
        Air changes of the prior population's 5R1C [1/h] (the class prior's coordinates).
    max_iter : int
        BFGS iterations (then ``polish_iter`` exact Newton steps, whose Hessian the intervals
        use).
    min_night_h : float
        Nights covering less are skipped.
    """

    def __init__(self, *, night_gain_w: float | None = None, night_gain_sd_w: float = 0.0,
                 sensor_offsets_k: tuple[float, float] = (0.5, 1.0), meter_error: float = 0.05,
                 ach_vent: float = 0.0, ach_infl: float = 0.01, max_iter: int = 200,
                 polish_iter: int = 3, min_night_h: float = 1.0):
        self.night_gain_w = night_gain_w
        self.night_gain_sd_w = night_gain_sd_w
        self.sensor_offsets_k = sensor_offsets_k
        self.meter_error = meter_error
        self.ach_vent = ach_vent
        self.ach_infl = ach_infl
        self.max_iter = max_iter
        self.polish_iter = polish_iter
        self.min_night_h = min_night_h

    def fit(self, nights: Sequence[NightSamples], ranges: dict | None = None,
            probabilities: dict | None = None) -> StateSpaceFit:
        """Fit one household's nights (class ``ranges`` or ``probabilities`` as the prior)."""
        vars(self).update(fit_households([(nights, ranges, probabilities)], self)[0])
        return self


def _gain_prior(est: StateSpaceFit) -> tuple[float, float, float]:
    if est.night_gain_w is None:
        return NIGHT_GAIN_W, NIGHT_GAIN_SD_W, float(np.hypot(*est.sensor_offsets_k))
    return float(est.night_gain_w), float(est.night_gain_sd_w), 0.0


def _start(series, mean: np.ndarray, gain_w: float) -> torch.Tensor:
    """A start: HLC from the held nights' Σ Q/Σ ΔT (coheating), the prior's centre elsewhere."""
    normal = [j for j, k in enumerate(series.kinds) if k == "normal"]
    hlc = 150.0
    if normal:
        ok = np.isfinite(series.y[normal])
        dtk = np.where(ok, series.y[normal] - series.t_out[normal], 0.0).sum()
        if dtk > 0:
            hlc = float(np.clip((series.q[normal] * ok).sum() + gain_w * ok.sum(), 1.0, None)
                        / dtk)
    row = ssm.unconstrained(float(np.clip(hlc, 20.0, 3000.0)), 2e7, 0.2 * hlc, 5.0 * hlc,
                            share_i=0.03, share_e=0.03, tau_e_h=0.5, phi0_w=gain_w,
                            sig_k_per_sqrt_h=(0.05, SIG_M_K_PER_SQRT_H, 0.2))
    row[[ssm.IDX["ln_c_m"], ssm.IDX["beta"], ssm.IDX["kappa"]]] = torch.as_tensor(
        mean, dtype=ssm.DTYPE)
    return row


def fit_households(jobs: Sequence[tuple[Sequence[NightSamples], dict | None, dict | None]],
                   est: StateSpaceFit | None = None) -> list[dict]:
    """Fit several households in one batch: ``jobs`` of (nights, ranges, probabilities).

    Returns one dict per household with the attributes :class:`StateSpaceFit` sets
    (``lumped_``, ``lumped_with_meter_``, ``meter_``, ``night_gain_``, ``adequacy_``,
    ``parameters_``, ``skipped_``, ``converged_``, ``n_iter_``, ``fit_time_s_`` — the batch's
    time divided among its households).
    """
    est = est or StateSpaceFit()
    started = time.perf_counter()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        out = _fit(jobs, est)
    finally:
        torch.set_num_threads(threads)
    per = (time.perf_counter() - started) / max(len(jobs), 1)
    for o in out:
        o["fit_time_s_"] = per
    return out


def _fit(jobs, est: StateSpaceFit) -> list[dict]:
    from ...errors import InputError

    series = [to_series(nights, est.min_night_h) for nights, _, _ in jobs]
    for s in series:
        if not s.kinds:
            raise InputError("no usable night: " + "; ".join(f"{i}: {r}" for i, r in s.skipped))
    gain_w, gain_sd, offset_sd = _gain_prior(est)
    rows = []
    for _, ranges, probs in jobs:
        mean, cov = class_prior(ranges, probs, est.ach_vent, est.ach_infl)
        rows.append((mean, cov, gain_w, gain_sd, offset_sd))
    pri = as_priors(rows)
    b = batch(series)
    free = free_mask(pri)
    u0 = torch.stack([_start(s, r[0], gain_w) for s, r in zip(series, rows, strict=True)])

    def objective(u):
        return neg_log_posterior(u, b, pri)

    u, _, n_bfgs, conv = bfgs(objective, u0, free, max_iter=est.max_iter)
    # a few exact Newton steps: the polish and the Hessian the intervals need
    res = newton(objective, u, free, max_iter=est.polish_iter)
    res.n_iter += n_bfgs
    res.converged = res.converged & conv
    cov = positive_inverse(res.hessian, free, floor=1e-9)
    uu = res.u.detach().clone().requires_grad_(True)
    logq = torch.log(ssm.lumped(uu))
    grads = torch.stack([torch.autograd.grad(logq[:, j].sum(), uu, retain_graph=True)[0]
                         for j in range(3)], 1)                                 # (H, 3, P)
    sd_log = torch.sqrt(torch.einsum("hjp,hpq,hjq->hj", grads, cov, grads).clamp_min(0))
    with torch.no_grad():
        _, z = neg_log_likelihood(res.u, b, innovations=True)
        phys = ssm.physical(res.u)
        q = ssm.lumped(res.u)
    meter_sd = est.meter_error / math.sqrt(3.0)
    out = []
    for i, s in enumerate(series):
        n = len(s.kinds)
        obs = b.observed[i, :n, :, 0].numpy()
        lumped, with_meter = {}, {}
        for j, name in enumerate(QUANTITIES):
            v, sd = float(q[i, j]), float(sd_log[i, j])
            lumped[name] = Estimate(v, v * math.exp(-Z95 * sd), v * math.exp(Z95 * sd), True)
            sm = math.hypot(sd, meter_sd) if name != "tau" else sd
            with_meter[name] = Estimate(v, v * math.exp(-Z95 * sm), v * math.exp(Z95 * sm), True)
        pinned = bool(pri.pinned[i])
        phi0 = float(phys.phi0_w[i])
        phi0_sd = float(math.sqrt(max(float(cov[i, ssm.IDX["phi0"], ssm.IDX["phi0"]]), 0.0))
                        * ssm.PHI0_SCALE_W)
        out.append({
            "lumped_": lumped, "lumped_with_meter_": with_meter,
            "sd_log_": {k: float(sd_log[i, j]) for j, k in enumerate(QUANTITIES)},
            "meter_": {"meter_error": est.meter_error, "meter_relative_sd": meter_sd,
                       "applies_to": ["hlc", "c_m"], "kind": "type B (stated, not in lumped_)"},
            "night_gain_": {"value_w": phi0, "sd_w": 0.0 if pinned else phi0_sd,
                            "how": ("declared" if est.night_gain_w is not None else
                                    "estimated (constant term under a physical prior)")},
            "parameters_": {
                "c_air_furniture_j_per_k": float(phys.c_i[i]),
                "c_emitter_j_per_k": float(phys.c_e[i]), "tau_emitter_h":
                float(phys.tau_e_s[i]) / 3600.0, "bypass_share": float(phys.beta[i]),
                "h_air_mass_w_per_k": float(phys.h_im[i]),
                "sigma_k_per_sqrt_h": [float(v) * 60.0 for v in phys.sig_s[i]],
                "sigma_y_k": float(phys.sig_y[i]),
                "sigma_heat_w_per_sqrt_h": float(phys.sig_q[i]) * 60.0,
                "meter_noise_relative": float(phys.r_q[i])},
            "adequacy_": adequacy(z[i, :n, :, 0].numpy(), obs),
            "skipped_": s.skipped, "night_ids_": s.night_ids, "converged_": bool(res.converged[i]),
            "n_iter_": res.n_iter, "neg_log_posterior_": float(res.f[i]), "u_": res.u[i]})
    return out
