"""The fitted parameters of the night model: the seven of Table IV and the nuisance terms, their
bounds, the sigmoid map between unconstrained and physical values, and what a parameter row
means for the house (its 5R1C network, HLC, C_m, τ). torch, float64."""

from __future__ import annotations

import torch

from ...model.house import H_MS, TABLE_IV, am_factor, conductances
from ...model.house_limits import PARAMETER_UNITS

DTYPE = torch.float64

#: The seven fitted parameters (the paper's Table IV), in this order everywhere.
PARAM_NAMES = TABLE_IV

PARAM_UNITS = {name: PARAMETER_UNITS[name] for name in TABLE_IV}

#: Parameters bounded by the classifiers' ranges; the others by :data:`PHYSICAL_BOUNDS`.
CLASSIFIED = ("floor_area", "c_f", "u_walls")

#: Search bounds. The three classified ones are the union of the paper's Table III classes and
#: apply only when no class range is given; the rest are wide physical limits for dwellings.
PHYSICAL_BOUNDS: dict[str, tuple[float, float]] = {
    "floor_area": (60.0, 300.0),
    "wall_height": (2.0, 6.0),
    "walls_area": (20.0, 600.0),
    "windows_area": (2.0, 150.0),
    "c_f": (0.8, 3.7),
    "u_walls": (0.2, 2.0),
    "u_windows": (0.5, 5.0),
}

#: Nuisance terms of the night model a real house needs (real-houses.md §2, §4, §7), fitted
#: after the seven (a row of parameters then has 10 entries): a constant internal gain over
#: the campaign (sleepers, base load) [W], split over the air, surface and mass nodes as ISO
#: 13790 C.1–C.3 splits Φ_int (:func:`impctl.fit.ode.node._gain_split`), and on constrained
#: nights the heat the emitter (and the air/furniture) still releases after the fit start,
#: emitter_w·exp(−t/emitter_tau_h) [W, h]. Bounded, reported, never the product's numbers.
#: The last, furniture_j_per_m2k, is heat capacity at the air node (air and furniture, per m²
#: of floor, real-houses.md §1: 3 + 10–31 kJ/(m²K)), charged through the furniture's coupling
#: time constant :data:`FURNITURE_TAU_S`: its heat flow C_fur·dT_fur/dt is computed from the
#: measured T_air (the data, not the state, drive it: a second state is not needed for a node
#: that follows T_air within an hour). It is part of the house's capacity: the reported C_m and
#: τ include it (:func:`lumped`).
#: The last, emitter_share, is the share of C_m that sits in the emitter (screed, radiator
#: water and metal, buffer) between the heat meter and the air node, with the time constant
#: emitter_tau_h (``NightFit(emitter_lag=True)``, :func:`build_rows`); the mass node keeps
#: the rest, so C_m and τ stay the house's whole (as the classes and the plant define them).
NUISANCE_NAMES = ("night_gain_w", "emitter_w", "emitter_tau_h", "furniture_j_per_m2k",
                  "emitter_share")

#: When no gain is fitted (``night_gain`` off, or not kept by the likelihood-ratio test) the
#: night_gain_w column is pinned to an assumed value (``NightFit(night_gain_w=…)``, default
#: :data:`impctl.imp.gain.NIGHT_GAIN_W`) by the box (g, g), not to 0 W.
NUISANCE_BOUNDS: dict[str, tuple[float, float]] = {
    # sleepers and base load, ≈ 150–400 W (real-houses.md §4). Not wide enough to absorb the
    # intercept sensor offsets make (HLC·(offset_in − offset_out)): with that much freedom the
    # gain trades against the emitter's release and the HLC (README "Accuracy")
    "night_gain_w": (0.0, 500.0),
    "emitter_w": (0.0, 4000.0),
    "emitter_tau_h": (0.2, 8.0),
    "furniture_j_per_m2k": (0.0, 40000.0),
    # screed 130–250 kJ/(m²K) of heated floor (real-houses.md §2): up to about half of C_m
    "emitter_share": (0.0, 0.6),
}

#: Furniture–air time constant [s]: 1/0.00022 s ≈ 76 min (real-houses.md §1, the Japanese
#: residential code's G_fur = 0.00022·C_fur).
FURNITURE_TAU_S = 1.0 / 0.00022

FUR_COLUMN = len(PARAM_NAMES) + 3   # column of furniture_j_per_m2k in a parameter row

EMC_COLUMN = len(PARAM_NAMES) + 4   # column of emitter_share


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


def eq63_margin(bounds: dict[str, tuple[float, float]]) -> float:
    """min over the box of H_tr,ms − H_tr,op [W/K]; eq. 63 needs it > 0 everywhere."""
    a_lo = bounds["floor_area"][0]
    h_ms = H_MS * float(am_factor(bounds["c_f"][0])) * a_lo
    return h_ms - bounds["u_walls"][1] * bounds["walls_area"][1]
