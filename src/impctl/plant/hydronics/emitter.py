"""Hydronic emitter: sizing, heat capacity and output K·(θ_w − θ_air)^n (RH §2).

The emitter node θ_w [°C] is the radiators' mean water temperature, or the underfloor screed's
temperature.

* Radiators: K sized to deliver the design heat load HLC·(20 °C − θ_design) at the design mean
  water temperature; P₅₀ = K·50ⁿ is the EN 442 rating (ΔT = 50 K) and the capacity ≈ 36 J/K per
  rated W (water + steel).
* Underfloor: K = 8.92 W/(m²K^1.1) × heated floor area (EN 1264 characteristic, RH §2), the
  screed 130–250 kJ/(m²K) of heated floor; this gives the screed–room time constant of ≈ 3.5–7 h
  of RH §2. The water runs above the screed by P/G_pipe, G_pipe sized so that the mean water
  temperature is ``design_water_c`` at the design load (it sets the supply temperature and COP
  only).

A buffer tank adds water (4186 J/(kg K)). The matched heating curve is
θ_w = 20 + (HLC·(20 − θ_e)/K)^(1/n).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..params import RADIATORS, Emitter

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


#: Underfloor output per m² of heated floor: q = 8.92·Δθ^1.1 W/m² (RH §2, EN 1264 [unverified]).
UFH_W_PER_M2 = 8.92


def output_constant(hlc_w_per_k: Array, emitter: Emitter, floor_area_m2: Array) -> Array:
    """K [W/Kⁿ]: radiators sized so that K·(θ_w,design − 20)ⁿ = the design load; underfloor
    8.92 W/(m²K^n) × heated area."""
    dt = np.asarray(emitter.design_water_c, dtype=float) - DESIGN_ROOM_C
    radiators = (design_load_w(hlc_w_per_k, emitter)
                 / dt ** np.asarray(emitter.exponent, dtype=float))
    ufh = UFH_W_PER_M2 * np.asarray(emitter.ufh_area_share, dtype=float) * floor_area_m2
    return np.where(np.asarray(emitter.kind) == RADIATORS, radiators, ufh)


def node_design_c(k_w: Array, hlc_w_per_k: Array, emitter: Emitter) -> Array:
    """Emitter node temperature delivering the design load [°C]."""
    n = np.asarray(emitter.exponent, dtype=float)
    return DESIGN_ROOM_C + (design_load_w(hlc_w_per_k, emitter) / k_w) ** (1.0 / n)


def pipe_conductance(k_w: Array, hlc_w_per_k: Array, emitter: Emitter) -> Array:
    """Water → emitter node conductance [W/K]: inf for radiators (the node is the water);
    underfloor: design load / (design water − design screed), inf if that is ≤ 0.5 K."""
    gap = np.asarray(emitter.design_water_c, dtype=float) - node_design_c(k_w, hlc_w_per_k,
                                                                          emitter)
    g = design_load_w(hlc_w_per_k, emitter) / np.maximum(gap, 0.5)
    return np.where((np.asarray(emitter.kind) == RADIATORS) | (gap <= 0.5), np.inf, g)


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
