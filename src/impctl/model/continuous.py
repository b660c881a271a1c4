"""Continuous-time form of the 5R1C model for the fit (the paper's eq. 1, 5 and 6).

The mass temperature θ_m is the only state; θ_s and θ_air are algebraic in it. Every function
is plain arithmetic on its arguments, so it evaluates on floats, NumPy arrays and torch tensors
(autograd included). Temperatures °C, powers W, time s, rates K/s. No solar gains, no internal
gains: the night-time cases of the paper. The heat Φ_HC enters the air node.

The Annex C step (C.4) is the trapezoidal (Crank–Nicolson) discretisation of
:func:`mass_derivative`, so stepping this ODE finely converges to Annex C at second order in Δt.
"""

from __future__ import annotations

from typing import Any

from .house import Conductances


def mass_derivative(t_m: Any, t_e: Any, phi_hc: Any, net: Conductances) -> Any:
    """dθ_m/dt [K/s] = (Φ_m,tot − (H_tr,em + H_tr,3)·θ_m)/C_m (paper eq. 1).

    Φ_m,tot = (H_tr,em + H_tr,3)·θ_e + H_tr,3/H_tr,2 · H_tr,is/(H_tr,is + H_ve) · Φ_HC, the
    C.5 flux with θ_sup = θ_e and no gains.
    """
    h_sum = net.h_tr_em + net.h_tr_3
    f_ia = net.h_tr_is / (net.h_tr_is + net.h_ve)
    phi_mtot = h_sum * t_e + net.h_tr_3 / net.h_tr_2 * f_ia * phi_hc
    return (phi_mtot - h_sum * t_m) / net.c_m_j_per_k


def surface_temperature(t_m: Any, t_e: Any, phi_hc: Any, net: Conductances) -> Any:
    """θ_s [°C] from the instantaneous θ_m (C.10 with no gains)."""
    f_ia = net.h_tr_is / (net.h_tr_is + net.h_ve)
    num = net.h_tr_ms * t_m + net.h_tr_w * t_e + f_ia * phi_hc + net.h_tr_1 * t_e
    return num / (net.h_tr_ms + net.h_tr_w + net.h_tr_1)


def air_temperature(t_m: Any, t_e: Any, phi_hc: Any, net: Conductances) -> Any:
    """θ_air [°C] from the instantaneous θ_m (C.10–C.11 with no gains)."""
    t_s = surface_temperature(t_m, t_e, phi_hc, net)
    return (net.h_tr_is * t_s + net.h_ve * t_e + phi_hc) / (net.h_tr_is + net.h_ve)


def mass_from_air(t_air: Any, t_e: Any, phi_hc: Any, net: Conductances) -> Any:
    """Invert :func:`air_temperature`: θ_m [°C] for a given θ_air (the paper's eq. 5/6 set)."""
    t_s = ((net.h_tr_is + net.h_ve) * t_air - net.h_ve * t_e - phi_hc) / net.h_tr_is
    f_ia = net.h_tr_is / (net.h_tr_is + net.h_ve)
    return ((net.h_tr_ms + net.h_tr_2) * t_s - net.h_tr_2 * t_e - f_ia * phi_hc) / net.h_tr_ms


def air_derivative(
    t_air: Any, t_e: Any, dt_e_dt: Any, phi_hc: Any, net: Conductances
) -> Any:
    """dθ_air/dt [K/s] at constant Φ_HC: the paper's eq. 5 (Φ_HC = the night's heat power) and
    eq. 6 (Φ_HC = 0, from one emitter lag after switch-off).

    dθ_air/dt = H_is/((H_is + H_ve)(H_ms + H_tr,2))·(H_ms·dθ_m/dt + H_tr,2·dθ_e/dt)
                + H_ve/(H_is + H_ve)·dθ_e/dt

    Parameters
    ----------
    t_air : °C
    t_e : °C
    dt_e_dt : K/s, rate of change of the outdoor temperature
    phi_hc : W, constant over the interval
    net : Conductances
    """
    t_m = mass_from_air(t_air, t_e, phi_hc, net)
    dt_m = mass_derivative(t_m, t_e, phi_hc, net)
    den = net.h_tr_is + net.h_ve
    surface_rate = (net.h_tr_ms * dt_m + net.h_tr_2 * dt_e_dt) / (net.h_tr_ms + net.h_tr_2)
    return net.h_tr_is / den * surface_rate + net.h_ve / den * dt_e_dt
