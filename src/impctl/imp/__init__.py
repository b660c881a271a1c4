"""The Identification Measurement Procedure: night plans, measured-night data, features.

* :class:`NightPlan` — one night (constrained or normal), its temperatures and its local window,
  turned into absolute instants (DST-safe); :data:`EMISSION_LAG_H` — the emitter lag.
* :class:`NightSamples` — one night's samples, simulated or measured.
* :func:`read_nights` — NIGHTS.csv → nights.
* :func:`night_features` — THE feature function (units in :data:`NIGHT_FEATURES`).
"""

from .features import (
    NIGHT_FEATURE_NAMES,
    NIGHT_FEATURES,
    Q_ON_W,
    features_from_arrays,
    night_features,
)
from .night import NightKind, NightSamples
from .nights_csv import read_nights, write_nights
from .plan import (
    DEFAULT_BAND_K,
    DEFAULT_CONSTRAINED_SETPOINT_C,
    DEFAULT_PREHEAT_H,
    DEFAULT_SETPOINTS_C,
    DEFAULT_WINDOW,
    EMISSION_LAG_H,
    NIGHT_KINDS,
    NightPlan,
    imp_plans,
)

__all__ = [
    "DEFAULT_BAND_K",
    "DEFAULT_CONSTRAINED_SETPOINT_C",
    "DEFAULT_PREHEAT_H",
    "DEFAULT_SETPOINTS_C",
    "DEFAULT_WINDOW",
    "EMISSION_LAG_H",
    "NIGHT_FEATURES",
    "NIGHT_FEATURE_NAMES",
    "NIGHT_KINDS",
    "NightKind",
    "NightPlan",
    "NightSamples",
    "Q_ON_W",
    "features_from_arrays",
    "imp_plans",
    "night_features",
    "read_nights",
    "write_nights",
]
