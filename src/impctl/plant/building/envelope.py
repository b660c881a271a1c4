"""The 5R1C envelope with air, furniture and emitter capacity: split of C_m and one time step.

Network (W/K, J/K): the ISO 13790 5R1C conductances unchanged (H_ve, H_tr,is, H_tr,w, H_tr,ms,
H_tr,em), so the steady-state heat-loss coefficient is exactly the 5R1C HLC. The ISO capacity C_m
is split, total unchanged (:func:`split_capacity`):

* C_air = ρc_air · V at the air node (3 kJ/(m²K) of floor at 2.5 m; RH §1),
* C_fur = furniture per m² · A_f on a furniture node coupled to the air by G_fur = rate · C_fur
  (τ ≈ 76 min; RH §1),
* C_em = the emitter's water + metal / screed (:mod:`impctl.plant.hydronics.emitter`),
* C_mass = C_m − C_air − C_fur − C_em on the ISO mass node.

If C_air + C_fur + C_em exceeds ``max_share`` · C_m the three are scaled down together (so a
light house with a heavy screed keeps ≥ 40 % of C_m as envelope mass).

Time step (``dt`` s, inputs constant over the step): Crank–Nicolson on the mass node (ISO C.4),
backward Euler on the air, furniture and emitter nodes (no ringing at any step), the surface node
algebraic. Every flux is evaluated at the same "evaluation temperatures" (the step mean of θ_m,
the end-of-step value of the others), so the energy balance — heat in = stored + lost — holds to
rounding in every step. With C_air = C_fur = C_em = 0 the scheme *is* Annex C (C.4–C.11): θ_m by
C.4, θ_s and θ_air from the step-mean θ_m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...model import HouseParameters
from ...model.house import H_MS

Array = NDArray[np.float64]


@dataclass(frozen=True)
class CapacitySplit:
    """How a house's C_m is shared between the nodes [J/K], arrays over houses.

    ``mass + air + furniture + emitter == c_m`` (the ISO C_m) to rounding.
    """

    c_m: Array
    mass: Array
    air: Array
    furniture: Array
    emitter: Array

    @property
    def shares(self) -> dict[str, Array]:
        """Each part / C_m [-]."""
        return {k: getattr(self, k) / self.c_m for k in ("mass", "air", "furniture", "emitter")}


def split_capacity(house: HouseParameters, air_j_per_k: Array, furniture_j_per_k: Array,
                   emitter_j_per_k: Array, max_share: Array) -> CapacitySplit:
    """Split C_m [J/K] into mass / air / furniture / emitter (module docstring).

    Parameters
    ----------
    house : HouseParameters
    air_j_per_k, furniture_j_per_k, emitter_j_per_k : wanted capacities [J/K]
    max_share : cap on their sum / C_m [-]
    """
    c_m = np.asarray(house.c_m_j_per_k, dtype=float)
    want = air_j_per_k + furniture_j_per_k + emitter_j_per_k
    scale = np.minimum(1.0, max_share * c_m / np.maximum(want, 1e-300))
    air, fur, em = air_j_per_k * scale, furniture_j_per_k * scale, emitter_j_per_k * scale
    return CapacitySplit(c_m, c_m - air - fur - em, air, fur, em)


@dataclass(frozen=True)
class Network:
    """Per-house constants of the envelope network (W/K, J/K; arrays over houses)."""

    h_ve: Array
    h_is: Array
    h_w: Array
    h_ms: Array
    h_em: Array
    c_air: Array
    c_fur: Array
    c_mass: Array
    g_fur: Array
    gain_ia: Array   # share of Φ_int at the air node (C.1)
    gain_m: Array    # share of (Φ_int/2 + Φ_sol) at the mass (C.2)
    gain_st: Array   # share of (Φ_int/2 + Φ_sol) at the surface (C.3)

    @classmethod
    def build(cls, house: HouseParameters, split: CapacitySplit,
              furniture_rate_per_s: Array, n: int) -> Network:
        """Network of ``n`` houses from the ISO parameters and the capacity split."""
        net = house.network

        def b(v):
            return np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()

        am_at = b(net.a_m_m2 / net.a_t_m2)
        return cls(
            h_ve=b(net.h_ve), h_is=b(net.h_tr_is), h_w=b(net.h_tr_w), h_ms=b(net.h_tr_ms),
            h_em=b(net.h_tr_em), c_air=b(split.air), c_fur=b(split.furniture),
            c_mass=b(split.mass), g_fur=b(furniture_rate_per_s * split.furniture),
            gain_ia=np.full(n, 0.5), gain_m=am_at,
            gain_st=1.0 - am_at - b(net.h_tr_w) / (H_MS * b(net.a_t_m2)),
        )


@dataclass
class NodeState:
    """Node temperatures at the end of the last step [°C], arrays over houses."""

    air: Array
    furniture: Array
    mass: Array
    water: Array
    surface: Array


@dataclass(frozen=True)
class StepSolution:
    """One solved step. Temperatures [°C] (``mass_mean`` = step mean of θ_m), powers [W]."""

    air: Array
    furniture: Array
    surface: Array
    mass_mean: Array
    mass: Array
    water: Array
    emitter_w: Array   # heat the emitter gives the air node
    net: Network
    t_e: Array
    phi_parts: tuple[Array, Array, Array]

    @property
    def loss_w(self) -> Array:
        """Heat lost to outside: ventilation, windows, opaque elements [W]."""
        n, t_e = self.net, self.t_e
        return (n.h_ve * (self.air - t_e) + n.h_w * (self.surface - t_e)
                + n.h_em * (self.mass_mean - t_e))

    @property
    def gains_w(self) -> Array:
        """Internal + solar gains entering the network (C.1–C.3) [W]."""
        a, m, st = self.phi_parts
        return a + m + st


class Solver:
    """Eliminates the node equations of one step for given inputs (module docstring).

    Every evaluation temperature is affine in the heat-pump power P into the water; ``air_free``
    and ``k_air`` give θ_air = air_free + k_air·P (used by the ideal controller, as Annex C
    C.13 uses it), :meth:`finish` the rest.
    """

    def __init__(self, net: Network) -> None:
        self.net = net
        self._dt_key: tuple[float, int] | None = None

    def _constants(self, dt: float, c_em: Array) -> None:
        """Per-step constants that depend only on Δt and the capacities (cached)."""
        n = self.net
        c_m2 = 2.0 * n.c_mass / dt          # CN: C/dt·(x_t − x_0) = 2C/dt·(x̄ − x_0)
        c_a = n.c_air / dt
        # Furniture: f = (c_f f0 + G a)/(c_f + G); flux to air γ_f (f0 − a), γ_f = G·c_f/(c_f+G).
        g_f = n.g_fur / (1.0 + n.g_fur * dt / np.maximum(n.c_fur, 1e-300))
        g_f = np.where(n.c_fur > 0, g_f, 0.0)
        den_m = c_m2 + n.h_ms + n.h_em
        mu_s = n.h_ms / den_m
        den_s = n.h_ms * (1.0 - mu_s) + n.h_w + n.h_is
        sig_a = n.h_is / den_s
        self._k = dict(
            c_m2_over_den_m=c_m2 / den_m, h_em_over_den_m=n.h_em / den_m, inv_den_m=1.0 / den_m,
            c_a=c_a, c_w=c_em / dt, g_f=g_f, mu_s=mu_s, inv_den_s=1.0 / den_s,
            h_ms_over_den_s=n.h_ms / den_s, h_w_over_den_s=n.h_w / den_s, sig_a=sig_a,
            den_a0=c_a + n.h_is * (1.0 - sig_a) + n.h_ve + g_f,
            fur_step=np.where(n.c_fur > 0, g_f * dt / np.maximum(n.c_fur, 1e-300), 1.0),
        )
        self._dt_key = (dt, id(c_em))

    def prepare(self, st: NodeState, dt: float, t_e: Array, phi_int: Array, phi_sol: Array,
                c_em: Array, g_em: Array) -> tuple[Array, Array]:
        """Return (air_free, k_air) for this step: θ_air = air_free + k_air·P [°C, K/W]."""
        if self._dt_key != (dt, id(c_em)):
            self._constants(dt, c_em)
        n, k = self.net, self._k
        c_w = k["c_w"]
        # Emitter: w = (c_w w0 + P + G a)/(c_w + G); flux to air γ_w (c_w (w0 − a) + P).
        gam_w = g_em / (c_w + g_em)
        half = 0.5 * phi_int + phi_sol
        phi_ia = n.gain_ia * phi_int
        phi_m = n.gain_m * half
        phi_st = n.gain_st * half
        # Mass: m̄ = μ0 + μs·s.
        mu0 = k["c_m2_over_den_m"] * st.mass + k["h_em_over_den_m"] * t_e + phi_m * k["inv_den_m"]
        # Surface: s = σ0 + σa·a.
        sig0 = (k["h_ms_over_den_s"] * mu0 + k["h_w_over_den_s"] * t_e
                + phi_st * k["inv_den_s"])
        gw_cw = gam_w * c_w
        den_a = k["den_a0"] + gw_cw
        num_a = (k["c_a"] * st.air + n.h_is * sig0 + n.h_ve * t_e + k["g_f"] * st.furniture
                 + gw_cw * st.water + phi_ia)
        self._c = (t_e, c_w, g_em, mu0, sig0, phi_ia, phi_m, phi_st)
        return num_a / den_a, gam_w / den_a

    def finish(self, st: NodeState, air_free: Array, k_air: Array, power_w: Array) -> StepSolution:
        """Solve the step for heat-pump power ``power_w`` [W] into the water and update ``st``."""
        n, k = self.net, self._k
        t_e, c_w, g_em, mu0, sig0, phi_ia, phi_m, phi_st = self._c
        a = air_free + k_air * power_w
        s = sig0 + k["sig_a"] * a
        m_bar = mu0 + k["mu_s"] * s
        w = (c_w * st.water + power_w + g_em * a) / (c_w + g_em)
        f = st.furniture + k["fur_step"] * (a - st.furniture)
        emitter_w = g_em * (w - a)
        mass_end = 2.0 * m_bar - st.mass
        st.air, st.furniture, st.mass, st.water, st.surface = a, f, mass_end, w, s
        return StepSolution(a, f, s, m_bar, mass_end, w, emitter_w, n, t_e,
                            (phi_ia, phi_m, phi_st))


def stored_j(split: CapacitySplit, c_em: Array, st: NodeState) -> Array:
    """Heat stored above 0 °C in all capacities [J] (for energy-balance checks)."""
    return (split.mass * st.mass + split.air * st.air + split.furniture * st.furniture
            + c_em * st.water)


def steady_state(house: HouseParameters, t_air_c: Array, t_e_c: Array) -> dict[str, Array]:
    """Node temperatures [°C] holding ``t_air_c`` at outdoor ``t_e_c`` with the heat at the air
    node and no gains; ``power_w`` = HLC·(θ_air − θ_e) [W]."""
    net = house.network
    env = net.h_tr_w + net.h_tr_op
    q_env = net.h_tr_is * env / (net.h_tr_is + env) * (t_air_c - t_e_c)
    t_s = t_air_c - q_env / net.h_tr_is
    q_op = q_env - net.h_tr_w * (t_s - t_e_c)
    t_m = t_s - q_op / net.h_tr_ms
    return {"air": t_air_c, "surface": t_s, "mass": t_m,
            "power_w": net.hlc_w_per_k * (t_air_c - t_e_c)}
