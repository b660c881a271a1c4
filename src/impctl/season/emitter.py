"""What the emitter is, read from the heating water the gateway records: radiators or a screed.

The season model lags the meter's heat by the emitter's time constant τ_e
(:mod:`.projection.columns`), and how far the search may take it decides how well τ and C_m come
out. τ_e takes in more than the emitter — the air's and the furniture's capacity read as lag too
— and where it is free it trades with the mass's own time constant. The bound is set by what the
emitter is: a radiator's water and steel answer within the hour, an underfloor screed in 3–7 h
(real-houses §2). On the development households (seed 31, 100 households, IMP + 28 owner
nights), against one bound of 3 h for all: underfloor houses with 5 h, HLC 4.4 → 2.8 %, P90 14 →
10 %, τ 5.5 → 3.3 %; radiator houses with 1.5 h, τ's P90 18 → 16 %, C_m 9.4 → 7.4 % (bias +7.8 →
+0.5 %, P90 25 → 16 %; 1.0 / 2.0 h: C_m's P90 24 / 18 %). A house whose emitter is not known
keeps the 3 h.

The water tells them apart. An underfloor loop delivers the house's heat a few kelvins of water
above the room (design mean water 28–38 °C), a radiator 20–35 K above it (40–55 °C; real-houses
§2, EN 442). :func:`water_excess_k` reads, on the owner's plain nights, the mean water's excess
over the room and scales it to one load — the heat the house loses at 20 K indoors–outdoors, by
the fit's HLC and the emitter law Q ∝ ΔT^n — so that a mild night's low water and a cold
night's high water give the same number. Units: °C, K, W, s.
"""

from __future__ import annotations

import math

import numpy as np

from .record import SeasonRecord

#: Load the excess is scaled to: the heat lost at this indoor–outdoor difference [K].
REFERENCE_DT_K = 20.0
#: Emitter exponent the scaling assumes [-] (radiators 1.3, underfloor 1.1: the middle).
EXPONENT = 1.2
#: Window of the owner nights read [h local] (the energy signature's: the house settled).
HOURS = (0.0, 5.0)
#: Fewest nights with a reading for the excess to be given [-].
MIN_NIGHTS = 3
#: A night's mean heat must reach this share of the reference load to be read [-]: near zero
#: the scaling blows a small excess up.
MIN_LOAD_SHARE = 0.15
#: Excess at the reference load [K] from which the emitter is read as radiators: between the
#: design ranges (designed for −10 °C outdoors, underfloor at ≤ 38 °C mean water gives ≤ 12.8 K
#: at the reference load, radiators at ≥ 40 °C ≥ 14.3 K). On the development households 12 and
#: 13 K classify alike (real-houses §2; the plant's emitters are sized the same way).
RADIATOR_EXCESS_K = 13.0
#: Upper bound of the emitter's lag [s] for radiators, an underfloor screed and an emitter
#: not known (module docstring).
TAU_E_MAX_RADIATORS_S = 1.5 * 3600
TAU_E_MAX_UNDERFLOOR_S = 5.0 * 3600
TAU_E_MAX_UNKNOWN_S = 3.0 * 3600


def water_excess_k(rec: SeasonRecord, hlc_w_per_k: float) -> float:
    """The mean water's excess over the room at the reference load [K] (module docstring): the
    median over the owner nights with the water, the room and the meter read through
    :data:`HOURS` and nothing left out (:meth:`~.record.SeasonRecord.owner_windows`). NaN
    without the water temperatures, a finite positive ``hlc_w_per_k`` [W/K] or
    :data:`MIN_NIGHTS` such nights."""
    if len(rec.t_water_c) != rec.n or not (math.isfinite(hlc_w_per_k) and hlc_w_per_k > 0):
        return float("nan")
    q_ref = hlc_w_per_k * REFERENCE_DT_K
    out = []
    for sel in rec.owner_windows(HOURS, (rec.t_water_c,)):
        q = float(np.mean(rec.q_hc_w[sel]))
        excess = float(np.mean(rec.t_water_c[sel] - rec.t_air_c[sel]))
        if q < MIN_LOAD_SHARE * q_ref or excess <= 0:
            continue
        out.append(excess * (q_ref / q) ** (1.0 / EXPONENT))
    return float(np.median(out)) if len(out) >= MIN_NIGHTS else float("nan")


def emitter_kind(excess_k: float) -> str | None:
    """"radiators", "underfloor", or None when the excess is unknown (NaN)."""
    if not math.isfinite(excess_k):
        return None
    return "radiators" if excess_k >= RADIATOR_EXCESS_K else "underfloor"


def tau_e_max_s(kind: str | None) -> float:
    """Upper bound of the emitter's lag [s] for an emitter of ``kind`` (None: not known)."""
    return {"radiators": TAU_E_MAX_RADIATORS_S,
            "underfloor": TAU_E_MAX_UNDERFLOOR_S}.get(kind, TAU_E_MAX_UNKNOWN_S)


def water_recorded(rec: SeasonRecord) -> bool:
    """Whether any step of ``rec`` has the heating water's temperature."""
    return len(rec.t_water_c) == rec.n and bool(np.isfinite(rec.t_water_c).any())
