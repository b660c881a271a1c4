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
night's high water give the same number. Where the two kinds' excesses overlap, the
constrained nights decide (:func:`water_decay_h`): once the heat stops, a radiator's excess
over the room fades within an hour or two, a screed's over many hours. Where that fade was
read it bounds the lag itself (:func:`lag_bound_s`), this house's measurement in place of its
kind's bound. Units: °C, K, W, s, h.
"""

from __future__ import annotations

import math

import numpy as np

from ..imp.protocol import Q_ON_W
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
#: Excesses [K] at which the two kinds overlap (on the development households: radiators'
#: 5th percentile 12.3 K, their misread ones down to 9.8 K; screeds' 95th 13.2 K): there the
#: water's decay after a switch-off decides, where a constrained night shows it.
DECAY_BAND_K = (9.5, 14.5)
#: The water's e-folding time after a switch-off [h] from which the emitter is a screed: a
#: radiator's water and steel fade in about half an hour, a screed's in 3–7 h (real-houses §2;
#: on four seeds of 200 realistic households radiators 0.9–4.6 h, 5th–95th percentile,
#: screeds 4.6–16 h — the room's own cooling and the pipes slow both).
SCREED_DECAY_H = 3.5
#: Share of the water's fade [-] the emitter's lag may reach, where the fade was read: the
#: lag takes in the air's and the furniture's lag too, and where it is free it trades with the
#: mass (measured: decision 0037); and the bounds that share is held within [s].
DECAY_LAG_SHARE = 0.6
LAG_BOUND_S = (0.5 * 3600, 8.0 * 3600)
#: Excess [K] a decay is read from, and down to; the shortest stretch read [h].
DECAY_FROM_K, DECAY_TO_K, DECAY_MIN_H = 2.0, 0.5, 1.0
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


def water_decay_h(rec: SeasonRecord) -> float:
    """How fast the water's excess over the room fades once the heat stops [h]: the median
    over the constrained nights of the e-folding time of (water − room), fitted log-linearly
    from the switch-off (the first step the meter reads under
    :data:`~impctl.imp.protocol.Q_ON_W`, from an excess of at least :data:`DECAY_FROM_K`) to
    the heat's return or the excess under :data:`DECAY_TO_K`, over at least
    :data:`DECAY_MIN_H`. NaN without the water, a constrained night or such a stretch."""
    if not water_recorded(rec):
        return float("nan")
    per = max(rec.step_s, 1.0)
    out = []
    steps = np.flatnonzero(rec.kind == "constrained")
    for night in dict.fromkeys(rec.night_id[steps].tolist()):
        at = steps[rec.night_id[steps] == night]
        ex = rec.t_water_c[at] - rec.t_air_c[at]
        off = rec.q_hc_w[at] < Q_ON_W
        first = np.flatnonzero(off & (ex >= DECAY_FROM_K))
        if not len(first):
            continue
        i = j = int(first[0])
        while j < len(at) and off[j] and np.isfinite(ex[j]) and ex[j] >= DECAY_TO_K:
            j += 1
        if (j - i) * per < DECAY_MIN_H * 3600.0:
            continue
        slope = np.polyfit((at[i:j] - at[i]) * per / 3600.0, np.log(ex[i:j]), 1)[0]
        if slope < 0:
            out.append(-1.0 / slope)
    return float(np.median(out)) if out else float("nan")


def emitter_kind(excess_k: float, decay_h: float = float("nan")) -> str | None:
    """"radiators", "underfloor", or None when the excess is unknown (NaN). Within
    :data:`DECAY_BAND_K`, where the two kinds' excesses overlap, the water's decay after a
    switch-off (:func:`water_decay_h`) decides when it was read: from :data:`SCREED_DECAY_H`
    a screed."""
    if not math.isfinite(excess_k):
        return None
    if decay_decides(excess_k, decay_h):
        return "underfloor" if decay_h >= SCREED_DECAY_H else "radiators"
    return "radiators" if excess_k >= RADIATOR_EXCESS_K else "underfloor"


def lag_bound_s(decay_h: float) -> float:
    """Upper bound of the emitter's lag [s] from the water's fade ``decay_h`` [h]
    (:data:`DECAY_LAG_SHARE` of it, within :data:`LAG_BOUND_S`)."""
    return min(max(DECAY_LAG_SHARE * decay_h * 3600.0, LAG_BOUND_S[0]), LAG_BOUND_S[1])


def decay_decides(excess_k: float, decay_h: float) -> bool:
    """Whether the water's decay, not its excess, tells the emitter (:func:`emitter_kind`)."""
    return DECAY_BAND_K[0] <= excess_k < DECAY_BAND_K[1] and math.isfinite(decay_h)


def tau_e_max_s(kind: str | None) -> float:
    """Upper bound of the emitter's lag [s] for an emitter of ``kind`` (None: not known)."""
    return {"radiators": TAU_E_MAX_RADIATORS_S,
            "underfloor": TAU_E_MAX_UNDERFLOOR_S}.get(kind, TAU_E_MAX_UNKNOWN_S)


def water_recorded(rec: SeasonRecord) -> bool:
    """Whether any step of ``rec`` has the heating water's temperature."""
    return len(rec.t_water_c) == rec.n and bool(np.isfinite(rec.t_water_c).any())
