"""Features of one IMP night, from what the IMP observes: T_air, T_out, Q_HC, T_set and times.

:func:`night_features` is THE feature function. It is a thin wrapper around
:func:`features_from_arrays`, which computes the same features for many nights at once (columns of
2-D arrays); the virtual population calls the array form, measured nights go through
:func:`night_features`, and both run the same arithmetic.

Constrained nights are cut: the emitters are taken to give heat until ``emission_lag_h`` after
the window start (the paper's approximation, :data:`impctl.imp.plan.EMISSION_LAG_H`), so no
feature looks at samples before that; the cooling ends at the first later sample where the heating
is back on (Q_HC > :data:`Q_ON_W`, i.e. T_min reached) or at the end of the samples.

Every night gets every feature; the ones of the other kind are NaN. A feature that needs
``MIN_SAMPLES`` samples and has fewer is NaN. The range classifiers combine a household's nights
(:mod:`impctl.classifiers.campaign`) and use only the features that do not depend on the 5R1C
switch-off artefact; the reasons are given there.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .night import NightSamples
from .plan import EMISSION_LAG_H
from .protocol import Q_ON_W

__all__ = ["Q_ON_W"]  # re-exported: Q_ON_W lives with the protocol (the gateway reads it too)
#: Fewest samples a mean, slope or decay fit is computed from.
MIN_SAMPLES = 3
#: Span [h] after the cut of the early decay rate: the same span on every constrained night
#: that lasts that long, whether it stops at T_min or at the window's end (the whole-night
#: decay rate and cooling time are censored by where the night stops).
EARLY_SPAN_H = 2.0

#: (name, unit, meaning) of every night feature, in column order.
NIGHT_FEATURES: tuple[tuple[str, str, str], ...] = (
    ("is_constrained", "1", "1 for a constrained (heating-off) night, 0 for a normal night"),
    ("t_out_mean_c", "°C", "mean outdoor temperature over the used samples"),
    ("cooling_time_h", "h", "constrained: time from the cut (start + emitter lag) to T_min "
                            "(heating back on) or to the last sample; 0 when the night ended "
                            "within the lag"),
    ("delta_t_air_k", "K", "constrained: T_air at the cut minus T_air at the end of cooling"),
    ("cooling_rate_k_per_h", "K/h", "constrained: delta_t_air_k / cooling_time_h"),
    ("dtheta_start_k", "K", "constrained: T_air − T_out at the cut"),
    ("decay_rate_per_h", "1/h", "constrained: k of dT_air/dt = −k·(T_air − T_out), fitted by "
                                "least squares of T_air on ∫(T_air − T_out)dt (≈ 1/τ)"),
    ("decay_rate_early_per_h", "1/h", "constrained: decay_rate_per_h over the first EARLY_SPAN_H "
                                      "(2 h) after the cut only"),
    ("t_set_c", "°C", "normal: T_set (the median T_air when the setpoint is unknown)"),
    ("q_hc_mean_w", "W", "normal: mean heat output Q_HC"),
    ("q_per_k_w_per_k", "W/K", "normal: mean Q_HC / mean (T_air − T_out), a one-night HLC"),
    ("q_slope_w_per_h", "W/h", "normal: least-squares slope of Q_HC over time"),
    ("q_per_t_out_w_per_k", "W/K", "normal: −least-squares slope of Q_HC on T_out within the "
                                   "night (how fast the heat output follows the weather)"),
)
NIGHT_FEATURE_NAMES: tuple[str, ...] = tuple(f[0] for f in NIGHT_FEATURES)


def _masked_mean(x: NDArray, use: NDArray, n: NDArray) -> NDArray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(use, x, 0.0).sum(axis=0) / n


def _masked_slope(x: NDArray, y: NDArray, use: NDArray) -> NDArray:
    """Least-squares slope dy/dx per column over the samples in ``use`` (NaN below MIN_SAMPLES)."""
    n = use.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        xm = np.where(use, x, 0.0).sum(axis=0) / n
        ym = np.where(use, y, 0.0).sum(axis=0) / n
        dx = np.where(use, x - xm, 0.0)
        sxx = (dx * dx).sum(axis=0)
        sxy = (dx * np.where(use, y - ym, 0.0)).sum(axis=0)
        slope = sxy / sxx
    return np.where((n >= MIN_SAMPLES) & (sxx > 0), slope, np.nan)


def features_from_arrays(
    time_s: ArrayLike,
    t_air_c: ArrayLike,
    t_out_c: ArrayLike,
    q_hc_w: ArrayLike,
    *,
    constrained: ArrayLike,
    setpoint_c: ArrayLike,
    valid: ArrayLike | None = None,
    emission_lag_h: float = EMISSION_LAG_H,
) -> dict[str, NDArray[np.float64]]:
    """Night features of many nights at once; one column per night.

    Parameters
    ----------
    time_s : array (n_samples,) or (n_samples, n_nights)
        Sample times since each window's start [s], increasing down the columns.
    t_air_c, t_out_c : array (n_samples, n_nights)
        Indoor air and outdoor temperature [°C].
    q_hc_w : array (n_samples, n_nights)
        Heat output of the heating [W].
    constrained : bool array (n_nights,)
        True for constrained nights, False for normal nights.
    setpoint_c : array (n_nights,)
        T_set per night [°C]; NaN if unknown.
    valid : bool array (n_samples, n_nights), optional
        Which entries are samples (nights of different lengths share one array); default all.
    emission_lag_h : float
        Emitter lag [h]: constrained-night samples before it are not used.

    Returns
    -------
    dict
        Feature name → array (n_nights,), in :data:`NIGHT_FEATURE_NAMES` order.
    """
    t_air = np.asarray(t_air_c, dtype=float)
    if t_air.ndim != 2:
        raise ValueError("t_air_c must be 2-D (n_samples, n_nights)")
    shape = t_air.shape
    t_out = np.broadcast_to(np.asarray(t_out_c, dtype=float), shape)
    q = np.broadcast_to(np.asarray(q_hc_w, dtype=float), shape)
    time = np.asarray(time_s, dtype=float)
    time = np.broadcast_to(time[:, None] if time.ndim == 1 else time, shape)
    cons = np.broadcast_to(np.asarray(constrained, dtype=bool), shape[1:])
    sp = np.broadcast_to(np.asarray(setpoint_c, dtype=float), shape[1:])
    ok = np.ones(shape, bool) if valid is None else np.broadcast_to(np.asarray(valid, bool), shape)
    ok = ok & np.isfinite(t_air) & np.isfinite(t_out) & np.isfinite(q)
    cols = np.arange(shape[1])

    # Constrained: from the emitter lag on, until the heating is back on (the night's end).
    after_lag = ok & (time >= emission_lag_h * 3600.0 - 1e-6)
    resumed = np.cumsum(after_lag & (q > Q_ON_W), axis=0) > 0
    use = np.where(cons[None, :], after_lag & ~resumed, ok)
    n = use.sum(axis=0)
    enough = n >= MIN_SAMPLES
    first = np.argmax(use, axis=0)
    last = shape[0] - 1 - np.argmax(use[::-1], axis=0)
    dtheta = t_air - t_out

    t_out_mean = np.where(n > 0, _masked_mean(t_out, use, n), np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        span_h = np.where(n > 0, (time[last, cols] - time[first, cols]) / 3600.0, 0.0)
        delta_air = t_air[first, cols] - t_air[last, cols]
        # Integrated form of dT_air/dt = −k·(T_air − T_out): T_air falls by k per K·h of
        # indoor–outdoor difference. Integrating averages out the 0.1 K quantisation that
        # sample-to-sample differences would amplify, and follows a drifting T_out.
        pair = use[:-1] & use[1:]
        step_kh = np.where(pair, 0.5 * (dtheta[:-1] + dtheta[1:]) * np.diff(time, axis=0), 0.0)
        exposure_kh = np.concatenate([np.zeros((1, shape[1])), np.cumsum(step_kh, 0)]) / 3600.0
        decay = -_masked_slope(exposure_kh, t_air, use)
        early = use & (time < (emission_lag_h + EARLY_SPAN_H) * 3600.0 - 1e-6)
        decay_early = -_masked_slope(exposure_kh, t_air, early)
        q_mean = _masked_mean(q, use, n)
        q_per_k = q_mean / _masked_mean(dtheta, use, n)
        rate = delta_air / span_h
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns → NaN, as wanted
        median_air = np.nanmedian(np.where(use, t_air, np.nan), axis=0)
    c_ok = cons & enough
    n_ok = ~cons & enough
    nan = np.full(shape[1], np.nan)
    return {
        "is_constrained": cons.astype(float),
        "t_out_mean_c": t_out_mean,
        "cooling_time_h": np.where(cons, span_h, nan),
        "delta_t_air_k": np.where(c_ok, delta_air, nan),
        "cooling_rate_k_per_h": np.where(c_ok & (span_h > 0), rate, nan),
        "dtheta_start_k": np.where(cons & (n > 0), dtheta[first, cols], nan),
        "decay_rate_per_h": np.where(cons, decay, nan),
        "decay_rate_early_per_h": np.where(cons, decay_early, nan),
        "t_set_c": np.where(~cons, np.where(np.isfinite(sp), sp, median_air), nan),
        "q_hc_mean_w": np.where(n_ok, q_mean, nan),
        "q_per_k_w_per_k": np.where(n_ok, q_per_k, nan),
        "q_slope_w_per_h": np.where(~cons, _masked_slope(time / 3600.0, q, use), nan),
        "q_per_t_out_w_per_k": np.where(~cons, -_masked_slope(t_out, q, use), nan),
    }


def night_features(night: NightSamples, emission_lag_h: float = EMISSION_LAG_H) -> dict[str, float]:
    """The feature row of one night (simulated or measured).

    Parameters
    ----------
    night : NightSamples
    emission_lag_h : float, default :data:`~impctl.imp.plan.EMISSION_LAG_H`
        Emitter lag [h]; constrained-night samples before it are not used.

    Returns
    -------
    dict
        Feature name → value, every name of :data:`NIGHT_FEATURE_NAMES` (units there); NaN where
        a feature does not apply to the night's kind or the night has too few samples.
    """
    col = lambda a: np.asarray(a, dtype=float).reshape(-1, 1)  # noqa: E731
    values = features_from_arrays(
        np.asarray(night.time_s, dtype=float),
        col(night.t_air_c),
        col(night.t_out_c),
        col(night.q_hc_w),
        constrained=np.array([night.kind == "constrained"]),
        setpoint_c=np.array([night.setpoint_c], dtype=float),
        emission_lag_h=emission_lag_h,
    )
    return {name: float(values[name][0]) for name in NIGHT_FEATURE_NAMES}
