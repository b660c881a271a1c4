"""How the gateway ends and keeps a constrained night, for the simulated nights (no torch).

The gateway (:mod:`impctl.controller`) ends a constrained night when the room sensor reads
T_min = T_set − ΔT, or earlier when the T_air trend reaches T_min within half an hour
(:func:`impctl.controller.plan.anticipated_end`), never switches off when the pre-heat fell
short (:func:`impctl.controller.plan.preheat_short`), restores the owner's setpoint, and counts
the night valid with :data:`~impctl.imp.protocol.MIN_NIGHT_H` of data after the emission lag
(:func:`impctl.controller.assess.assess_night`); an invalid one is repeated, up to
``campaign.max_invalid_nights``. The same rules on simulated nights, vectorised over houses, read
from :mod:`impctl.imp.protocol` as the controller's (issue 14, branch h14w):
:func:`gateway_end`, :func:`with_gateway_stops` (used by
:func:`impctl.population.imp_run.synth.run_schedule` and ``run_schedule_plant``) and
:func:`gateway_constrained_nights`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ...imp.protocol import (
    MIN_NIGHT_H,
    MIN_TREND_SPAN_S,
    SWITCH_OFF_MIN_K,
    TREND_WINDOW_S,
    anticipates_t_min,
)

if TYPE_CHECKING:
    from .setup import SynthSchedule


def gateway_end(t_air_c: np.ndarray, dt_s: float, t_min_c: float, lag: int,
                anticipate: bool = True, t_start_c: np.ndarray | None = None) -> np.ndarray:
    """Step (from switch-off, per house) at which the gateway ends a constrained night, or
    ``len(t_air_c)`` where it runs to the window's end.

    ``t_air_c`` (n_steps, n_houses) [°C]: the room sensor from the window's start, one reading
    per step of ``dt_s`` [s] (the gateway reads once a minute). The night ends at the first step
    after ``lag`` steps where T_air ≤ ``t_min_c`` or, with ``anticipate``, where T_air is within
    :data:`~impctl.imp.protocol.ANTICIPATE_WITHIN_K` of T_min and the least-squares trend
    since switch-off, over the last :data:`~impctl.imp.protocol.TREND_WINDOW_S` (at least
    :data:`~impctl.imp.protocol.MIN_TREND_SPAN_S`), reaches it within
    :data:`~impctl.imp.protocol.ANTICIPATE_S` (:func:`impctl.controller.plan.anticipated_end`).
    At step 0 where T_air at the window's start (``t_start_c``, default the first reading) is
    < T_min + :data:`~impctl.imp.protocol.SWITCH_OFF_MIN_K`: the gateway never switches off
    (:func:`impctl.controller.plan.preheat_short`).
    """
    v = np.atleast_2d(np.asarray(t_air_c, float).T).T
    n = v.shape[0]
    end = v <= t_min_c
    if anticipate and n > 1:
        # Trend over readings k-w..k (now − t ≤ window), in steps; sums by cumulative sums.
        w = int(round(TREND_WINDOW_S / dt_s))
        k = np.arange(n, dtype=float)[:, None]
        first = np.maximum(0.0, k - w)
        cnt = k - first + 1.0

        def window_sum(x):
            c = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
            return c[1:] - c[first[:, 0].astype(int)]

        kk = np.broadcast_to(k, v.shape)
        s_t, s_v = window_sum(kk), window_sum(v)
        s_tt, s_tv = window_sum(kk * kk), window_sum(kk * v)
        den = s_tt - s_t * s_t / cnt
        with np.errstate(invalid="ignore", divide="ignore"):
            slope = np.where(den > 0, (s_tv - s_t * s_v / cnt) / den, 0.0) / dt_s   # K/s
        end |= ((k - first) * dt_s >= MIN_TREND_SPAN_S) & anticipates_t_min(v, slope, t_min_c)
    end[:lag] = False
    stop = np.where(end.any(axis=0), end.argmax(axis=0), n)
    start = v[0] if t_start_c is None else np.asarray(t_start_c, float)
    return np.where(start < t_min_c + SWITCH_OFF_MIN_K, 0, stop)


def _stopped_at_t_min(t_air_c: np.ndarray, w0: int, w1: int, t_min_c: float, lag: int,
                      after_c, dt_s: float = 60.0, anticipate: bool = True) -> np.ndarray:
    """A constrained window's setpoints (steps w0:w1, per house) when it ends as the gateway
    ends it (:func:`gateway_end` on ``t_air_c`` [°C] from step ``w0``, the last reading before
    the window deciding the switch-off): off (NaN) until the end, ``after_c`` [°C] from there."""
    v = np.atleast_2d(np.asarray(t_air_c).T).T
    first = gateway_end(v[w0:w1], dt_s, t_min_c, lag, anticipate, v[max(w0 - 1, 0)])
    steps = np.arange(w1 - w0)[:, None]
    return np.where(steps >= first[None, :], after_c, np.nan)


def with_gateway_stops(run, t_air_of, sched: SynthSchedule, emission_lag_h: float,
                        anticipate: bool):
    """Run the schedule with each constrained night ended as the gateway ends it: nights in
    order, one re-simulation per night (the simulation is causal, so what precedes a stop is
    the open-loop night); after the stop the day setpoint, as the gateway restores the owner's.
    ``run(sp)`` simulates, ``t_air_of(result)`` [°C] is what the gateway's room sensor read."""
    sp = sched.setpoint_c.copy()
    result = run(sp)
    lag = int(round(emission_lag_h * 3600 / sched.dt_s))
    for _, kind, w0, w1, t_set in sched.windows:
        if kind != "constrained":
            continue
        sp[w0:w1] = _stopped_at_t_min(t_air_of(result), w0, w1, t_set - sched.band_k, lag,
                                      sched.t_m_init_c, sched.dt_s, anticipate)
        result = run(sp)
    return result, sp



