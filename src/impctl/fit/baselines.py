"""Simple baselines the Neural-ODE fit must beat (identifiability.md §8), numpy/scipy only.

* :func:`coheating_hlc` — HLC = mean Q_HC / mean (T_air − T_out) over the normal nights.
* :func:`loglinear_tau` — τ from ln(T_air − mean T_out) falling linearly in time on the
  constrained nights (common slope, one intercept per night; the night's *mean* T_out, because a
  per-sample difference is badly wrong when T_out drifts, §11.4).
* C_m ≈ τ·HLC from the two.
* :func:`least_squares_fit` — the same 5R1C night model and residuals as the default
  :class:`~impctl.fit.NightFit` (eq. 6 T_air on constrained nights, heat power given the
  held T_air on normal nights), integrated by the *exact* discretisation of the linear ODE for
  piecewise-linear inputs and fitted by ``scipy.optimize.least_squares`` (bounded, trust-region,
  one start at the centre of the box).

All take nights already cut to their fit windows (``fit.prepare_nights``) with "instant" stamps.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.optimize import least_squares

from ..imp.night import NightSamples
from ..model import TABLE_IV, conductances
from ..model.continuous import air_temperature, mass_from_air

PARAM_NAMES = TABLE_IV


def _span_weights(t: np.ndarray) -> np.ndarray:
    w = np.zeros_like(t)
    w[:-1] = np.diff(t)
    return w


def coheating_hlc(nights: Sequence[NightSamples]) -> float:
    """Σ Q_HC·Δt / Σ (T_air − T_out)·Δt over the normal nights [W/K]; NaN without any."""
    num = den = 0.0
    for n in nights:
        if n.kind != "normal":
            continue
        w = _span_weights(np.asarray(n.time_s, float))
        num += float(np.sum(w * n.q_hc_w))
        den += float(np.sum(w * (n.t_air_c - n.t_out_c)))
    return num / den if den > 0 else float("nan")


def loglinear_tau(nights: Sequence[NightSamples]) -> float:
    """τ [h] = −1/slope of ln(T_air − mean T_out) on time, pooled over constrained nights."""
    sxy = sxx = 0.0
    for n in nights:
        if n.kind != "constrained" or len(n.time_s) < 3:
            continue
        dt = np.asarray(n.t_air_c, float) - float(np.mean(n.t_out_c))
        if np.any(dt <= 0):
            continue
        t_h = np.asarray(n.time_s, float) / 3600.0
        y = np.log(dt)
        sxy += float(np.sum((t_h - t_h.mean()) * (y - y.mean())))
        sxx += float(np.sum((t_h - t_h.mean()) ** 2))
    slope = sxy / sxx if sxx > 0 else float("nan")
    return -1.0 / slope if slope < 0 else float("nan")


def _phi1(x: np.ndarray) -> np.ndarray:
    """(e^x − 1)/x, stable near 0."""
    small = np.abs(x) < 1e-8
    return np.where(small, 1.0 + x / 2, np.expm1(x) / np.where(small, 1.0, x))


def _phi2(x: np.ndarray) -> np.ndarray:
    """(e^x − 1 − x)/x², stable near 0."""
    small = np.abs(x) < 1e-4
    xs = np.where(small, 1.0, x)
    return np.where(small, 0.5 + x / 6 + x * x / 24, (np.expm1(xs) - xs) / (xs * xs))


def exact_linear(a: float, x0: float, t: np.ndarray, u0: np.ndarray, u1: np.ndarray
                 ) -> np.ndarray:
    """Exact solution of dx/dt = a·x + u0_k + u1_k·(t − t_k) on each [t_k, t_k+1), at the t_k."""
    h = np.diff(t)
    e = np.exp(a * h)
    g0 = h * _phi1(a * h)
    g1 = h * h * _phi2(a * h)
    x = np.empty(len(t))
    x[0] = x0
    for k in range(len(h)):
        x[k + 1] = e[k] * x[k] + g0[k] * u0[k] + g1[k] * u1[k]
    return x


def _night_model(p: np.ndarray, t_m0: float, night: NightSamples, ach: tuple[float, float]):
    """Model output at the samples: T_air (constrained, eq. 6) or Φ_HC (normal, T_air given)."""
    net = conductances(*p, *ach)
    t = np.asarray(night.time_s, float) - float(night.time_s[0])
    te = np.asarray(night.t_out_c, float)
    ta = np.asarray(night.t_air_c, float)
    te_s = np.append(np.diff(te) / np.diff(t), 0.0)
    ta_s = np.append(np.diff(ta) / np.diff(t), 0.0)
    s = net.h_tr_is + net.h_tr_w + net.h_tr_ms
    if night.kind == "constrained":
        # State z = T_air with Φ_HC = 0: dz/dt = A·z + B·T_e + C·dT_e/dt, A…C from eq. 6,
        # written out from dθ_m/dt and the algebraic T_air(θ_m, T_e) of the 5R1C network.
        alpha = air_temperature(1.0, 0.0, 0.0, net)
        beta = air_temperature(0.0, 1.0, 0.0, net)
        h_sum = net.h_tr_em + net.h_tr_3
        a = -h_sum / net.c_m_j_per_k
        # θ_m' = a·(θ_m − T_e) → z' = α·θ_m' + β·T_e' = a·z − a·(α + β)·T_e + β·T_e'
        u0 = -a * (alpha + beta) * te + beta * te_s
        u1 = -a * (alpha + beta) * te_s
        z0 = air_temperature(t_m0, te[0], 0.0, net)
        return exact_linear(a, z0, t, u0, u1)
    a = (net.h_tr_ms * (net.h_tr_ms / s - 1.0) - net.h_tr_em) / net.c_m_j_per_k
    b_air = net.h_tr_ms * net.h_tr_is / s / net.c_m_j_per_k
    b_e = (net.h_tr_ms * net.h_tr_w / s + net.h_tr_em) / net.c_m_j_per_k
    t_m = exact_linear(a, t_m0, t, b_air * ta + b_e * te, b_air * ta_s + b_e * te_s)
    phi = ((net.h_tr_is + net.h_ve - net.h_tr_is ** 2 / s) * ta
           + (-net.h_ve - net.h_tr_is * net.h_tr_w / s) * te - net.h_tr_is * net.h_tr_ms / s * t_m)
    # A power sample is the mean until the next one: trapezoid of the model, last one dropped.
    return 0.5 * (phi[:-1] + phi[1:])


def least_squares_fit(
    nights: Sequence[NightSamples],
    bounds: dict[str, tuple[float, float]],
    ach: tuple[float, float] = (0.0, 0.01),
    sigma_t_k: float = 0.05,
    sigma_p_rel: float = 0.05,
) -> dict[str, float]:
    """Bounded least squares of the night model, exact discretisation (module docstring).

    Two passes: nominal σ (``sigma_t_k``, ``sigma_p_rel``·mean normal power), then σ per kind
    re-estimated from the residuals.

    Returns
    -------
    dict with the seven parameters, ``hlc`` [W/K], ``c_m`` [J/K], ``tau`` [h], ``cost``, ``nfev``
    """
    lo = np.array([bounds[n][0] for n in PARAM_NAMES])
    hi = np.array([bounds[n][1] for n in PARAM_NAMES])
    p0 = 0.5 * (lo + hi)
    net0 = conductances(*p0, *ach)
    normal_q = [float(np.mean(n.q_hc_w)) for n in nights if n.kind == "normal"]
    sig = {"constrained": sigma_t_k,
           "normal": sigma_p_rel * (np.mean(normal_q) if normal_q else 1000.0)}
    m0 = [float(mass_from_air(n.t_air_c[0], n.t_out_c[0],
                              float(np.mean(n.q_hc_w)) if n.kind == "normal" else 0.0, net0))
          for n in nights]

    def raw(x):
        p, t_m0 = x[:7], x[7:]
        out = []
        for night, m in zip(nights, t_m0, strict=True):
            y = _night_model(p, m, night, ach)
            meas = night.t_air_c if night.kind == "constrained" else night.q_hc_w[:-1]
            out.append((night.kind, y - meas))
        return out

    def resid(x):
        return np.concatenate([r / sig[k] for k, r in raw(x)])

    x0 = np.concatenate([p0, m0])
    lb = np.concatenate([lo, np.full(len(nights), -50.0)])
    ub = np.concatenate([hi, np.full(len(nights), 80.0)])
    scale = np.concatenate([hi - lo, np.full(len(nights), 1.0)])
    nfev = 0
    res = None
    for _ in range(2):
        res = least_squares(resid, x0, bounds=(lb, ub), x_scale=scale, method="trf")
        nfev += res.nfev
        for kind in sig:
            r = [v for k, v in raw(res.x) if k == kind]
            if r:
                sig[kind] = max(1e-3, float(np.sqrt(np.mean(np.concatenate(r) ** 2))))
        x0 = res.x
    p = res.x[:7]
    net = conductances(*p, *ach)
    out = dict(zip(PARAM_NAMES, p.tolist(), strict=True))
    out.update(hlc=float(net.hlc_w_per_k), c_m=float(net.c_m_j_per_k), tau=float(net.tau_h),
               cost=float(res.cost), nfev=nfev)
    return out
