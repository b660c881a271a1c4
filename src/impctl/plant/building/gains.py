"""Internal and solar gains over time (RH §4): what the fit does not know.

Internal: ``night_w`` from 22:00 to 07:00 local, ``day_w`` otherwise, times a slow random walk
(SD ``drift_w`` per √h, clipped to 0…2× the level). Solar: a half-sine from 08:00 to 16:00 local
with ``solar_peak_w`` at noon, times a per-day clearness drawn uniformly in 0…1. The solar heat
enters the mass and surface nodes by the ISO split (C.2–C.3), so the afternoon's sun is still
leaving the mass at night.

:func:`internal_gains_w` and :func:`solar_gains_w` build whole series (batch);
:class:`HouseGains` gives the same profiles for one house step by step (the Modbus simulator).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..params import Gains

Array = NDArray[np.float64]

#: Local hours of the night level of internal gains [h].
NIGHT_HOURS = (22.0, 7.0)
#: Rows per block when building (n_steps, n) series in place.
_ROWS = 512
#: Local hours of daylight for the solar profile [h] [own choice, a winter day].
SUN_HOURS = (8.0, 16.0)


def _is_night(h):
    """Night level of the internal gains at local hour ``h`` [h] (float or array)."""
    return (h >= NIGHT_HOURS[0]) | (h < NIGHT_HOURS[1])


def sun_shape(hour_local):
    """Clear-day solar profile at local hour ``hour_local`` [h]: half-sine over
    :data:`SUN_HOURS`, 1 at its middle, 0 outside [-] (float or array)."""
    h = hour_local
    span = SUN_HOURS[1] - SUN_HOURS[0]
    shape = np.clip(np.sin(np.pi * (h - SUN_HOURS[0]) / span), 0.0, None)
    return np.where((h >= SUN_HOURS[0]) & (h <= SUN_HOURS[1]), shape, 0.0)


def internal_gains_w(hour_local: Array, gains: Gains, n: int,
                     rng: np.random.Generator, dt_s: float) -> Array:
    """Internal gains [W], shape (n_steps, n) for local hours ``hour_local`` (n_steps,) or
    (n_steps, n)."""
    h = np.asarray(hour_local, dtype=float)
    h = h[:, None] if h.ndim == 1 else h
    night = _is_night(h)
    night_w = np.broadcast_to(np.asarray(gains.night_w, float), (n,))
    day_w = np.broadcast_to(np.asarray(gains.day_w, float), (n,))
    drift = np.broadcast_to(np.asarray(gains.drift_w, float), (n,))
    # In place and by blocks of rows: this series is n_steps × n houses, the largest array of a
    # population run, and every fresh full-size temporary costs a first touch of its memory.
    # Same operations in the same order as clip(level + drift·walk, 0, 2·level).
    walk = rng.standard_normal((h.shape[0], n))
    np.cumsum(walk, axis=0, out=walk)
    walk *= np.sqrt(dt_s / 3600.0)
    for b in range(0, walk.shape[0], _ROWS):
        w = walk[b:b + _ROWS]
        level = np.where(night[b:b + _ROWS], night_w, day_w)
        np.multiply(drift, w, out=w)
        np.add(level, w, out=w)
        level *= 2.0
        # np.clip with array bounds is several times slower than the two ufuncs it stands for.
        np.maximum(w, 0.0, out=w)
        np.minimum(w, level, out=w)
    return walk


def solar_gains_w(hour_local: Array, day_index: Array, gains: Gains, n: int,
                  rng: np.random.Generator) -> Array:
    """Transmitted solar gains [W], shape (n_steps, n); ``day_index`` (n_steps,) integer day."""
    h = np.asarray(hour_local, dtype=float)
    h = h[:, None] if h.ndim == 1 else h
    days = np.asarray(day_index)
    days = days[:, None] if days.ndim == 1 else days
    shape = sun_shape(h)
    d0 = int(days.min())
    clear = rng.uniform(0.0, 1.0, (int(days.max()) - d0 + 1, n))
    peak = np.broadcast_to(np.asarray(gains.solar_peak_w, float), (n,))
    if days.shape[1] == 1 and shape.shape[1] == 1:
        # One day number and hour per step (the common case): a row lookup, then the
        # (peak·shape)·clearness product by blocks of rows, in place (no full-size temporaries).
        out = clear[(days[:, 0] - d0).astype(int)]
        for b in range(0, out.shape[0], _ROWS):
            np.multiply(peak * shape[b:b + _ROWS], out[b:b + _ROWS], out=out[b:b + _ROWS])
        return out
    return peak * shape * np.take_along_axis(clear, np.broadcast_to(days - d0, shape.shape)
                                             .astype(int), axis=0)


class HouseGains:
    """Internal and solar gains of one house, step by step at local times (as the batch
    functions: the night/day level times a random walk, a half-sine sun times a clearness drawn
    once per local day).

    Parameters
    ----------
    gains : Gains
        The house's gains section (floats).
    seed : int or Generator
        The random walk and the daily clearness.

    Examples
    --------
    >>> g = HouseGains(Gains(), seed=1)
    >>> internal_w, solar_w = g.step(60.0, 23.5 * 3600.0)   # 23:30 local, day 0
    >>> solar_w
    0.0
    """

    def __init__(self, gains: Gains, seed: int | np.random.Generator = 0) -> None:
        self.gains = gains
        self.rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        self._walk = 0.0
        self._day: int | None = None
        self._clear = 0.0

    def step(self, dt_s: float, local_s: float) -> tuple[float, float]:
        """Advance the walk by ``dt_s`` [s]; return (internal, solar) gains [W] at ``local_s``,
        the local clock time in seconds since any local midnight (e.g. the Unix time plus the
        UTC offset): its hour of day picks the levels, its day number the clearness."""
        g = self.gains
        hour = (local_s / 3600.0) % 24.0
        level = float(g.night_w if _is_night(hour) else g.day_w)
        self._walk += float(self.rng.standard_normal()) * math.sqrt(dt_s / 3600.0)
        internal = min(max(level + float(g.drift_w) * self._walk, 0.0), 2.0 * level)
        day = int(local_s // 86400.0)
        if day != self._day:
            self._day, self._clear = day, float(self.rng.uniform())
        return internal, float(g.solar_peak_w) * float(sun_shape(hour)) * self._clear
