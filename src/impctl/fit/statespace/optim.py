"""Batched optimisers of independent per-household objectives (torch autograd).

The households share no parameter, so Σ_h f_h(u_h) separates and each household can keep its
own curvature model and step length inside one batched evaluation:

* :func:`bfgs` — quasi-Newton, one dense P×P inverse-Hessian approximation per household
  (P = 12 here, so dense BFGS is cheaper than L-BFGS's two-loop recursion batched), a
  backtracking Armijo line search per household; the workhorse (one gradient per iteration);
* :func:`newton` — Levenberg-damped Newton with the exact Hessian, for polishing the optimum;
* :func:`grad_hess` — the exact Hessian: its block-diagonal structure means one backward pass
  of each gradient column gives column j of every household's Hessian at once (P passes
  whatever the number of households); the Laplace intervals use it at the optimum.

Converged households keep being evaluated (the batch is one tensor) but no longer move.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch


@dataclass
class NewtonResult:
    u: torch.Tensor          # (H, P) the optimum
    f: torch.Tensor          # (H,) objective there
    hessian: torch.Tensor    # (H, P, P) at the optimum (fixed rows/cols: identity)
    n_iter: int
    converged: torch.Tensor  # (H,) bool


def grad_hess(f: Callable[[torch.Tensor], torch.Tensor], u: torch.Tensor
              ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(f (H,), gradient (H, P), Hessian (H, P, P)) of per-row objectives, by autograd."""
    with torch.enable_grad():
        uu = u.detach().clone().requires_grad_(True)
        val = f(uu)
        g = torch.autograd.grad(val.sum(), uu, create_graph=True)[0]
        cols = [torch.autograd.grad(g[:, j].sum(), uu, retain_graph=j + 1 < u.shape[1])[0]
                for j in range(u.shape[1])]
    h = torch.stack(cols, dim=1)
    return val.detach(), g.detach(), 0.5 * (h + h.transpose(1, 2)).detach()


def newton(f: Callable[[torch.Tensor], torch.Tensor], u0: torch.Tensor, free: torch.Tensor,
           max_iter: int = 60, tol: float = 1e-7, lam0: float = 1e-2) -> NewtonResult:
    """Minimise each row's f over the ``free`` (H, P) entries of u, starting at ``u0``."""
    u = u0.detach().clone()
    lam = torch.full((len(u),), lam0, dtype=u.dtype)
    done = torch.zeros(len(u), dtype=torch.bool)
    eye = torch.eye(u.shape[1], dtype=u.dtype)
    fixed = ~free
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007
        fv, g, h = grad_hess(f, u)
        g = g.masked_fill(fixed, 0.0)
        h = h.masked_fill(fixed[:, :, None] | fixed[:, None, :], 0.0) + torch.diag_embed(
            fixed.to(u.dtype))
        moved = torch.zeros(len(u), dtype=torch.bool)
        for _ in range(8):
            trial = ~moved & ~done
            if not trial.any():
                break
            scale = torch.diagonal(h, dim1=1, dim2=2).abs().mean(1).clamp_min(1e-8)
            a = h + (lam * scale)[:, None, None] * eye
            chol, info = torch.linalg.cholesky_ex(a)
            ok = info == 0
            step = torch.zeros_like(u)
            if ok.any():
                step[ok] = -torch.cholesky_solve(g[ok, :, None], chol[ok])[..., 0]
            step = step.masked_fill(fixed, 0.0)
            with torch.no_grad():
                fn = f(u + step)
            better = trial & ok & torch.isfinite(fn) & (fn <= fv + 1e-12)
            u = torch.where(better[:, None], u + step, u)
            decrement = (g * step).sum(1).abs()
            done = done | (better & ((decrement < tol) | ((fv - fn).abs() < tol)))
            moved = moved | better
            lam = torch.where(better, (lam / 5).clamp_min(1e-9), lam)
            lam = torch.where(trial & ~better, lam * 10, lam)
        # a household whose step cannot improve with heavy damping has converged as far
        # as float64 allows
        done = done | (lam > 1e8)
        if done.all():
            break
    fv, _, h = grad_hess(f, u)
    h = h.masked_fill(fixed[:, :, None] | fixed[:, None, :], 0.0) + torch.diag_embed(
        fixed.to(u.dtype))
    return NewtonResult(u, fv, h, it, done)


