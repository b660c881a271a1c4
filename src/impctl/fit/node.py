"""The night-time 5R1C dynamics as a torch module (the paper's eq. 5 and 6), batched over nights.

One *row* is one night under one parameter set. All rows share one time grid (the union of the
nights' sample times, measured from each night's fit start), so a whole fit — every start, every
night, both modes, the finite-difference copies of the Jacobian — is one ``torchdiffeq.odeint``
call with ``rk4`` stepping exactly on that grid. Each step must see the inputs of its own
interval only (the last rk4 stage sits at the step's end, where a plain lookup would already
return the next interval): torchdiffeq announces every step through ``callback_step``, and the
module looks the interval up there, once per step. That is the "left-closed lookup per step" of
identifiability.md §7; torchdiffeq's ``perturb=True`` would do the same with four ``nextafter``
calls per step and costs ~20 % of the run time. float64 throughout, direct backprop through the
steps when gradients are wanted (no adjoint).

Row types
---------
``AIR`` (T_air is the model output, paper eq. 5/6)
    Within a sample interval Φ_HC is constant and T_out linear, and eq. 5 (Φ_HC = the night's
    heat power) or eq. 6 (Φ_HC = 0) reads dT_air/dt = A·T_air + B·T_out + C·dT_out/dt + D·Φ_HC;
    A…D come from :func:`impctl.model.continuous.air_derivative` (affine, so evaluating it at unit
    inputs gives the coefficients). A measured Φ_HC *series* steps between samples, and the
    massless air node then jumps by k_Φ·ΔΦ (k_Φ = ∂T_air/∂Φ_HC at fixed θ_m). The state is
    therefore z = T_air − k_Φ·Φ_HC, the air temperature without the instantaneous share of the
    heat input; it is continuous, obeys dz/dt = A·z + B·T_out + C·dT_out/dt + (A·k_Φ + D)·Φ_HC,
    and for a constant Φ_HC it is eq. 5/6 shifted by a constant. Output T_air = z + k_Φ·Φ_HC.
``DEMAND`` (Φ_HC is the model output, T_air the input)
    The same 5R1C equations with the held-setpoint night read the other way round
    (identifiability.md §11.3): the state is θ_m, driven by the measured T_air and T_out; Φ_HC
    follows from the air-node balance. The default for normal nights in the fit (the measured
    power is then an output with its noise, not an input) and the heat-demand validation.

Inputs are piecewise linear in T_out and T_air (samples are instants) and piecewise constant in
Φ_HC: the value at a sample time holds until the next sample (meter convention: ``q_hc`` at a
row is the mean power over the interval that starts there). :func:`pack_nights` also handles
the "interval" convention (every value a mean over the interval that starts at its stamp).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torchdiffeq import odeint

from ..imp.night import NightSamples
from ..model.continuous import air_derivative, air_temperature
from ..model.house import H_MS, PARAMETER_UNITS, TABLE_IV, am_factor, conductances

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

ROW_AIR = 0
ROW_DEMAND = 1


def bounds_tensor(bounds: dict[str, tuple[float, float]]) -> torch.Tensor:
    """Bounds as a (7, 2) tensor in :data:`PARAM_NAMES` order."""
    return torch.tensor([bounds[n] for n in PARAM_NAMES], dtype=DTYPE)


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
    """(HLC [W/K], C_m [J/K], τ [h]) of parameter rows (…, 7) → (…, 3), differentiable."""
    net = network(params, ach_vent, ach_infl)
    return torch.stack([net.hlc_w_per_k, net.c_m_j_per_k, net.tau_h], dim=-1)


def eq63_margin(bounds: dict[str, tuple[float, float]]) -> float:
    """min over the box of H_tr,ms − H_tr,op [W/K]; eq. 63 needs it > 0 everywhere."""
    a_lo = bounds["floor_area"][0]
    h_ms = H_MS * float(am_factor(bounds["c_f"][0])) * a_lo
    return h_ms - bounds["u_walls"][1] * bounds["walls_area"][1]


TIMESTAMPS = ("instant", "interval")


@dataclass
class PackedNights:
    """Nights on one shared grid (tensors float64; N nights, K grid nodes).

    Attributes
    ----------
    night_ids, kinds : per night
    timestamps : "instant" or "interval" (see :func:`pack_nights`)
    grid_s : (K,) node times [s] from each night's fit start
    t_out_c, t_air_c : (N, K) values at the nodes [°C] (held after a night's last sample)
    t_out_slope, t_air_slope : (N, K) slope on the interval that starts at node k [K/s]
    t_air_in_c, t_air_in_slope : (N, K) the smoothed T_air that drives DEMAND rows, and its slope
    q_w : (N, K) heat power belonging to node k [W] (the value a sample reports)
    q_in_w : (N, K) mean heat power over the interval that starts at node k [W]
    q_mean_w : (N,) mean power over the night [W] (time-weighted)
    mask : (N, K) bool, node k is one of the night's samples
    next_node : (N, K) long, index of the night's next sample (itself for the last one)
    last : (N, K) bool, node k is the night's last sample
    """

    night_ids: list[str]
    kinds: list[str]
    timestamps: str
    grid_s: torch.Tensor
    t_out_c: torch.Tensor
    t_out_slope: torch.Tensor
    t_air_c: torch.Tensor
    t_air_slope: torch.Tensor
    t_air_in_c: torch.Tensor
    t_air_in_slope: torch.Tensor
    q_w: torch.Tensor
    q_in_w: torch.Tensor
    q_mean_w: torch.Tensor
    mask: torch.Tensor
    next_node: torch.Tensor
    last: torch.Tensor

    @property
    def n_nights(self) -> int:
        return len(self.night_ids)

    @property
    def constrained(self) -> torch.Tensor:
        return torch.tensor([k == "constrained" for k in self.kinds])


def _slopes(t: np.ndarray, y: np.ndarray, t_end: float) -> np.ndarray:
    out = np.zeros_like(y)
    out[:-1] = np.diff(y) / np.diff(t)
    out[t >= t_end] = 0.0
    return out


def smooth(t: np.ndarray, y: np.ndarray, width_s: float) -> np.ndarray:
    """Centred moving average of samples within ±width/2 [s] (window shrinks at the ends)."""
    if width_s <= 0 or len(t) < 3:
        return y.copy()
    lo = np.searchsorted(t, t - width_s / 2, side="left")
    hi = np.searchsorted(t, t + width_s / 2, side="right")
    c = np.concatenate([[0.0], np.cumsum(y)])
    return (c[hi] - c[lo]) / (hi - lo)


def pack_nights(nights: Sequence[NightSamples], offsets_s: Sequence[float], *,
                timestamps: str = "instant", smooth_air_s: float = 0.0) -> PackedNights:
    """Put prepared nights (already cut to their fit windows) on one grid.

    Parameters
    ----------
    nights : nights whose samples all belong to the fit (see ``fit.prepare_nights``)
    offsets_s : per night, the time [s] in its ``time_s`` that becomes grid time 0
    timestamps : {"instant", "interval"}
        "instant": temperatures are readings at the stamp, ``q_hc`` the mean power until the
        next stamp. "interval": every value is the mean over the interval that starts at the
        stamp (hourly logs, the virtual IMP): temperatures then belong to the interval's middle,
        so the nodes move there, and the power on [middle_k, middle_k+1) is (q_k + q_k+1)/2.
    smooth_air_s : width of the moving average applied to the T_air that drives DEMAND rows [s]
    """
    if timestamps not in TIMESTAMPS:
        raise ValueError(f"timestamps must be one of {TIMESTAMPS}")
    rel = []
    for night, off in zip(nights, offsets_s, strict=True):
        t = np.asarray(night.time_s, float) - off
        if timestamps == "interval":
            span = np.diff(t)
            t = t + 0.5 * np.append(span, span[-1])
        rel.append(np.round(t, 3))
    grid = np.unique(np.concatenate(rel))
    n, k = len(nights), len(grid)
    te, te_s, ta, ta_s, tai, tai_s, q, q_in = (np.zeros((n, k)) for _ in range(8))
    mask = np.zeros((n, k), dtype=bool)
    next_node = np.tile(np.arange(k), (n, 1))
    last = np.zeros((n, k), dtype=bool)
    q_mean = np.zeros(n)
    for i, (night, t) in enumerate(zip(nights, rel, strict=True)):
        t_air = np.asarray(night.t_air_c, float)
        for dst, dst_s, y in ((te, te_s, night.t_out_c), (ta, ta_s, t_air),
                              (tai, tai_s, smooth(t, t_air, smooth_air_s))):
            dst[i] = np.interp(grid, t, np.asarray(y, float))
            dst_s[i] = _slopes(grid, dst[i], t[-1])
        qi = np.asarray(night.q_hc_w, float)
        idx = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, len(t) - 1)
        q[i] = qi[idx]
        q_in[i] = q[i]
        if timestamps == "interval":
            q_in[i] = 0.5 * (qi[idx] + qi[np.minimum(idx + 1, len(t) - 1)])
        nodes = np.searchsorted(grid, t)
        mask[i, nodes] = True
        next_node[i, nodes] = np.append(nodes[1:], nodes[-1])
        last[i, nodes[-1]] = True
        span = np.diff(t)
        q_mean[i] = float(np.sum(qi[:-1] * span) / np.sum(span))

    def tt(a):
        return torch.as_tensor(a, dtype=DTYPE)

    return PackedNights(
        night_ids=[x.night_id for x in nights], kinds=[x.kind for x in nights],
        timestamps=timestamps, grid_s=tt(grid),
        t_out_c=tt(te), t_out_slope=tt(te_s), t_air_c=tt(ta), t_air_slope=tt(ta_s),
        t_air_in_c=tt(tai), t_air_in_slope=tt(tai_s), q_w=tt(q), q_in_w=tt(q_in),
        q_mean_w=tt(q_mean), mask=torch.as_tensor(mask), next_node=torch.as_tensor(next_node),
        last=torch.as_tensor(last),
    )


class NightODE(torch.nn.Module):
    """dz/dt = A·z + u(t) for R independent rows, u linear within each grid interval.

    The interval of ``t`` is looked up once per solver step: torchdiffeq calls
    :meth:`callback_step` with the step's start t0 (a grid node), and with ``rk4`` on the grid
    all four stages of that step belong to [t0, t1] — the last one at t1 evaluated with the
    interval's own (left-closed) inputs. Outside ``odeint`` (no step announced) :meth:`forward`
    falls back to a ``searchsorted`` lookup, right-continuous like the data.

    Parameters
    ----------
    grid_s : (K,) node times [s]
    a_per_s : (R,) the rate A [1/s]
    u0 : (R, K) forcing at the start of each interval [K/s]
    u1 : (R, K) slope of the forcing within the interval [K/s²]
    """

    def __init__(self, grid_s: torch.Tensor, a_per_s: torch.Tensor, u0: torch.Tensor,
                 u1: torch.Tensor):
        super().__init__()
        self.grid_s = grid_s
        self.a_per_s = a_per_s
        # Node-major copies, so one interval's forcing is a contiguous row.
        self.u0_k = u0.t().contiguous()
        self.u1_k = u1.t().contiguous()
        self._last = len(grid_s) - 2
        self._k: int | None = None

    def _interval(self, t: torch.Tensor) -> int:
        k = int(torch.searchsorted(self.grid_s, t.reshape(1), right=True)) - 1
        return min(max(k, 0), self._last)

    def callback_step(self, t0: torch.Tensor, y0: torch.Tensor, dt: torch.Tensor) -> None:
        self._k = self._interval(t0)

    def forward(self, t: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        k = self._interval(t) if self._k is None else self._k
        return self.a_per_s * z + self.u0_k[k] + self.u1_k[k] * (t - self.grid_s[k])

    def integrate(self, z0: torch.Tensor) -> torch.Tensor:
        """States at the grid nodes, shape (R, K)."""
        if len(self.grid_s) == 1:
            return z0[:, None]
        try:
            z = odeint(self, z0, self.grid_s, method="rk4")
        finally:
            self._k = None
        return z.transpose(0, 1)


@dataclass
class RowModel:
    """Everything needed to integrate rows and compare them with data (R rows, K nodes)."""

    ode: NightODE
    z0: torch.Tensor          # (R,)
    out_c: torch.Tensor       # (R,) output = out_c·z + out_v
    out_v: torch.Tensor       # (R, K)
    measured: torch.Tensor    # (R, K) T_air [°C] for AIR rows, Φ_HC [W] for DEMAND rows
    mask: torch.Tensor        # (R, K) bool
    mean_next: torch.Tensor | None = None  # (R, K) next node: compare (y_k + y_next)/2

    def predict(self) -> torch.Tensor:
        """Model output at the nodes, (R, K) (interval means where ``mean_next`` says so)."""
        y = self.out_c[:, None] * self.ode.integrate(self.z0) + self.out_v
        if self.mean_next is None:
            return y
        return 0.5 * (y + torch.gather(y, 1, self.mean_next))


def _unit(net, which: int):
    """Coefficient of input ``which`` (T_air, T_e, dT_e/dt, Φ) in eq. 5/6: affine → unit input."""
    args = [0.0, 0.0, 0.0, 0.0]
    args[which] = 1.0
    return air_derivative(*args, net)


def build_rows(
    packed: PackedNights,
    params: torch.Tensor,
    t_m0_c: torch.Tensor,
    night_index: torch.Tensor,
    row_type: torch.Tensor,
    phi_w: torch.Tensor,
    phi_in_w: torch.Tensor,
    ach_vent: float,
    ach_infl: float,
) -> RowModel:
    """Rows for parameter sets ``params`` (R, 7) with initial mass temperatures ``t_m0_c`` (R,).

    Parameters
    ----------
    packed : the nights
    params : (R, 7) physical parameters per row (:data:`PARAM_NAMES` order)
    t_m0_c : (R,) mass temperature at grid time 0 [°C]
    night_index : (R,) which packed night each row models
    row_type : (R,) :data:`ROW_AIR` or :data:`ROW_DEMAND`
    phi_w, phi_in_w : (R, K) heat input Φ_HC of AIR rows [W] at the nodes (for the output) and
        on the intervals (for the dynamics): zeros for eq. 6, the night mean for eq. 5 with the
        mean power, or the measured series (``q_w`` and ``q_in_w``); ignored for DEMAND rows
    ach_vent, ach_infl : fixed air changes [1/h]
    """
    net = network(params, ach_vent, ach_infl)
    te = packed.t_out_c[night_index]
    te_s = packed.t_out_slope[night_index]
    ta = packed.t_air_in_c[night_index]
    ta_s = packed.t_air_in_slope[night_index]
    grid = packed.grid_s
    demand = (row_type == ROW_DEMAND)

    # AIR rows: eq. 5/6 in the shifted state z = T_air − k_Φ·Φ_HC.
    a_air = _unit(net, 0)
    b, c, d = _unit(net, 1), _unit(net, 2), _unit(net, 3)
    k_phi = air_temperature(0.0, 0.0, 1.0, net)
    u0_air = b[:, None] * te + c[:, None] * te_s + (a_air * k_phi + d)[:, None] * phi_in_w
    u1_air = b[:, None] * te_s
    z0_air = air_temperature(t_m0_c, te[:, 0], 0.0, net)

    # DEMAND rows: θ_m driven by measured T_air, T_out; surface node balance without Φ_st.
    s = net.h_tr_is + net.h_tr_w + net.h_tr_ms
    a_dem = (net.h_tr_ms * (net.h_tr_ms / s - 1.0) - net.h_tr_em) / net.c_m_j_per_k
    b_air = net.h_tr_ms * net.h_tr_is / s / net.c_m_j_per_k
    b_e = (net.h_tr_ms * net.h_tr_w / s + net.h_tr_em) / net.c_m_j_per_k
    u0_dem = b_air[:, None] * ta + b_e[:, None] * te
    u1_dem = b_air[:, None] * ta_s + b_e[:, None] * te_s
    c_air = net.h_tr_is + net.h_ve - net.h_tr_is ** 2 / s
    c_e = -net.h_ve - net.h_tr_is * net.h_tr_w / s
    c_m = -net.h_tr_is * net.h_tr_ms / s

    dm = demand[:, None]
    mask = packed.mask[night_index]
    mean_next = None
    if packed.timestamps == "instant":
        # A power sample is the mean until the next sample: compare the model's interval mean
        # (trapezoid), and drop the last sample, whose interval lies outside the night.
        nxt = packed.next_node[night_index]
        mean_next = torch.where(dm, nxt, torch.arange(len(grid)).expand_as(nxt))
        mask = mask & ~(dm & packed.last[night_index])
    ode = NightODE(
        grid,
        torch.where(demand, a_dem, a_air),
        torch.where(dm, u0_dem, u0_air),
        torch.where(dm, u1_dem, u1_air),
    )
    return RowModel(
        ode=ode,
        z0=torch.where(demand, t_m0_c, z0_air),
        out_c=torch.where(demand, c_m, torch.ones_like(c_m)),
        out_v=torch.where(dm, c_air[:, None] * ta + c_e[:, None] * te, k_phi[:, None] * phi_w),
        measured=torch.where(dm, packed.q_w[night_index], packed.t_air_c[night_index]),
        mask=mask,
        mean_next=mean_next,
    )
