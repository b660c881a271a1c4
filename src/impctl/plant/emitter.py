"""Hydronic emitter: sizing, heat capacity and output K·(θ_w − θ_air)^n (RH §2).

θ_w is the emitter's mean water temperature [°C]. Radiators: P₅₀ = K·50ⁿ is the EN 442 rating
(ΔT = 50 K), capacity ≈ 36 J/K per rated W (water + steel). Underfloor: capacity of the screed per
m² of heated floor (130–250 kJ/(m²K)), n ≈ 1.1. A buffer tank adds water (4186 J/(kg K)). The
emitter is sized to deliver the design heat load HLC·(20 °C − θ_design) at the design mean water
temperature, so a "well-matched" heating curve is θ_w = 20 + (HLC·(20 − θ_e)/K)^(1/n).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .params import RADIATORS, Emitter

Array = NDArray[np.float64]

#: Room temperature of the design point [°C].
DESIGN_ROOM_C = 20.0
#: c_p of water [J/(kg K)]; 1 L ≈ 1 kg.
WATER_J_PER_KG_K = 4186.0
#: Smallest temperature difference used for the secant conductance [K] (n > 1 makes the
#: conductance vanish at ΔT = 0; natural convection never quite stops).
MIN_DELTA_K = 0.5


def design_load_w(hlc_w_per_k: Array, emitter: Emitter) -> Array:
    """Design heat load HLC·(20 − θ_design) [W]."""
    return hlc_w_per_k * (DESIGN_ROOM_C - np.asarray(emitter.design_t_out_c, dtype=float))


def output_constant(hlc_w_per_k: Array, emitter: Emitter) -> Array:
    """K [W/Kⁿ] such that K·(θ_w,design − 20)ⁿ = the design load."""
    dt = np.asarray(emitter.design_water_c, dtype=float) - DESIGN_ROOM_C
    return design_load_w(hlc_w_per_k, emitter) / dt ** np.asarray(emitter.exponent, dtype=float)


def capacity_j_per_k(k_w: Array, emitter: Emitter, floor_area_m2: Array,
                     hp_nominal_w: Array) -> Array:
    """Emitter water + metal (radiators) or screed (underfloor) + buffer [J/K]."""
    n = np.asarray(emitter.exponent, dtype=float)
    rated_w = k_w * 50.0 ** n
    radiators = np.asarray(emitter.radiator_j_per_k_per_w, dtype=float) * rated_w
    screed = (np.asarray(emitter.screed_j_per_m2k, dtype=float)
              * np.asarray(emitter.ufh_area_share, dtype=float) * floor_area_m2)
    body = np.where(np.asarray(emitter.kind) == RADIATORS, radiators, screed)
    buffer = np.asarray(emitter.buffer_l_per_kw, dtype=float) * hp_nominal_w / 1000.0
    return body + buffer * WATER_J_PER_KG_K


def output_w(k_w: Array, exponent: Array, t_water_c: Array, t_air_c: Array) -> Array:
    """Emitter output K·sign(ΔT)·|ΔT|ⁿ [W] (negative: the emitter takes heat from the room)."""
    d = t_water_c - t_air_c
    return k_w * np.sign(d) * np.abs(d) ** exponent


def secant_conductance(k_w: Array, exponent: Array, t_water_c: Array,
                       t_air_c: Array) -> Array:
    """K·|ΔT|ⁿ⁻¹ [W/K] at the start of a step (ΔT ≥ :data:`MIN_DELTA_K`), used over the step."""
    d = np.maximum(np.abs(t_water_c - t_air_c), MIN_DELTA_K)
    return k_w * d ** (exponent - 1.0)


def matched_water_c(k_w: Array, exponent: Array, hlc_w_per_k: Array, setpoint_c: Array,
                    t_out_c: Array) -> Array:
    """Mean water temperature whose steady output holds ``setpoint_c`` at ``t_out_c`` [°C]."""
    load = hlc_w_per_k * np.maximum(setpoint_c - t_out_c, 0.0)
    return setpoint_c + (load / k_w) ** (1.0 / exponent)