def positive_inverse(h: torch.Tensor, free: torch.Tensor, floor: float = 1e-6) -> torch.Tensor:
    """Inverse of each household's Hessian over its free parameters with the eigenvalues'
    magnitudes floored (an indefinite or flat direction gets a finite, positive curvature);
    zero on fixed parameters."""
    h = h.masked_fill(~free[:, :, None] | ~free[:, None, :], 0.0)
    w, v = torch.linalg.eigh(0.5 * (h + h.transpose(1, 2)))
    top = w.abs().amax(1, keepdim=True)
    w = w.abs().clamp_min(floor * top + 1e-12)
    inv = (v / w[:, None, :]) @ v.transpose(1, 2)
    return inv.masked_fill(~free[:, :, None] | ~free[:, None, :], 0.0)


def _value_grad(f, u):
    with torch.enable_grad():
        uu = u.detach().clone().requires_grad_(True)
        val = f(uu)
        g = torch.autograd.grad(val.sum(), uu)[0]
    return val.detach(), g


def bfgs(f: Callable[[torch.Tensor], torch.Tensor], u0: torch.Tensor, free: torch.Tensor,
         max_iter: int = 150, tol: float = 1e-6) -> tuple[torch.Tensor, torch.Tensor, int,
                                                           torch.Tensor]:
    """Minimise each row's f over the ``free`` entries; (u, f, iterations, converged)."""
    u = u0.detach().clone()
    fv, g, h = grad_hess(f, u)
    g = g.masked_fill(~free, 0.0)
    hp = u.shape[1]
    # the first curvature model is the exact Hessian, made positive definite
    hinv = positive_inverse(h, free)
    done = torch.zeros(len(u), dtype=torch.bool)
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007
        d = -(hinv @ g[..., None])[..., 0]
        d = d.masked_fill(~free, 0.0)
        slope = (g * d).sum(1)
        # not a descent direction (curvature lost): restart from the scaled gradient
        bad = slope >= 0
        d = torch.where(bad[:, None], -0.1 * g, d)
        hinv = torch.where(bad[:, None, None], torch.eye(hp, dtype=u.dtype) * 0.1, hinv)
        slope = (g * d).sum(1)
        alpha = torch.where(done, 0.0, 1.0).to(u.dtype)
        accepted = done.clone()
        fn = fv.clone()
        for _ in range(12):
            trial = ~accepted
            if not trial.any():
                break
            with torch.no_grad():
                ft = f(u + alpha[:, None] * d)
            ok = trial & torch.isfinite(ft) & (ft <= fv + 1e-4 * alpha * slope)
            fn = torch.where(ok, ft, fn)
            accepted = accepted | ok
            alpha = torch.where(trial & ~ok, alpha * 0.25, alpha)
        alpha = torch.where(accepted & ~done, alpha, 0.0)
        step = alpha[:, None] * d
        u_new = u + step
        fv_new, g_new = _value_grad(f, u_new)
        g_new = g_new.masked_fill(~free, 0.0)
        yv = g_new - g
        sy = (step * yv).sum(1)
        upd = sy > 1e-12
        rho = torch.where(upd, 1.0 / sy.clamp_min(1e-12), 0.0)
        eye = torch.eye(hp, dtype=u.dtype)
        a = eye - rho[:, None, None] * step[:, :, None] * yv[:, None, :]
        new_h = (a @ hinv @ a.transpose(1, 2)
                 + rho[:, None, None] * step[:, :, None] * step[:, None, :])
        hinv = torch.where(upd[:, None, None], new_h, hinv)
        moved = alpha > 0
        # the Newton decrement gᵀH⁻¹g (= −slope of the quasi-Newton step) is small
        conv = moved & (slope.abs() < tol)
        stuck = ~done & ~accepted
        u = torch.where(moved[:, None], u_new, u)
        fv = torch.where(moved, fv_new, fv)
        g = torch.where(moved[:, None], g_new, g)
        done = done | conv | stuck
        if done.all():
            break
    return u, fv, it, done
