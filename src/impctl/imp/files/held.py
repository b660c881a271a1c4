"""Is an auto-cut night an IMP night at all? The held-setpoint test of unlabelled nights.

A NIGHTS file without ``kind`` is cut into 22:00–05:00 windows and each labelled by its first
hour (:func:`impctl.imp.files.nights_csv.read_nights`). A window may be neither kind: heat pulses
(a pseudo-random binary sequence, a manual test), the heating switched off in the middle of a
held night, or a heater too small to hold the setpoint — the room drifts while heat flows. Such
a night is not used: :func:`not_held` gives the reason, the fit lists it among the skipped
nights (:func:`impctl.fit.nights.data.prepare_nights`).

* **Heat pulses** (needs the ``heating`` column, 1 while the heating is enabled): the heating
  comes on and goes off again inside the window. A constrained night ends once, at its
  resumption (the heating stays on to 05:00), and a held night never goes off.
* **Falling under a fixed heat input** (normal nights): the median T_air of the last hour is
  more than :data:`HOLD_DRIFT_K` below that of the second hour (after the setpoint step)
  while the heat power stays fixed (coefficient of variation under :data:`FIXED_POWER_CV`: no
  controller is acting), or more than :data:`FALL_MAX_K` below whatever the power did. The
  twin houses' held nights move ≤ 0.03 K; their nights heated with a constant 500 W that does
  not hold them fall 0.31–0.75 K; a heating switched off at 00:10 falls 2.2 K. A climbing
  T_air is a held night charging after a setpoint step, and a controller's varying power
  while T_air falls is a weather curve following the night: both are used. On the realistic
  plant's held nights (50 households, 300 nights, ``bench/fit.py``'s population) this drops
  none; a test on T_air alone (|drift| > 0.25 K) would drop 158 of them.
"""

from __future__ import annotations

import numpy as np

#: Largest fall of T_air [K] over a held night under a fixed heat input (second hour's median
#: − last hour's). A room thermostat's hysteresis (±0.3 K) averages out over an hour; a sensor
#: resolution of 0.1 K moves a median by at most that.
HOLD_DRIFT_K = 0.25
#: Coefficient of variation of the heat power below which no controller is acting [-]: the
#: twin houses' pseudo-random sequence's 500 W has 0.00; their thermostat-held resistive
#: heaters 0.01–0.09 (while T_air stays); a heat pump's held night ≥ 0.28.
FIXED_POWER_CV = 0.15
#: A fall of T_air [K] over a night with the heating on that no held night shows.
FALL_MAX_K = 1.0


def not_held(kind: str, time_s: np.ndarray, t_air_c: np.ndarray, off: np.ndarray,
             heating_column: bool, q_hc_w: np.ndarray | None = None) -> str:
    """Why an auto-labelled night of ``kind`` is not an IMP night ("" when it is one).

    ``off``: per sample, heating off (the ``heating`` column 0, or without it Q_HC below the
    on threshold); ``heating_column``: whether ``off`` comes from the ``heating`` column (heat
    pulses are only told from switching there: a cycling heat pump's power is not a switch);
    ``q_hc_w``: the heat power [W] (whether it is fixed while T_air falls).
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
    fall = float(np.median(second) - np.median(last))
    q = (np.asarray(q_hc_w, float)[t >= 3600.0] if q_hc_w is not None else np.zeros(0))
    q = q[np.isfinite(q)]
    cv = float(np.std(q) / np.mean(q)) if len(q) and np.mean(q) > 0 else float("inf")
    if fall > HOLD_DRIFT_K and cv < FIXED_POWER_CV:
        return (f"normal night by its first hour, but T_air fell {fall:.2f} K under a fixed "
                f"heat input ({np.mean(q):.0f} W ± {100 * cv:.0f} %): the setpoint is not held")
    if fall > FALL_MAX_K:
        return (f"normal night by its first hour, but T_air fell {fall:.2f} K with the "
                "heating on: the setpoint is not held")
    return ""