def gateway_constrained_nights(sp: np.ndarray, sched: SynthSchedule, n_needed: int = 2,
                               max_invalid: int = 3, lag_h: float = 1.0,
                               need_h: float = MIN_NIGHT_H) -> dict[str, np.ndarray]:
    """Which constrained nights a gateway's campaign runs and keeps, per house.

    The constrained windows are taken in order (the planned ones, then the schedule's spares): a
    night is valid with ≥ ``need_h`` [h] of data after switch-off + ``lag_h`` [h] (the gateway's
    :func:`impctl.controller.assess.assess_night`); the campaign runs them until ``n_needed`` are
    valid or ``max_invalid`` ended invalid (``campaign.max_invalid_nights``). ``sp``: the
    setpoints used (NaN = heating off). Returns arrays (n_constrained, n_houses): ``usable_h``
    [h] after the lag, ``run`` (the night was run), ``used`` (run and valid: given to the fit);
    and per house ``paid`` (constrained nights run).
    """
    usable = []
    for _, kind, w0, w1, _ in sched.windows:
        if kind != "constrained":
            continue
        on = ~np.isnan(sp[w0:w1])
        span_h = np.where(on.any(axis=0), on.argmax(axis=0), w1 - w0) * sched.dt_s / 3600.0
        usable.append(span_h - lag_h)
    usable_h = np.array(usable)
    valid = usable_h >= need_h - 1e-9
    run = campaign_runs(valid, n_needed, max_invalid)
    return {"usable_h": usable_h, "run": run, "used": run & valid, "paid": run.sum(axis=0)}


def campaign_runs(valid: np.ndarray, n_needed: int = 2, max_invalid: int = 3) -> np.ndarray:
    """Which nights a gateway's campaign runs, taking them in order (axis 0): until
    ``n_needed`` were valid or ``max_invalid`` were not (``campaign.max_invalid_nights``).
    ``valid``: bool (n_nights, ...) — each night's verdict had it been run."""
    valid = np.asarray(valid, bool)
    run = np.zeros_like(valid)
    n_valid = np.zeros(valid.shape[1:], int)
    n_bad = np.zeros(valid.shape[1:], int)
    for j in range(valid.shape[0]):
        run[j] = (n_valid < n_needed) & (n_bad < max_invalid)
        n_valid += run[j] & valid[j]
        n_bad += run[j] & ~valid[j]
    return run
