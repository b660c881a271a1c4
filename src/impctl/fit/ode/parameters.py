"""The fitted parameters of the night model: the seven of Table IV and the nuisance terms, their
bounds, the sigmoid map between unconstrained and physical values, and what a parameter row
means for the house (its 5R1C network, HLC, C_m, τ). torch, float64."""

from __future__ import annotations

import torch

from ...model.house import conductances
from .names import (  # noqa: F401  (the names and bounds, re-exported beside their tensors)
    CLASSIFIED,
    EMC_COLUMN,
    FUR_COLUMN,
    FURNITURE_TAU_S,
    NUISANCE_BOUNDS,
    NUISANCE_NAMES,
    PARAM_NAMES,
    PARAM_UNITS,
    PHYSICAL_BOUNDS,
    eq63_margin,
)

DTYPE = torch.float64


def bounds_tensor(bounds: dict[str, tuple[float, float]],
                  nuisance: dict[str, tuple[float, float]] | None = None) -> torch.Tensor:
    """Bounds as a (7, 2) tensor in :data:`PARAM_NAMES` order; (10, 2) with ``nuisance``
    bounds appended in :data:`NUISANCE_NAMES` order (``(0, 0)`` switches a term off)."""
    names = [bounds[n] for n in PARAM_NAMES]
    if nuisance is not None:
        names += [nuisance[n] for n in NUISANCE_NAMES]
    return torch.tensor(names, dtype=DTYPE)


def to_physical(u: torch.Tensor, bounds: torch.Tensor) -> torch.Tensor:
    """Unconstrained u (…, 7) → physical parameters lo + (hi − lo)·sigmoid(u).

    ``bounds`` is (7, 2) or one box per row of ``u``, (…, 7, 2).
    """
    return bounds[..., 0] + (bounds[..., 1] - bounds[..., 0]) * torch.sigmoid(u)


def to_unconstrained(x: torch.Tensor, bounds: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`to_physical`, clipped 1e-6 inside the bounds."""
    frac = ((x - bounds[..., 0]) / (bounds[..., 1] - bounds[..., 0])).clamp(1e-6, 1 - 1e-6)
    return torch.logit(frac)


def network(params: torch.Tensor, ach_vent: float, ach_infl: float):
    """The 5R1C :class:`~impctl.model.house.Conductances` of parameter rows (…, 7)."""
    cols = [params[..., i] for i in range(len(PARAM_NAMES))]
    return conductances(*cols, ach_vent, ach_infl)


def lumped(params: torch.Tensor, ach_vent: float, ach_infl: float) -> torch.Tensor:
    """(HLC [W/K], C_m [J/K], τ [h]) of parameter rows (…, 7) → (…, 3), differentiable.

    With the nuisance terms appended, the air/furniture capacity is added to C_m and τ grows
    in proportion (τ = C_m/(H_tr,em + H_tr,3), the house's definition)."""
    net = network(params, ach_vent, ach_infl)
    c_m, tau = net.c_m_j_per_k, net.tau_h
    if params.shape[-1] > FUR_COLUMN:
        c_fur = params[..., FUR_COLUMN] * params[..., 0]
        tau = tau * (c_m + c_fur) / c_m
        c_m = c_m + c_fur
    return torch.stack([net.hlc_w_per_k, c_m, tau], dim=-1)
