"""The night-time 5R1C dynamics as a torch module (the paper's eq. 5 and 6), batched over nights.

One *row* is one night under one parameter set; each row keeps its night's own sample times
(nights padded to the longest one). A whole fit — every start, every night, both modes, the
finite-difference copies of the Jacobian — is integrated by one ``torchdiffeq.odeint`` call with
``rk4``: the dynamics are linear, so every sample interval of every row is integrated at once in
its own normalised time (its response to the state it starts from and to its own inputs), and the
intervals are chained by the exact linear recurrence (:class:`NightODE`). The Python cost is a
few solver steps per call instead of one step per sample (21 s → about 2 s for the demo's
export), and each interval sees only its own inputs by construction (the "left-closed lookup per
step" of identifiability.md §7). float64 throughout, direct backprop through the solver when
gradients are wanted (no adjoint).

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

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from ...imp.night import NightSamples
from ...model.continuous import air_derivative, air_temperature
from ...model.house import H_MS, PARAMETER_UNITS, TABLE_IV, am_factor, conductances
from .solver import (
    NightODE,  # the integrator (re-exported: tests and readers find it here)
    exact_chain,
)

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

#: Nuisance terms of the night model a real house needs (real-houses.md §2, §4, §7), fitted
#: after the seven (a row of parameters then has 10 entries): a constant internal gain over
#: the campaign (sleepers, base load) [W], split over the air, surface and mass nodes as ISO
#: 13790 C.1–C.3 splits Φ_int (:func:`_gain_split`), and on constrained
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
#: :data:`impctl.night_gain.NIGHT_GAIN_W`) by the box (g, g), not to 0 W.
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
_FUR = len(PARAM_NAMES) + 3   # column of furniture_j_per_m2k in a parameter row
_EMC = len(PARAM_NAMES) + 4   # column of emitter_share


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
    if params.shape[-1] > _FUR:
        c_fur = params[..., _FUR] * params[..., 0]
        tau = tau * (c_m + c_fur) / c_m
        c_m = c_m + c_fur
    return torch.stack([net.hlc_w_per_k, c_m, tau], dim=-1)


def eq63_margin(bounds: dict[str, tuple[float, float]]) -> float:
    """min over the box of H_tr,ms − H_tr,op [W/K]; eq. 63 needs it > 0 everywhere."""
    a_lo = bounds["floor_area"][0]
    h_ms = H_MS * float(am_factor(bounds["c_f"][0])) * a_lo
    return h_ms - bounds["u_walls"][1] * bounds["walls_area"][1]


TIMESTAMPS = ("instant", "interval")


@dataclass
class PackedNights:
    """Nights side by side (tensors float64; N nights, K nodes = the longest night's samples).

    Attributes
    ----------
    night_ids, kinds : per night
    timestamps : "instant" or "interval" (see :func:`pack_nights`)
    grid_s : (N, K) node times [s] from each night's fit start: the night's own samples,
        the last one repeated after its end
    t_out_c, t_air_c : (N, K) values at the nodes [°C] (held after a night's last sample)
    t_out_slope, t_air_slope : (N, K) slope on the interval that starts at node k [K/s]
    t_air_in_c, t_air_in_slope : (N, K) the smoothed T_air that drives DEMAND rows, and its slope
    q_w : (N, K) heat power belonging to node k [W] (the value a sample reports)
    q_in_w : (N, K) mean heat power over the interval that starts at node k [W]
    q_mean_w : (N,) mean power over the night [W] (time-weighted)
    t_fur_slope : (N, K) dT_fur/dt [K/s] of a node that follows the (30-min smoothed) measured
        T_air with the time constant :data:`FURNITURE_TAU_S`
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
    t_fur_slope: torch.Tensor
    mask: torch.Tensor
    next_node: torch.Tensor
    last: torch.Tensor
    power_ok: torch.Tensor | None = None  # (N, K) bool: the power sample can be compared
    #: the meter measures the heat into an emitter node that holds ``emitter_share`` of C_m
    #: (``NightFit(emitter_lag=True)``, :func:`build_rows`)
    emitter_lag: bool = False

    @property
    def n_nights(self) -> int:
        return len(self.night_ids)

    @property
    def constrained(self) -> torch.Tensor:
        return torch.tensor([k == "constrained" for k in self.kinds])

    def demand_mask(self) -> torch.Tensor:
        """(N, K) bool: the nodes a DEMAND row compares — :attr:`mask` without the last
        sample ("instant" power is the mean until the next sample) and without the power
        samples that cannot be compared. Computed once per packing: every optimiser
        iteration's rows read it."""
        cached = self.__dict__.get("_demand_mask")
        if cached is None:
            cached = self.mask
            if self.timestamps == "instant":
                cached = cached & ~self.last
            if self.power_ok is not None:
                cached = cached & self.power_ok
            self.__dict__["_demand_mask"] = cached
        return cached


def smooth(t: np.ndarray, y: np.ndarray, width_s: float) -> np.ndarray:
    """Centred moving average of samples within ±width/2 [s] (window shrinks at the ends)."""
    if width_s <= 0 or len(t) < 3:
        return y.copy()
    lo = np.searchsorted(t, t - width_s / 2, side="left")
    hi = np.searchsorted(t, t + width_s / 2, side="right")
    c = np.concatenate([[0.0], np.cumsum(y)])
    return (c[hi] - c[lo]) / (hi - lo)


def furniture_rate(t: np.ndarray, t_air: np.ndarray, tau_s: float, steady: bool) -> np.ndarray:
    """dT_fur/dt [K/s] at the samples of a node following ``t_air`` (piecewise linear) with
    time constant ``tau_s`` (exact per interval). It starts in step with T_air (``steady``:
    at rest, a held night from its day) or lagging a steady slope (a cooling night)."""
    t_air = smooth(t, np.asarray(t_air, float), 1800.0)
    h = np.diff(t)
    slope = np.diff(t_air) / np.where(h > 0, h, 1.0)
    e = np.zeros(len(t))           # T_fur − T_air
    if not steady and len(slope):
        e[0] = -tau_s * slope[0]
    alpha = np.exp(-h / tau_s)
    for k in range(len(h)):
        e[k + 1] = e[k] * alpha[k] - slope[k] * tau_s * (1.0 - alpha[k])
    return -e / tau_s


def pack_nights(nights: Sequence[NightSamples], offsets_s: Sequence[float], *,
                timestamps: str = "instant", smooth_air_s: float = 0.0,
                smooth_out_s: float = 0.0,
                power_ok: Sequence[np.ndarray] | None = None) -> PackedNights:
    """Put prepared nights (already cut to their fit windows) side by side, each on its own
    sample times (padded to the longest night by repeating its last sample: zero-length
    intervals that change nothing).

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
    smooth_out_s : width of the moving average applied to T_out [s]: the outdoor temperature
        is an input of every row, and its sensor noise (0.2–0.5 K per reading, real-houses.md
        §5) would otherwise enter as errors in the variables and bias the fit
    power_ok : per night, bool per sample: False where the measured power is not the space
        heating the model describes (a DHW recharge, a defrost and the recovery after them);
        those samples still drive the model (T_air), their power is not compared
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
    n, k = len(nights), max(len(t) for t in rel)
    grid, te, te_s, ta, ta_s, tai, tai_s, q, q_in, fur = (np.zeros((n, k)) for _ in range(10))
    mask = np.zeros((n, k), dtype=bool)
    next_node = np.tile(np.arange(k), (n, 1))
    last = np.zeros((n, k), dtype=bool)
    q_mean = np.zeros(n)

    def padded(y, m):
        y = np.asarray(y, float)
        return np.concatenate([y, np.full(k - m, y[-1])])

    for i, (night, t) in enumerate(zip(nights, rel, strict=True)):
        m = len(t)
        grid[i] = padded(t, m)
        t_air = np.asarray(night.t_air_c, float)
        t_out = smooth(t, np.asarray(night.t_out_c, float), smooth_out_s)
        for dst, dst_s, y in ((te, te_s, t_out), (ta, ta_s, t_air),
                              (tai, tai_s, smooth(t, t_air, smooth_air_s))):
            dst[i] = padded(y, m)
            dst_s[i, :m - 1] = np.diff(np.asarray(y, float)) / np.diff(t)
        fur[i, :m] = furniture_rate(t, t_air, FURNITURE_TAU_S, night.kind != "constrained")
        qi = np.asarray(night.q_hc_w, float)
        q[i] = padded(qi, m)
        q_in[i] = q[i]
        if timestamps == "interval":
            q_in[i, :m - 1] = 0.5 * (qi[:-1] + qi[1:])
        mask[i, :m] = True
        next_node[i, :m - 1] += 1
        last[i, m - 1] = True
        span = np.diff(t)
        q_mean[i] = float(np.sum(qi[:-1] * span) / np.sum(span))

    def tt(a):
        return torch.as_tensor(a, dtype=DTYPE)

    return PackedNights(
        night_ids=[x.night_id for x in nights], kinds=[x.kind for x in nights],
        timestamps=timestamps, grid_s=tt(grid),
        t_out_c=tt(te), t_out_slope=tt(te_s), t_air_c=tt(ta), t_air_slope=tt(ta_s),
        t_air_in_c=tt(tai), t_air_in_slope=tt(tai_s), q_w=tt(q), q_in_w=tt(q_in),
        q_mean_w=tt(q_mean), t_fur_slope=tt(fur), mask=torch.as_tensor(mask),
        next_node=torch.as_tensor(next_node), last=torch.as_tensor(last),
        power_ok=None if power_ok is None else torch.as_tensor(np.stack([
            np.concatenate([np.asarray(p, bool), np.ones(k - len(p), bool)]) for p in power_ok])),
    )


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
    lag_next: torch.Tensor | None = None   # (R, K) next node of the emitter-lag difference
    lag_rate: torch.Tensor | None = None   # (R, K) τ_e/h_k [-]: 0 where there is no lag
    lag_extra: torch.Tensor | None = None  # (R, K) C_e·dT_air/dt [W] on the interval

    def predict(self) -> torch.Tensor:
        """Model output at the nodes, (R, K) (interval means where ``mean_next`` says so;
        plus τ_e·ΔP/h on DEMAND rows with the emitter lag)."""
        y = self.out_c[:, None] * self.ode.integrate(self.z0) + self.out_v
        out = y if self.mean_next is None else 0.5 * (y + torch.gather(y, 1, self.mean_next))
        if self.lag_rate is not None:
            out = out + self.lag_rate * (torch.gather(y, 1, self.lag_next) - y)
        if self.lag_extra is not None:
            out = out + self.lag_extra
        return out


def _unit(net, which: int):
    """Coefficient of input ``which`` (T_air, T_e, dT_e/dt, Φ) in eq. 5/6: affine → unit input."""
    args = [0.0, 0.0, 0.0, 0.0]
    args[which] = 1.0
    return air_derivative(*args, net)


def _gain_split(net) -> tuple:
    """Per W of a constant internal gain G, split as ISO 13790 C.1–C.3 does (Φ_ia = G/2 at the
    air node; of G/2, A_m/A_t at the mass and 1 − A_m/A_t − H_tr,w/(9.1·A_t) at the surface;
    the rest leaves through the windows): the realistic plant and :func:`impctl.model.simulate`
    put sleepers and base load there, and about half of a mass/surface gain leaves through
    H_tr,em without lowering the heat the air needs. θ_sup = θ_e (no heat recovery at night).

    Returns (AIR rows: dθ_air/dt at fixed θ_air, θ_e [K/s]; θ_air at fixed θ_m [K];
    DEMAND rows: dθ_m/dt at fixed θ_air, θ_e [K/s]; the heat the air node no longer needs at
    fixed θ_air, θ_m [W]) — each per W of G."""
    am = net.a_m_m2 / net.a_t_m2
    phi_ia = 0.5
    phi_m = 0.5 * am
    phi_st = 0.5 * (1.0 - am - net.h_tr_w / (H_MS * net.a_t_m2))
    s = net.h_tr_is + net.h_tr_w + net.h_tr_ms
    den = net.h_tr_is + net.h_ve - net.h_tr_is ** 2 / s
    alpha = net.h_tr_is * net.h_tr_ms / s / den        # ∂θ_air/∂θ_m
    # AIR rows: θ_air, θ_e held at 0 → θ_s, θ_m from the air and surface balances
    t_s = -phi_ia / net.h_tr_is
    t_m = (s * t_s - phi_st) / net.h_tr_ms
    dm = (net.h_tr_ms * (t_s - t_m) - net.h_tr_em * t_m + phi_m) / net.c_m_j_per_k
    air_rate = alpha * dm
    air_level = (net.h_tr_is / s * phi_st + phi_ia) / den
    dem_rate = (net.h_tr_ms / s * phi_st + phi_m) / net.c_m_j_per_k
    dem_heat = phi_ia + net.h_tr_is / s * phi_st
    return air_rate, air_level, dem_rate, dem_heat


def _mixed_mask(packed: PackedNights, night_index: torch.Tensor, dm: torch.Tensor, k: int
                ) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Compared nodes and interval-mean partners of rows of both types, (R, K) each."""
    mask = packed.mask[night_index]
    mean_next = None
    if packed.timestamps == "instant":
        # A power sample is the mean until the next sample: compare the model's interval mean
        # (trapezoid), and drop the last sample, whose interval lies outside the night.
        nxt = packed.next_node[night_index]
        mean_next = torch.where(dm, nxt, torch.arange(k).expand_as(nxt))
        mask = mask & ~(dm & packed.last[night_index])
    if packed.power_ok is not None:
        mask = mask & ~(dm & ~packed.power_ok[night_index])
    return mask, mean_next


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
    method: str = "exact",
) -> RowModel:
    """Rows for parameter sets ``params`` (R, 7) with initial mass temperatures ``t_m0_c`` (R,).

    Parameters
    ----------
    packed : the nights
    params : (R, 7) physical parameters per row (:data:`PARAM_NAMES` order), or (R, 10) with
        the :data:`NUISANCE_NAMES` terms appended
    t_m0_c : (R,) mass temperature at grid time 0 [°C]
    night_index : (R,) which packed night each row models
    row_type : (R,) :data:`ROW_AIR` or :data:`ROW_DEMAND`
    phi_w, phi_in_w : (R, K) heat input Φ_HC of AIR rows [W] at the nodes (for the output) and
        on the intervals (for the dynamics): zeros for eq. 6, the night mean for eq. 5 with the
        mean power, or the measured series (``q_w`` and ``q_in_w``); ignored for DEMAND rows
    ach_vent, ach_infl : fixed air changes [1/h]
    method : the integration method of :class:`NightODE` ("exact" or "rk4")
    """
    net = network(params, ach_vent, ach_infl)
    cap_e = None   # the emitter's capacity [J/K]
    if packed.emitter_lag and params.shape[-1] > _EMC:
        # the emitter's share of C_m is not at the mass node (as the plant splits it)
        cap_e = params[:, _EMC] * net.c_m_j_per_k
        net = dataclasses.replace(net, c_m_j_per_k=net.c_m_j_per_k - cap_e)
    te = packed.t_out_c[night_index]
    te_s = packed.t_out_slope[night_index]
    ta = packed.t_air_in_c[night_index]
    ta_s = packed.t_air_in_slope[night_index]
    grid = packed.grid_s[night_index]
    demand = (row_type == ROW_DEMAND)
    dm = demand[:, None]
    # Rows of one type skip the other type's arithmetic (most of a fit's rows are DEMAND rows,
    # and lm evaluates each type on its own rows).
    any_air, any_dem = not bool(demand.all()), bool(demand.any())

    def pick(dem, air):
        return air if not any_dem else dem if not any_air else torch.where(
            dm if dem.dim() == 2 or air.dim() == 2 else demand, dem, air)

    # AIR rows: eq. 5/6 in the shifted state z = T_air − k_Φ·Φ_HC.
    a_air = _unit(net, 0)
    b, c, d = _unit(net, 1), _unit(net, 2), _unit(net, 3)
    k_phi = air_temperature(0.0, 0.0, 1.0, net)
    u0_air = u1_air = z0_air = None
    if any_air:
        u0_air = b[:, None] * te + c[:, None] * te_s + (a_air * k_phi + d)[:, None] * phi_in_w
        u1_air = b[:, None] * te_s
        z0_air = air_temperature(t_m0_c, te[:, 0], 0.0, net)
    gain = torch.zeros_like(a_air)
    q_fur = torch.zeros_like(te)
    if params.shape[-1] > _FUR:
        # heat the air/furniture capacity takes from the air node [W]
        q_fur = (params[:, _FUR] * params[:, 0])[:, None] * packed.t_fur_slope[night_index]
    if params.shape[-1] > len(PARAM_NAMES):
        gain = params[:, len(PARAM_NAMES)]
    # the constant gain enters at the air, surface and mass nodes as ISO 13790 splits it
    g_air_rate, g_air_level, g_dem_rate, g_dem_heat = _gain_split(net)
    if params.shape[-1] > len(PARAM_NAMES) and any_air:
        u0_air = u0_air + (g_air_rate * gain)[:, None]
        z0_air = z0_air + g_air_level * gain
        # Extra heat to the air node, x(t) = the emitter's release on constrained nights
        # (− the furniture's uptake), linear between the nodes: it enters like Φ_HC (z stays
        # continuous).
        em_w, em_tau_s = (params[:, len(PARAM_NAMES) + j] for j in (1, 2))
        em_tau_s = (em_tau_s * 3600.0).clamp_min(60.0)  # a term switched off has τ = 0
        cons = packed.constrained[night_index][:, None]
        x = torch.where(cons, em_w[:, None] * torch.exp(
            -(grid - grid[:, :1]) / em_tau_s[:, None]), 0.0) - q_fur
        if cap_e is not None:
            x = x + torch.where(cons, _emitter_release(cap_e, em_tau_s, grid,
                                                       packed.t_air_in_slope[night_index]), 0.0)
        h = torch.diff(grid, dim=1)
        x_slope = torch.zeros_like(x)
        x_slope[:, :-1] = torch.where(h > 0, torch.diff(x, dim=1) / h.clamp_min(1e-9), 0.0)
        coef = (a_air * k_phi + d)[:, None]
        u0_air = u0_air + coef * x
        u1_air = u1_air + coef * x_slope
        phi_w = phi_w + x

    # DEMAND rows: θ_m driven by measured T_air, T_out; surface node balance without Φ_st.
    s = net.h_tr_is + net.h_tr_w + net.h_tr_ms
    a_dem = (net.h_tr_ms * (net.h_tr_ms / s - 1.0) - net.h_tr_em) / net.c_m_j_per_k
    b_air = net.h_tr_ms * net.h_tr_is / s / net.c_m_j_per_k
    b_e = (net.h_tr_ms * net.h_tr_w / s + net.h_tr_em) / net.c_m_j_per_k
    c_air = net.h_tr_is + net.h_ve - net.h_tr_is ** 2 / s
    c_e = -net.h_ve - net.h_tr_is * net.h_tr_w / s
    c_m = -net.h_tr_is * net.h_tr_ms / s
    u0_dem = u1_dem = out_dem = None
    if any_dem:
        u0_dem = b_air[:, None] * ta + b_e[:, None] * te + (g_dem_rate * gain)[:, None]
        u1_dem = b_air[:, None] * ta_s + b_e[:, None] * te_s
        out_dem = (c_air[:, None] * ta + c_e[:, None] * te - (g_dem_heat * gain)[:, None]
                   + q_fur)

    mean_next = None
    if not any_air:  # DEMAND rows only (lm builds each row type on its own rows)
        mask = packed.demand_mask()[night_index]
        if packed.timestamps == "instant":
            mean_next = packed.next_node[night_index]
    elif not any_dem:  # AIR rows compare T_air at each sample's node: no interval mean
        mask = packed.mask[night_index]
    else:
        mask, mean_next = _mixed_mask(packed, night_index, dm, grid.shape[1])
    lag_next = lag_rate = lag_extra = None
    if packed.emitter_lag and any_dem and params.shape[-1] > len(PARAM_NAMES):
        # The meter measures the heat into the emitter, not into the room: with the emitter
        # node T_e = T_air + P/H_e (P the heat it gives the air, what the 5R1C demands) its
        # balance C_e·dT_e/dt = P_meter − P gives P_meter = P + τ_e·dP/dt + C_e·dT_air/dt,
        # τ_e = C_e/H_e — exact for a linear emitter, no extra state and no initial
        # condition (tests/test_node.py). Over a sample interval the mean of τ_e·dP/dt is
        # τ_e·(P_k+1 − P_k)/h_k. τ_e is the emitter time constant of the release after
        # switch-off (one constant for both kinds of night); switched off with that term.
        lag_next = packed.next_node[night_index]
        h = torch.gather(grid, 1, lag_next) - grid
        tau_s = torch.where(demand, params[:, len(PARAM_NAMES) + 2] * 3600.0, 0.0)
        lag_rate = torch.where(h > 0, tau_s[:, None] / h.clamp_min(1e-9), 0.0)
        if cap_e is not None:
            lag_extra = torch.where(demand, cap_e, 0.0)[:, None] * ta_s
    ode = NightODE(grid, pick(a_dem, a_air), pick(u0_dem, u0_air), pick(u1_dem, u1_air),
                   method=method)
    return RowModel(
        ode=ode,
        z0=pick(t_m0_c, z0_air),
        out_c=pick(c_m, torch.ones_like(c_m)),
        out_v=pick(out_dem, k_phi[:, None] * phi_w if any_air else None),
        measured=pick(packed.q_w[night_index] if any_dem else None,
                      packed.t_air_c[night_index] if any_air else None),
        mask=mask,
        mean_next=mean_next,
        lag_next=lag_next,
        lag_rate=lag_rate,
        lag_extra=lag_extra,
    )


def _emitter_release(c_e: torch.Tensor, tau_s: torch.Tensor, grid: torch.Tensor,
                     t_air_slope: torch.Tensor) -> torch.Tensor:
    """Heat [W] (R, K) an emitter of capacity C_e and time constant τ_e gives the air of a
    cooling night beyond its initial release: its excess e = T_e − T_air obeys
    de/dt = −e/τ_e − dT_air/dt (no metered heat), driven by the measured (smoothed) T_air and
    starting in step with a steady cooling; the heat is (C_e/τ_e)·e."""
    s = t_air_slope
    e = exact_chain(-tau_s * s[:, 0], -1.0 / tau_s, torch.diff(grid, dim=1), -s[:, :-1],
                    torch.zeros_like(s[:, :-1]))
    return (c_e / tau_s)[:, None] * e
