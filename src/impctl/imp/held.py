"""Is an auto-cut night an IMP night at all? The held-setpoint test of unlabelled nights.

A NIGHTS file without ``kind`` is cut into 22:00–05:00 windows and each labelled by its first
hour (:func:`impctl.imp.nights_csv.read_nights`). A window may be neither kind: heat pulses
(a pseudo-random binary sequence, a manual test), the heating switched off in the middle of a
held night, or a heater too small to hold the setpoint — the room drifts while heat flows. Such
a night is not used: :func:`not_held` gives the reason, the fit lists it among the skipped
nights (:func:`impctl.fit.nights.data.prepare_nights`).

* **Heat pulses** (needs the ``heating`` column, 1 while the heating is enabled): the heating
  comes on and goes off again inside the window. A constrained night ends once, at its
  resumption (the heating stays on to 05:00), and a held night never goes off.
* **Drift** (normal nights): T_air a held night keeps is its level; the median of the last hour
  differs from the median of the second hour (after the setpoint step settles) by more than
  :data:`HOLD_DRIFT_K`. The twin houses' held nights drift ≤ 0.03 K, their nights heated with a
  constant 500 W that does not hold them 0.35–0.70 K, a heating switched off at 00:10 2.2 K.
"""

from __future__ import annotations

import numpy as np

#: Largest drift of T_air [K] over a held night (last hour's median − second hour's median).
#: A room thermostat's hysteresis (±0.3 K) averages out over an hour; a sensor resolution of
#: 0.1 K moves a median by at most that.
HOLD_DRIFT_K = 0.25


def not_held(kind: str, time_s: np.ndarray, t_air_c: np.ndarray, off: np.ndarray,
             heating_column: bool) -> str:
    """Why an auto-labelled night of ``kind`` is not an IMP night ("" when it is one).

    ``off``: per sample, heating off (the ``heating`` column 0, or without it Q_HC below the
    on threshold); ``heating_column``: whether ``off`` comes from the ``heating`` column (heat
    pulses are only told from switching there: a cycling heat pump's power is not a switch).
    """
    on = ~np.asarray(off, bool)
    if heating_column and len(on) > 2:
        starts = np.flatnonzero(on[1:] & ~on[:-1]) + 1
        ends = np.flatnonzero(~on[1:] & on[:-1]) + 1
        pulses = int(np.sum(ends > (starts[0] if len(starts) else len(on))))
        if pulses:
            return (f"{kind} night by its first hour, but the heating came on and went off "
                    f"again {pulses} time(s) inside the window: heat pulses, neither a held "
                    "nor a constrained night")
        if kind == "normal" and (~on[1:]).any():
            share = float((~on).mean())
            return (f"normal night by its first hour, but the heating was switched off for "
                    f"{100 * share:.0f} % of the window: the setpoint is not held")
    if kind != "normal":
        return ""
    t = np.asarray(time_s, float) - float(time_s[0])
    t_air = np.asarray(t_air_c, float)
    second = t_air[(t >= 3600.0) & (t < 7200.0) & np.isfinite(t_air)]
    last = t_air[(t >= t[-1] - 3600.0) & np.isfinite(t_air)]
    if t[-1] < 3.0 * 3600.0 or not len(second) or not len(last):
        return ""
    drift = float(np.median(last) - np.median(second))
    if abs(drift) > HOLD_DRIFT_K:
        return (f"normal night by its first hour, but T_air drifted {drift:+.2f} K with the "
                f"heating on (more than ±{HOLD_DRIFT_K:g} K): the setpoint is not held")
    return ""
