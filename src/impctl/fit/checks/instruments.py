"""The instruments' uncertainty a fit cannot see in the nights: declared, else assumed.

An offset of the indoor or the outdoor sensor, and the heat meter's gain error, shift every
night alike; no night reveals them, so they enter the intervals as type-B shares
(:func:`impctl.fit.intervals.uncertainty.offset_allowance`). The installer may know them (a
calibrated sensor, a class-2 meter, the electric power of resistive heaters): then they are
declared (``impctl fit --t-air-offset-sd-k``, ``--t-out-offset-sd-k``, ``--meter-error``,
``[fit]`` keys of the same names); else these assumptions are used and said to be assumed.
Pure constants and arithmetic: the daemon's config and the CLI import them without numpy.
"""

from __future__ import annotations

from collections.abc import Sequence

#: SD of an uncalibrated indoor and outdoor sensor's offset [K] when nobody says better
#: (real-houses.md §3: ±0.2–1 K accuracy, and placement; an outdoor sensor in sun or on a
#: warm wall is worse).
ASSUMED_SENSOR_OFFSETS_K = (0.5, 1.0)
#: Half-width of the heat meter's systematic error when nobody says better: class 3 (±5 %).
ASSUMED_METER_ERROR = 0.05
#: What a declared offset SD [K] may be.
SENSOR_OFFSET_LIMITS_K = (0.0, 5.0)
#: What a declared meter error (a fraction) may be: 0 (exact) to ±20 %.
METER_ERROR_LIMITS = (0.0, 0.2)


def instruments(sensor_offsets_k: Sequence[float | None] | None, meter_error: float | None
                ) -> tuple[tuple[float, float], float, dict[str, str]]:
    """The sensors' offset SDs [K] and the meter's error a fit uses, each as declared (a
    number) or, where None, the assumption (:data:`ASSUMED_SENSOR_OFFSETS_K`,
    :data:`ASSUMED_METER_ERROR`); and per value its source, "declared" or "assumed"."""
    given = (None, None) if sensor_offsets_k is None else tuple(sensor_offsets_k)
    offsets = (float(ASSUMED_SENSOR_OFFSETS_K[0] if given[0] is None else given[0]),
               float(ASSUMED_SENSOR_OFFSETS_K[1] if given[1] is None else given[1]))
    sources = {"t_air_offset": "assumed" if given[0] is None else "declared",
               "t_out_offset": "assumed" if given[1] is None else "declared",
               "meter_error": "assumed" if meter_error is None else "declared"}
    meter = float(ASSUMED_METER_ERROR if meter_error is None else meter_error)
    return offsets, meter, sources
