"""The night-time 5R1C dynamics as a torch module (the paper's eq. 5 and 6), batched over nights.

One *row* is one night under one parameter set; each row keeps its night's own sample times
(nights padded to the longest one). A whole fit — every start, every night, both modes — is
integrated in one batched call: by the exact discretisation (the default, :mod:`.solver`), whose
responses also give the optimiser its analytic Jacobian (:mod:`..optim.jacobian`), or by one
``torchdiffeq.odeint`` call with ``rk4`` (then the Jacobian's finite-difference copies ride in
the same call). The dynamics are linear, so every sample interval of every row is integrated at
once (its response to the state it starts from and to its own inputs), and the intervals are
chained by the exact linear recurrence (:class:`NightODE`). The Python cost is a few tensor
operations per call instead of one step per sample (21 s → about 2 s for the demo's export),
and each interval sees only its own inputs by construction (the "left-closed lookup per
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
row is the mean power over the interval that starts there). :func:`~.packing.pack_nights`
also handles the "interval" convention (every value a mean over the interval that starts at its
stamp).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch

from ...model.continuous import air_derivative, air_temperature
from ...model.house import H_MS
from .packing import PackedNights, rows_at
from .parameters import EMC_COLUMN, FUR_COLUMN, PARAM_NAMES, network
from .solver import (
    NightODE,  # the integrator (re-exported: tests and readers find it here)
    exact_chain,
)

ROW_AIR = 0
ROW_DEMAND = 1


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

    def take(self, sel: torch.Tensor) -> RowModel:
        """The rows ``sel`` (indices)."""
        ode = self.ode
        return RowModel(NightODE(ode.grid_s[sel], ode.a_per_s[sel], ode.u0[sel], ode.u1[sel],
                                 ode.method),
                        *(None if x is None else x[sel] for x in (
                            self.z0, self.out_c, self.out_v, self.measured, self.mask,
                            self.mean_next, self.lag_next, self.lag_rate, self.lag_extra)))

    def predict(self, z: torch.Tensor | None = None) -> torch.Tensor:
        """Model output at the nodes, (R, K) (interval means where ``mean_next`` says so;
        plus τ_e·ΔP/h on DEMAND rows with the emitter lag); ``z`` the states at the nodes when
        they are integrated already."""
        if z is None:
            z = self.ode.integrate(self.z0)
        out = self.observe(self.out_c[:, None] * z + self.out_v)
        if self.lag_extra is not None:
            out = out + self.lag_extra
        return out

    def observe(self, y: torch.Tensor) -> torch.Tensor:
        """The compared values of node values ``y`` (R, K), or of F columns at once (R, F, K):
        the linear part of :meth:`predict` (the analytic Jacobian maps its columns with it)."""
        def at(index):
            return torch.gather(y, -1, index if y.dim() == 2 else index[:, None].expand_as(y))

        out = y if self.mean_next is None else 0.5 * (y + at(self.mean_next))
        if self.lag_rate is not None:
            lag = self.lag_rate if y.dim() == 2 else self.lag_rate[:, None]
            out = out + lag * (at(self.lag_next) - y)
        return out


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
    mask = rows_at(packed.mask, night_index)
    mean_next = None
    if packed.timestamps == "instant":
        # A power sample is the mean until the next sample: compare the model's interval mean
        # (trapezoid), and drop the last sample, whose interval lies outside the night.
        nxt = rows_at(packed.next_node, night_index)
        mean_next = torch.where(dm, nxt, torch.arange(k).expand_as(nxt))
        mask = mask & ~(dm & rows_at(packed.last, night_index))
    if packed.power_ok is not None:
        mask = mask & ~(dm & ~rows_at(packed.power_ok, night_index))
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
    params : (R, 7) physical parameters per row (:data:`~.parameters.PARAM_NAMES` order), or
        (R, 10) with the :data:`~.parameters.NUISANCE_NAMES` terms appended
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
    if packed.emitter_lag and params.shape[-1] > EMC_COLUMN:
        # the emitter's share of C_m is not at the mass node (as the plant splits it)
        cap_e = params[:, EMC_COLUMN] * net.c_m_j_per_k
        net = dataclasses.replace(net, c_m_j_per_k=net.c_m_j_per_k - cap_e)
    te = rows_at(packed.t_out_c, night_index)
    te_s = rows_at(packed.t_out_slope, night_index)
    ta = rows_at(packed.t_air_in_c, night_index)
    ta_s = rows_at(packed.t_air_in_slope, night_index)
    grid = rows_at(packed.grid_s, night_index)
    demand = (row_type == ROW_DEMAND)
    dm = demand[:, None]
    # Rows of one type skip the other type's arithmetic (most of a fit's rows are DEMAND rows,
    # and lm evaluates each type on its own rows).
    any_air, any_dem = not bool(demand.all()), bool(demand.any())

    def pick(dem, air):
        return air if not any_dem else dem if not any_air else torch.where(
            dm if dem.dim() == 2 or air.dim() == 2 else demand, dem, air)

    # AIR rows: eq. 5/6 in the shifted state z = T_air − k_Φ·Φ_HC.
    a_air = b = c = d = k_phi = u0_air = u1_air = z0_air = None
    if any_air:
        a_air, b, c, d, k_phi = _air_coefficients(net)
        u0_air = b[:, None] * te + c[:, None] * te_s + (a_air * k_phi + d)[:, None] * phi_in_w
        u1_air = b[:, None] * te_s
        z0_air = air_temperature(t_m0_c, te[:, 0], 0.0, net)
    gain, em_w, em_tau_s, c_fur = _nuisance(packed, params, night_index)
    q_fur = torch.zeros_like(te)
    if params.shape[-1] > FUR_COLUMN:
        # heat the air/furniture capacity takes from the air node [W]
        q_fur = c_fur[:, None] * rows_at(packed.t_fur_slope, night_index)
    # the constant gain enters at the air, surface and mass nodes as ISO 13790 splits it
    g_air_rate, g_air_level, g_dem_rate, g_dem_heat = _gain_split(net)
    if params.shape[-1] > len(PARAM_NAMES) and any_air:
        u0_air = u0_air + (g_air_rate * gain)[:, None]
        z0_air = z0_air + g_air_level * gain
        # Extra heat to the air node, x(t) = the emitter's release on constrained nights
        # (− the furniture's uptake), linear between the nodes: it enters like Φ_HC (z stays
        # continuous).
        cons = rows_at(packed.constrained, night_index)[:, None]
        x = torch.where(cons, em_w[:, None] * torch.exp(
            -(grid - grid[:, :1]) / em_tau_s[:, None]), 0.0) - q_fur
        if cap_e is not None:
            slope = rows_at(packed.t_air_in_slope, night_index)
            x = x + torch.where(cons, _emitter_release(cap_e, em_tau_s, grid, slope), 0.0)
        h = torch.diff(grid, dim=1)
        x_slope = torch.zeros_like(x)
        x_slope[:, :-1] = interval_slope(x, h)
        coef = (a_air * k_phi + d)[:, None]
        u0_air = u0_air + coef * x
        u1_air = u1_air + coef * x_slope
        phi_w = phi_w + x

    # DEMAND rows: θ_m driven by measured T_air, T_out; surface node balance without Φ_st.
    a_dem, b_air, b_e, gain_rate, c_m, c_air, c_e, gain_heat = _demand_scalars(
        net, gain, g_dem_rate, g_dem_heat)
    u0_dem = u1_dem = out_dem = None
    if any_dem:
        u0_dem = b_air[:, None] * ta + b_e[:, None] * te + gain_rate[:, None]
        u1_dem = b_air[:, None] * ta_s + b_e[:, None] * te_s
        out_dem = c_air[:, None] * ta + c_e[:, None] * te - gain_heat[:, None] + q_fur

    mean_next = None
    if not any_air:  # DEMAND rows only (lm builds each row type on its own rows)
        mask = rows_at(packed.demand_mask(), night_index)
        if packed.timestamps == "instant":
            mean_next = rows_at(packed.next_node, night_index)
    elif not any_dem:  # AIR rows compare T_air at each sample's node: no interval mean
        mask = rows_at(packed.mask, night_index)
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
        lag_next = rows_at(packed.next_node, night_index)
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
        measured=pick(rows_at(packed.q_w, night_index) if any_dem else None,
                      rows_at(packed.t_air_c, night_index) if any_air else None),
        mask=mask,
        mean_next=mean_next,
        lag_next=lag_next,
        lag_rate=lag_rate,
        lag_extra=lag_extra,
    )


def interval_slope(v: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
    """Slope of node values ``v`` (R, …, K) on each interval of lengths ``h`` (R, …, K−1) [s]:
    zero on padding (zero-length intervals)."""
    return torch.where(h > 0, torch.diff(v, dim=-1) / h.clamp_min(1e-9), 0.0)


def _air_coefficients(net) -> tuple:
    """AIR rows' dz/dt = a·z + b·T_out + c·dT_out/dt + d·Φ_HC (eq. 5/6) and the air node's
    instantaneous share of the heat input k_Φ = ∂T_air/∂Φ_HC [K/W], each (R,).

    Eq. 5/6 are affine, so a coefficient is the derivative at a unit input; the four unit
    inputs go through one call broadcast to (4, R): per element the same arithmetic as four
    calls, in a quarter of the small-tensor operations (an optimiser evaluation's fixed cost).
    """
    unit = torch.eye(4, dtype=net.h_ve.dtype)[:, :, None]
    a, b, c, d = air_derivative(unit[0], unit[1], unit[2], unit[3], net)
    return a, b, c, d, air_temperature(0.0, 0.0, 1.0, net)


def _nuisance(packed: PackedNights, params: torch.Tensor, night_index: torch.Tensor | None
              ) -> tuple:
    """Per row (R,): the night's gain [W] (the campaign's, plus a measured night's own unless
    ``night_index`` is None), the emitter's release [W] and its time constant [s], the
    air/furniture capacity C_fur [J/K]; zeros (and τ 60 s) without the nuisance terms."""
    zero = torch.zeros_like(params[:, 0])
    gain, em_w, em_tau_s, c_fur = zero, zero, torch.full_like(zero, 60.0), zero
    if params.shape[-1] > FUR_COLUMN:
        c_fur = params[:, FUR_COLUMN] * params[:, 0]
    if params.shape[-1] > len(PARAM_NAMES):
        gain = params[:, len(PARAM_NAMES)]
        if packed.gain_w is not None and night_index is not None:
            gain = gain + rows_at(packed.gain_w, night_index)   # measured nights: each its own gain
        em_w, em_tau_s = (params[:, len(PARAM_NAMES) + j] for j in (1, 2))
        em_tau_s = (em_tau_s * 3600.0).clamp_min(60.0)  # a term switched off has τ = 0
    return gain, em_w, em_tau_s, c_fur


def _demand_scalars(net, gain, g_dem_rate, g_dem_heat) -> tuple:
    """The per-row numbers through which the parameters enter a DEMAND row, each (R,):
    dθ_m/dt = a·θ_m + b_air·T_air + b_e·T_out + gain_rate and
    Φ_HC = c_m·θ_m + c_air·T_air + c_e·T_out − gain_heat + q_fur
    (a, b in 1/s, c in W/K, the gain terms in K/s and W)."""
    s = net.h_tr_is + net.h_tr_w + net.h_tr_ms
    a_dem = (net.h_tr_ms * (net.h_tr_ms / s - 1.0) - net.h_tr_em) / net.c_m_j_per_k
    b_air = net.h_tr_ms * net.h_tr_is / s / net.c_m_j_per_k
    b_e = (net.h_tr_ms * net.h_tr_w / s + net.h_tr_em) / net.c_m_j_per_k
    c_air = net.h_tr_is + net.h_ve - net.h_tr_is ** 2 / s
    c_e = -net.h_ve - net.h_tr_is * net.h_tr_w / s
    c_m = -net.h_tr_is * net.h_tr_ms / s
    return a_dem, b_air, b_e, g_dem_rate * gain, c_m, c_air, c_e, g_dem_heat * gain


def row_scalars(packed: PackedNights, params: torch.Tensor, night_index: torch.Tensor | None,
                ach_vent: float, ach_infl: float, kinds: tuple[bool, ...]
                ) -> dict[bool, torch.Tensor]:
    """What a row's residuals depend on, as :func:`build_rows` computes it, for the row types
    ``kinds`` (True: DEMAND, False: AIR) from one network.

    DEMAND rows, (R, 9): the 8 numbers of :func:`_demand_scalars` and the furniture's capacity
    C_fur [J/K] (its heat is C_fur·dT_fur/dt). AIR rows, (R, 12): the rate a [1/s]; the
    initial state z0 = α·θ_m,0 + β·T_out,0 + z_gain as α, β [-] and z_gain [K]; the forcing
    weights b [1/s], c [-] and coef = a·k_Φ + d [K/J] of T_out, dT_out/dt and the heat
    input; the gain's rate [K/s]; k_Φ [K/W]; the emitter's release [W] and time constant [s];
    C_fur [J/K]. Rows may be problems (``night_index`` None) where no night has a gain of its
    own. Without the emitter lag (its emitter splits C_m).
    """
    net = network(params, ach_vent, ach_infl)
    gain, em_w, em_tau_s, c_fur = _nuisance(packed, params, night_index)
    g_air_rate, g_air_level, g_dem_rate, g_dem_heat = _gain_split(net)
    out = {}
    if True in kinds:
        out[True] = torch.stack([*_demand_scalars(net, gain, g_dem_rate, g_dem_heat), c_fur],
                                dim=1)
    if False in kinds:
        a_air, b, c, d, k_phi = _air_coefficients(net)
        unit = torch.eye(2, dtype=params.dtype)[:, :, None]
        alpha, beta = air_temperature(unit[0], unit[1], 0.0, net)
        out[False] = torch.stack([a_air, alpha, beta, g_air_level * gain, b, c,
                                  a_air * k_phi + d, g_air_rate * gain, k_phi, em_w, em_tau_s,
                                  c_fur], dim=1)
    return out


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
