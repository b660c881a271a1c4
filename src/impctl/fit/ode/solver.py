"""The integrator of the night dynamics (:class:`NightODE`; see :mod:`.node` for the dynamics).

Two methods give each sample interval's response, chained by the exact linear recurrence:
``"exact"`` (the default) the closed-form solution of the scalar linear ODE with its inputs
linear within the interval (the exact discretisation, one ``exp`` per interval), and ``"rk4"``
``torchdiffeq.odeint`` over every interval at once in normalised time. They agree to rk4's
error (≈ 1e-7 of the state per interval; ``tests/test_node.py``); the exact one costs a fixed
handful of tensor operations, where rk4 needs 4 right-hand sides per sub-step and more sub-steps
when any row of the batch has a fast mode (``bench/fleet.py --profile``).
"""

from __future__ import annotations

import numpy as np
import torch

#: Rates [1/s] below which :func:`exact_chain` takes the first-order form (τ ≈ 30 years).
_SLOW_RATE = 1e-9
#: Integration methods of :class:`NightODE`.
METHODS = ("exact", "rk4")


class NightODE(torch.nn.Module):
    """dz/dt = A·z + u(t) for R independent rows, u linear within each grid interval.

    How it is integrated (why it is fast): the dynamics are linear, so over grid interval k
    (length h_k) the solution is z_k+1 = Φ_k·z_k + Γ_k — Φ_k the response to z_k = 1 without
    forcing, Γ_k the response to the interval's forcing from z_k = 0. ``torchdiffeq.odeint``
    integrates those two responses for *every interval of every row at once*, in the interval's
    normalised time s ∈ [0, 1] (dz/ds = h_k·f), with ``rk4`` in :attr:`n_sub` equal steps: one
    batched call whose Python cost is a handful of solver steps, not one step per sample. The
    interval's inputs are its own by construction (no lookup, no stage at the next interval's
    edge). The intervals are then chained by the exact linear recurrence (a cumulative product
    in log space; a plain loop when the products would underflow). With ``n_sub = 1`` this is
    step for step the same arithmetic as ``rk4`` on the sample grid; :meth:`integrate` picks
    ``n_sub`` so that |A|·h_k/n_sub ≤ 0.1 (fast air or emitter modes get sub-steps).

    ``method="exact"`` (the default) skips the integrator: with A constant and the forcing
    linear on the interval, Φ_k = exp(A·h_k) and Γ_k = h_k·φ₁(A·h_k)·u0_k + h_k²·φ₂(A·h_k)·u1_k
    (φ₁(x) = (eˣ − 1)/x, φ₂(x) = (eˣ − 1 − x)/x²), which is what rk4 converges to.

    :meth:`forward` is dz/dt at a time on the grid (right-continuous lookup, like the data): the
    ODE as written, used by checks.

    Parameters
    ----------
    grid_s : (K,) node times [s]
    a_per_s : (R,) the rate A [1/s]
    u0 : (R, K) forcing at the start of each interval [K/s]
    u1 : (R, K) slope of the forcing within the interval [K/s²]
    method : {"exact", "rk4"}
        the closed-form interval solution, or ``torchdiffeq.odeint`` rk4
    """

    #: largest |A|·h per rk4 sub-step (local error ≈ x⁵/120 ≈ 1e-7 of the state)
    MAX_RATE_STEP = 0.1

    def __init__(self, grid_s: torch.Tensor, a_per_s: torch.Tensor, u0: torch.Tensor,
                 u1: torch.Tensor, method: str = "exact"):
        super().__init__()
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}")
        grid_s = grid_s if grid_s.dim() == 2 else grid_s[None]   # (K,) for all rows, or (R, K)
        # plain attributes, not through nn.Module.__setattr__: its Parameter checks cost more
        # than the rest of a fleet batch's row building (one ODE per optimiser evaluation)
        self.__dict__.update(method=method, grid_s=grid_s, a_per_s=a_per_s, u0=u0, u1=u1,
                             h_s=torch.diff(grid_s, dim=1), n_sub=1)

    def forward(self, t: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        grid = self.grid_s.expand(len(z), -1).contiguous()
        k = torch.searchsorted(grid, t.reshape(1, 1).expand(len(z), 1).contiguous(),
                               right=True) - 1
        k = k.clamp(0, grid.shape[1] - 2)
        t0 = grid.gather(1, k)[:, 0]
        return (self.a_per_s * z + self.u0.gather(1, k)[:, 0]
                + self.u1.gather(1, k)[:, 0] * (t - t0))

    def _interval_rhs(self, s: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """d/ds of (homogeneous, forced) responses, (R, K−1, 2), in normalised time s."""
        forcing = torch.addcmul(self._hu0, self._hu1, s.expand(1, 1))
        return torch.addcmul(self._forced * forcing[..., None], self._ha, y)

    def integrate(self, z0: torch.Tensor) -> torch.Tensor:
        """States at the grid nodes, shape (R, K)."""
        if self.grid_s.shape[1] == 1:
            return z0[:, None]
        h = self.h_s
        if self.method == "exact":
            return exact_chain(z0, self.a_per_s, h, self.u0[:, :-1], self.u1[:, :-1])
        rate = float((self.a_per_s.detach().abs() * h.amax(1)).max().clamp_min(0))
        self.n_sub = max(1, min(256, int(np.ceil(rate / self.MAX_RATE_STEP))))
        # dz/ds = h·(A·z + u0 + u1·h·s) on each interval, for z(0) = 1 unforced and z(0) = 0
        self._ha = (self.a_per_s[:, None] * h)[..., None]
        self._hu0 = self.u0[:, :-1] * h
        self._hu1 = self.u1[:, :-1] * h * h
        self._forced = torch.tensor([0.0, 1.0], dtype=z0.dtype)
        y0 = torch.zeros(z0.shape[0], h.shape[1], 2, dtype=z0.dtype)
        y0[..., 0] = 1.0
        s = torch.tensor([0.0, 1.0], dtype=z0.dtype)
        # imported here: torchdiffeq pulls in scipy.integrate (~1 s per fleet worker start),
        # and only "rk4" needs it
        from torchdiffeq import odeint

        try:
            y1 = odeint(self._interval_rhs, y0, s, method="rk4",
                        options={"step_size": 1.0 / self.n_sub})[-1]
        finally:
            del self._ha, self._hu0, self._hu1
        return chain(z0, y1[..., 0], y1[..., 1])


def exact_chain(z0: torch.Tensor, a_per_s: torch.Tensor, h_s: torch.Tensor, u0: torch.Tensor,
                u1: torch.Tensor) -> torch.Tensor:
    """Exact solution of dz/dt = A·z + u0_k + u1_k·(t − t_k) at the nodes, (R, K).

    ``a_per_s`` (R,) [1/s], ``h_s`` (R, K−1) interval lengths [s] (zero for padding),
    ``u0`` [K/s] and ``u1`` [K/s²] (R, K−1) the forcing on each interval.

    Γ = h·φ₁(x)·u0 + h²·φ₂(x)·u1 with x = A·h is evaluated as
    (expm1(x)·(u0 + u1/A) − h·u1)/A: A is one number per row, so no elementwise case split
    near x = 0 is needed. Its rounding, ≈ 1e-16·h·|u1|/|A|·(1/h) per interval, is negligible
    for |A| ≥ 1e-9/s (τ up to decades); rows with a slower (or zero) rate take the Taylor form
    h·u0·(1 + x/2) + h²·u1·(1/2 + x/6), whose relative error x²/6 is then below 1e-12.
    """
    slow = a_per_s.abs() < _SLOW_RATE
    a = torch.where(slow, torch.full_like(a_per_s, -_SLOW_RATE), a_per_s)
    inv_a = (1.0 / a)[:, None]
    x = a_per_s[:, None] * h_s
    gamma = inv_a * (torch.expm1(x) * torch.addcmul(u0, inv_a, u1) - h_s * u1)
    if bool(slow.any()):
        taylor = h_s * (u0 * (1.0 + 0.5 * x) + h_s * u1 * (0.5 + x / 6.0))
        gamma = torch.where(slow[:, None], taylor, gamma)
    return chain(z0, None, gamma, log_phi=x)


def chain(z0: torch.Tensor, phi: torch.Tensor | None, gamma: torch.Tensor,
          log_phi: torch.Tensor | None = None) -> torch.Tensor:
    """z_0 = z0, z_k+1 = Φ_k·z_k + Γ_k for rows (R,) and intervals (R, K−1) → (R, K).

    Closed form z_k = P_k·(z0 + Σ_j<k Γ_j/P_j+1), P_k = Π_j<k Φ_j from a cumulative sum of
    log Φ (Φ > 0: exp(A·h), or a power of rk4's stability polynomial, which is positive;
    ``log_phi`` when it is known, then ``phi`` may be None); a loop when P would leave the
    float64 range.
    """
    log_p = torch.cumsum(torch.log(phi) if log_phi is None else log_phi, dim=1)
    if float(log_p.detach().min()) > -600.0:
        p = torch.exp(log_p)
        s = torch.cumsum(gamma / p, dim=1)
        rest = p * (z0[:, None] + s)
        return torch.cat([z0[:, None], rest], dim=1)
    if phi is None:
        phi = torch.exp(log_phi)
    out = [z0]
    z = z0
    for k in range(phi.shape[1]):
        z = torch.addcmul(gamma[:, k], phi[:, k], z)
        out.append(z)
    return torch.stack(out, dim=1)


def chain_responses(a_per_s: torch.Tensor, h_s: torch.Tensor, u0: torch.Tensor,
                    u1: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None:
    """Responses of :func:`exact_chain` to F forcings at once, for the analytic Jacobian.

    ``a_per_s`` (R,) [1/s], ``h_s`` (R, K−1) [s], ``u0`` [K/s] and ``u1`` [K/s²] (R, F, K−1).
    Returns (P, Z, Γ): P (R, K) the response to z0 = 1 without forcing (exp(A·t)), Z (R, F, K)
    the response to each forcing from z0 = 0, Γ (R, F, K−1) the forcings' interval terms —
    one exp and one expm1 for all F. None where :func:`exact_chain` would leave its main
    branch (a rate below 1e-9/s, or P below e^−600): the caller then differentiates by
    forward differences.
    """
    if bool((a_per_s.abs() < _SLOW_RATE).any()):
        return None
    x = a_per_s[:, None] * h_s
    log_p = torch.cumsum(x, dim=1)
    if log_p.numel() and float(log_p.min()) <= -600.0:
        return None
    p = torch.exp(log_p)
    inv_a = (1.0 / a_per_s)[:, None, None]
    gamma = inv_a * (torch.expm1(x)[:, None] * torch.addcmul(u0, inv_a, u1)
                     - h_s[:, None] * u1)
    z = p[:, None] * torch.cumsum(gamma / p[:, None], dim=2)
    ones = torch.ones_like(a_per_s)[:, None]
    return (torch.cat([ones, p], dim=1),
            torch.cat([torch.zeros_like(z[..., :1]), z], dim=2), gamma)


def chain_rate_derivative(z: torch.Tensor, a_per_s: torch.Tensor, h_s: torch.Tensor,
                          u0: torch.Tensor, u1: torch.Tensor, gamma: torch.Tensor,
                          p: torch.Tensor) -> torch.Tensor:
    """∂z/∂A (R, K) [K·s] of the exact chain's states ``z`` (R, K) at fixed z0 and forcing.

    z_k+1 = P_k·(z0 + Σ_j≤k Γ_j/P_j) with P_k = exp(A·T_k), T_k the time of node k+1, so
    ∂z_k+1/∂A = T_k·z_k+1 + P_k·Σ_j≤k (∂Γ_j/∂A − T_j·Γ_j)/P_j, and from
    Γ = (e^x − 1)·(u0 + u1/A)/A − h·u1/A (x = A·h):
    ∂Γ/∂A = (h·e^x·(u0 + u1/A) − (e^x − 1)·u1/A² − Γ)/A. ``gamma`` (R, K−1) the total
    forcing's Γ, ``p`` (R, K) from :func:`chain_responses`; ``u0``, ``u1`` (R, K−1) the
    total forcing.
    """
    a = a_per_s[:, None]
    x = a * h_s
    t = torch.cumsum(h_s, dim=1)
    pk = p[:, 1:]
    d_gamma = (h_s * torch.exp(x) * (u0 + u1 / a) - torch.expm1(x) * u1 / (a * a) - gamma) / a
    rest = t * z[:, 1:] + pk * torch.cumsum((d_gamma - t * gamma) / pk, dim=1)
    return torch.cat([torch.zeros_like(z[:, :1]), rest], dim=1)
