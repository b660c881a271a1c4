"""ISO 13790 Annex C time step (C.1–C.11, demand by C.13), vectorised over houses.

Temperatures in °C, powers in W, the time step Δt in s. Heating only: the heat Φ_HC enters the
air node; supply air is outdoor air (θ_sup = θ_e).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .house import Conductances, HouseParameters

#: Test power per floor area for the C.13 interpolation [W/m²].
PHI_10_W_PER_M2 = 10.0


@dataclass(frozen=True)
class Simulation:
    """Result of :func:`simulate`; arrays of shape (n_steps, n_houses), or (n_steps,) for one house.

    Attributes
    ----------
    t_air_c : air temperature of the step [°C] (C.11, with the step-mean θ_m)
    t_s_c : surface (star) node temperature of the step [°C] (C.10)
    t_m_c : mass temperature at the END of the step, θ_m,t [°C] (C.4)
    phi_hc_w : heating power delivered in the step [W]
    """

    t_air_c: NDArray[np.float64]
    t_s_c: NDArray[np.float64]
    t_m_c: NDArray[np.float64]
    phi_hc_w: NDArray[np.float64]


class _Step:
    """Per-house constants of one Annex C step of length ``dt_s``.

    Every node temperature of a step is affine in Φ_HC: θ = θ(Φ=0) + Φ·k. The ``k_*`` are those
    sensitivities, so the C.13 second evaluation with Φ_10 and the final evaluation reuse the
    first one exactly instead of repeating C.1–C.11 (same numbers, a third of the work).
    """

    def __init__(self, net: Conductances, dt_s: float):
        h_ve, h_is, h_w, h_ms = net.h_ve, net.h_tr_is, net.h_tr_w, net.h_tr_ms
        h1, h2, h3, h_em = net.h_tr_1, net.h_tr_2, net.h_tr_3, net.h_tr_em
        c_dt = net.c_m_j_per_k / dt_s
        self.den_m = c_dt + 0.5 * (h3 + h_em)
        self.a_m = (c_dt - 0.5 * (h3 + h_em)) / self.den_m  # θ_m,t-1 → θ_m,t
        # H_tr,1·(Φ_ia/H_ve + θ_sup) = Φ_ia·f_ia + H_tr,1·θ_sup, finite at H_ve = 0.
        self.f_ia = h_is / (h_ve + h_is)
        self.h1, self.h2, self.h3, self.h_em, self.h_w = h1, h2, h3, h_em, h_w
        self.h_ms, self.h_is, self.h_ve = h_ms, h_is, h_ve
        self.den_s = h_ms + h_w + h1
        self.den_air = h_is + h_ve
        self.am_at = net.a_m_m2 / net.a_t_m2
        self.st_frac = 1.0 - self.am_at - h_w / (9.1 * net.a_t_m2)
        # Sensitivities to Φ_HC (W → K).
        self.k_m = h3 * self.f_ia / h2 / self.den_m
        self.k_s = (h_ms * 0.5 * self.k_m + self.f_ia) / self.den_s
        self.k_air = (h_is * self.k_s + 1.0) / self.den_air
        self.phi_10 = PHI_10_W_PER_M2 * net.floor_area_m2

    def free(self, t_m_prev, t_e, phi_int, phi_sol):
        """C.1–C.11 with Φ_HC = 0 → (θ_m,t, θ_s, θ_air)."""
        gains = 0.5 * phi_int + phi_sol
        phi_ia = 0.5 * phi_int
        phi_m = self.am_at * gains
        phi_st = self.st_frac * gains
        q1 = phi_ia * self.f_ia + self.h1 * t_e
        phi_mtot = phi_m + self.h_em * t_e + self.h3 * (phi_st + self.h_w * t_e + q1) / self.h2
        t_m = self.a_m * t_m_prev + phi_mtot / self.den_m
        t_mean = 0.5 * (t_m + t_m_prev)
        t_s = (self.h_ms * t_mean + phi_st + self.h_w * t_e + q1) / self.den_s
        t_air = (self.h_is * t_s + self.h_ve * t_e + phi_ia) / self.den_air
        return t_m, t_s, t_air


def _as_2d(name: str, value: ArrayLike | None, n_steps: int | None, n_houses: int) -> NDArray:
    """Shape (n_steps, 1) or (n_steps, n_houses); shared inputs are not copied per house."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        if n_steps is None:
            raise ValueError(f"{name}: cannot infer the number of steps from a scalar")
        return np.broadcast_to(arr, (n_steps, 1))
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[1] not in (1, n_houses):
        raise ValueError(f"{name}: shape {np.shape(value)} fits neither (n_steps,) nor "
                         f"(n_steps, {n_houses})")
    if n_steps is not None and arr.shape[0] != n_steps:
        raise ValueError(f"{name}: {arr.shape[0]} steps, expected {n_steps}")
    return arr


