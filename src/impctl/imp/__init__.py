"""The Identification Measurement Procedure: night plans, measured-night data, features.

* :class:`NightPlan` — one night (constrained or normal), its temperatures and its local window,
  turned into absolute instants (DST-safe); :data:`EMISSION_LAG_H` — the emitter lag.
* :class:`NightSamples` — one night's samples, simulated or measured.
* :func:`read_nights` — NIGHTS.csv → nights.
* :func:`night_features` — THE feature function (units in :data:`NIGHT_FEATURES`).
* :mod:`.protocol` — the night protocol's constants, shared by the gateway, the population
  and the fit; :mod:`.gain` — what is assumed of the unmetered night gain; :mod:`.tables` —
  strict CSV tables.

Names are resolved on first use (lazy_loader): the daemon imports the protocol's constants
without numpy or pandas.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "features": ["NIGHT_FEATURE_NAMES", "NIGHT_FEATURES", "Q_ON_W", "features_from_arrays",
                 "night_features"],
    "night": ["NightKind", "NightSamples"],
    "files.nights_csv": ["read_nights", "write_nights"],
    "plan": ["DEFAULT_BAND_K", "DEFAULT_CONSTRAINED_SETPOINT_C", "DEFAULT_PREHEAT_H",
             "DEFAULT_SETPOINTS_C", "DEFAULT_WINDOW", "EMISSION_LAG_H", "NIGHT_KINDS",
             "NightPlan", "imp_plans"],
})
