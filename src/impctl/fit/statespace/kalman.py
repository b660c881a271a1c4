"""Exact discretisation of the linear SDE and the Kalman-filter likelihood, batched, torch.

Over one sample interval Δt with the inputs held (zero-order hold), dx = (A x + B u) dt + G dw
has the exact solution x_{k+1} = Φ x_k + Γ u_k + w_k, w_k ~ N(0, Q_d), with

* Φ, Γ from one matrix exponential of the augmented matrix [[A, B], [0, 0]]·Δt
  (``torch.linalg.matrix_exp``);
* Q_d = ∫_0^Δt e^{As} G Gᵀ e^{Aᵀs} ds. :func:`van_loan` computes it by Van Loan's (1978)
  exponential of [[−A, G Gᵀ], [0, Aᵀ]]·Δt; :func:`discretise` uses the equivalent closed form
  Q_d = P_∞ − Φ P_∞ Φᵀ with P_∞ the stationary covariance (A P_∞ + P_∞ Aᵀ + G Gᵀ = 0, solved
  as a Kronecker system), exact for a stable A and free of Van Loan's e^{−AΔt}, which
  overflows on a fast air node (C_i/H ≈ seconds, Δt = 5 min); the tests check they agree.

:func:`filter_nll` runs the filter over a batch of series (households × nights) on a common
step grid: update with each observed sample, skip the update where the sample is
missing, predict with that interval's inputs. The covariance update is the standard
P − K S Kᵀ (S scalar); the state is 3-dimensional and float64, where the Joseph form buys nothing
measurable for 3× the work. It returns the negative log-likelihood of each
series in innovations form, Σ ½(ln 2πS_k + e_k²/S_k), and the standardised innovations.
"""

from __future__ import annotations

import math

import torch


def augmented_exp(a: torch.Tensor, b: torch.Tensor, dt_s: torch.Tensor
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """(Φ, Γ) of A (…, n, n), B (…, n, m) over Δt (…) [s]."""
    n, m = a.shape[-1], b.shape[-1]
    top = torch.cat([a, b], dim=-1)
    bottom = torch.zeros(*a.shape[:-2], m, n + m, dtype=a.dtype)
    big = torch.cat([top, bottom], dim=-2) * dt_s[..., None, None]
    e = torch.linalg.matrix_exp(big)
    return e[..., :n, :n], e[..., :n, n:]


def stationary_cov(a: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
    """P with A P + P Aᵀ + Q = 0 (A stable), batched, via (I ⊗ A + A ⊗ I) vec P = −vec Q."""
    n = a.shape[-1]
    eye = torch.eye(n, dtype=a.dtype)
    # row-major vec: vec(A P) = (A ⊗ I) vec P, vec(P Aᵀ) = (I ⊗ A) vec P
    k = (torch.einsum("...ij,kl->...ikjl", a, eye)
         + torch.einsum("ij,...kl->...ikjl", eye, a)).reshape(*a.shape[:-2], n * n, n * n)
    # solve_ex: a trial point of the line search with a singular system gives a non-finite
    # likelihood (rejected) rather than an exception
    p = torch.linalg.solve_ex(k, -q.reshape(*q.shape[:-2], n * n, 1))[0].reshape(q.shape)
    return 0.5 * (p + p.transpose(-1, -2))


def discretise(a: torch.Tensor, b: torch.Tensor, g: torch.Tensor, dt_s: torch.Tensor
               ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(Φ, Γ, Q_d) of dx = (A x + B u) dt + G dw over Δt [s] with u held, batched."""
    phi, gam = augmented_exp(a, b, dt_s)
    gg = g @ g.transpose(-1, -2)
    p_inf = stationary_cov(a, gg)
    qd = p_inf - phi @ p_inf @ phi.transpose(-1, -2)
    return phi, gam, 0.5 * (qd + qd.transpose(-1, -2))


def van_loan(a: torch.Tensor, g: torch.Tensor, dt_s: torch.Tensor) -> torch.Tensor:
    """Q_d by Van Loan's method (for checking :func:`discretise` where A Δt is moderate)."""
    n = a.shape[-1]
    gg = g @ g.transpose(-1, -2)
    top = torch.cat([-a, gg], dim=-1)
    bottom = torch.cat([torch.zeros_like(a), a.transpose(-1, -2)], dim=-1)
    e = torch.linalg.matrix_exp(torch.cat([top, bottom], dim=-2) * dt_s[..., None, None])
    phi = e[..., n:, n:].transpose(-1, -2)
    return phi @ e[..., :n, n:]


def filter_nll(phi: torch.Tensor, gam_u: torch.Tensor, qd: torch.Tensor, x0: torch.Tensor,
               p0: torch.Tensor, y: torch.Tensor, r: torch.Tensor, observed: torch.Tensor,
               channels: tuple[int, ...]) -> tuple[torch.Tensor, torch.Tensor]:
    """Kalman filter of measurements y_j = x[channels[j]] + ε_j over a batch of series.

    Parameters
    ----------
    phi, qd : (…, n, n) transition and process-noise covariance; the batch shape broadcasts
        against the series' (e.g. (H, 1) per household against (H, N) nights)
    gam_u : (…, T, n) the inputs' contribution Γ u_k over each interval [t_k, t_k+1)
    x0, p0 : (…, n), (…, n, n) the state's mean and covariance at the first sample
    y, r, observed : (…, T, m) measurements (any finite value where not observed), their
        variances, and whether each was observed; the m channels are independent and taken
        one after the other (sequential scalar updates)

    Returns
    -------
    nll (…): Σ over observed samples and channels of ½(ln 2πS + e²/S);
    z (…, T, m): standardised innovations e/√S (0 where not observed)
    """
    x, p = x0, p0
    nll = torch.zeros(y.shape[:-2], dtype=y.dtype)
    zs = []
    phi_t = phi.transpose(-1, -2)
    half_log_2pi = 0.5 * math.log(2 * math.pi)
    for k in range(y.shape[-2]):
        zk = []
        for j, c in enumerate(channels):
            obs = observed[..., k, j]
            pc = p[..., :, c]                                             # P Cᵀ
            s = pc[..., c] + r[..., k, j]
            e = y[..., k, j] - x[..., c]
            gain = pc / s[..., None]
            # P − K S Kᵀ, symmetric by construction (K S Kᵀ = P Cᵀ C P / S)
            p = torch.where(obs[..., None, None], p - gain[..., :, None] * pc[..., None, :], p)
            x = torch.where(obs[..., None], x + gain * e[..., None], x)
            nll = nll + torch.where(obs, half_log_2pi + 0.5 * (torch.log(s) + e * e / s), 0.0)
            zk.append(torch.where(obs, e / torch.sqrt(s), 0.0))
        zs.append(torch.stack(zk, -1))
        if k + 1 < y.shape[-2]:
            x = (phi @ x[..., None])[..., 0] + gam_u[..., k, :]
            p = phi @ p @ phi_t + qd
    return nll, torch.stack(zs, -2)