def simulate(
    house: HouseParameters,
    t_out_c: ArrayLike,
    dt_s: float,
    *,
    setpoint_c: ArrayLike | None = None,
    phi_hc_w: ArrayLike | None = None,
    internal_gains_w: ArrayLike = 0.0,
    solar_gains_w: ArrayLike = 0.0,
    t_m_init_c: ArrayLike = 20.0,
) -> Simulation:
    """Run the ISO 13790 Annex C simple hourly method for any time step.

    Each step is one of: (a) a heating setpoint — demand by the 10 W/m² method (C.13), capped at
    ``max_heating_power``; (b) heating off — Φ_HC = 0; (c) a forced Φ_HC. A forced power wins
    over a setpoint; NaN means "none" in both arrays. No cooling.

    Parameters
    ----------
    house : HouseParameters
        One house (float fields) or many (array fields of length n_houses).
    t_out_c : array, shape (n_steps,) or (n_steps, n_houses)
        Outdoor (and supply-air) temperature per step [°C].
    dt_s : float
        Time step [s].
    setpoint_c : array, optional
        Heating setpoint per step [°C]; NaN = heating off. Default: heating off throughout.
    phi_hc_w : array, optional
        Forced heating power per step [W]; NaN = not forced.
    internal_gains_w, solar_gains_w : float or array
        Φ_int and transmitted Φ_sol [W]; default 0.
    t_m_init_c : float or array (n_houses,)
        Mass temperature before the first step θ_m,0 [°C].

    Returns
    -------
    Simulation
    """
    if not dt_s > 0:
        raise ValueError("dt_s must be > 0")
    single = house.n_houses is None
    n_houses = house.n_houses or 1
    t_e = _as_2d("t_out_c", t_out_c, None, n_houses)
    n_steps = t_e.shape[0]
    nan = np.broadcast_to(np.nan, (n_steps, 1))
    sp = _as_2d("setpoint_c", nan if setpoint_c is None else setpoint_c, n_steps, n_houses)
    forced = _as_2d("phi_hc_w", nan if phi_hc_w is None else phi_hc_w, n_steps, n_houses)
    phi_int = _as_2d("internal_gains_w", internal_gains_w, n_steps, n_houses)
    phi_sol = _as_2d("solar_gains_w", solar_gains_w, n_steps, n_houses)

    def per_house(v):
        return np.broadcast_to(np.asarray(v, dtype=float), (n_houses,))

    step = _Step(house.network, float(dt_s))
    step = _broadcast_step(step, per_house)
    p_max = per_house(house.max_heating_power)

    out_air = np.empty((n_steps, n_houses))
    out_s = np.empty((n_steps, n_houses))
    out_m = np.empty((n_steps, n_houses))
    out_phi = np.empty((n_steps, n_houses))
    t_m = per_house(t_m_init_c).copy()
    has_forced = bool(np.any(~np.isnan(forced)))
    for i in range(n_steps):
        t_m_free, t_s_free, t_air_free = step.free(t_m, t_e[i], phi_int[i], phi_sol[i])
        # C.13: Φ_un = Φ_10·(θ_set − θ_air,0)/(θ_air,10 − θ_air,0); θ_air,10 − θ_air,0 = Φ_10·k_air.
        phi_un = step.phi_10 * (sp[i] - t_air_free) / (step.phi_10 * step.k_air)
        # NaN setpoint (off) and a free-floating step (θ_air,0 ≥ θ_set) both give 0.
        phi = np.minimum(np.where(phi_un > 0, phi_un, 0.0), p_max)
        if has_forced:
            phi = np.where(np.isnan(forced[i]), phi, forced[i])
        t_m = t_m_free + phi * step.k_m
        out_m[i] = t_m
        out_s[i] = t_s_free + phi * step.k_s
        out_air[i] = t_air_free + phi * step.k_air
        out_phi[i] = phi
    if single:
        return Simulation(out_air[:, 0], out_s[:, 0], out_m[:, 0], out_phi[:, 0])
    return Simulation(out_air, out_s, out_m, out_phi)


def _broadcast_step(step: _Step, per_house) -> _Step:
    for name, value in vars(step).items():
        setattr(step, name, per_house(value))
    return step
