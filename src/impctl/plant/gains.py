"""Internal and solar gains over time (RH §4): what the fit does not know.

Internal: ``night_w`` from 22:00 to 07:00 local, ``day_w`` otherwise, times a slow random walk
(SD ``drift_w`` per √h, clipped to 0…2× the level). Solar: a half-sine from 08:00 to 16:00 local
with ``solar_peak_w`` at noon, times a per-day clearness drawn uniformly in 0…1. The solar heat
enters the mass and surface nodes by the ISO split (C.2–C.3), so the afternoon's sun is still
leaving the mass at night.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .params import Gains

Array = NDArray[np.float64]

#: Local hours of the night level of internal gains [h].
NIGHT_HOURS = (22.0, 7.0)
#: Local hours of daylight for the solar profile [h] [own choice, a winter day].
SUN_HOURS = (8.0, 16.0)


def internal_gains_w(hour_local: Array, gains: Gains, n: int,
                     rng: np.random.Generator, dt_s: float) -> Array:
    """Internal gains [W], shape (n_steps, n) for local hours ``hour_local`` (n_steps,) or
    (n_steps, n)."""
    h = np.asarray(hour_local, dtype=float)
    h = h[:, None] if h.ndim == 1 else h
    night = (h >= NIGHT_HOURS[0]) | (h < NIGHT_HOURS[1])
    level = np.where(night, np.broadcast_to(np.asarray(gains.night_w, float), (n,)),
                     np.broadcast_to(np.asarray(gains.day_w, float), (n,)))
    drift = np.broadcast_to(np.asarray(gains.drift_w, float), (n,))
    walk = np.cumsum(rng.standard_normal((h.shape[0], n)), axis=0) * np.sqrt(dt_s / 3600.0)
    return np.clip(level + drift * walk, 0.0, 2.0 * level)


def solar_gains_w(hour_local: Array, day_index: Array, gains: Gains, n: int,
                  rng: np.random.Generator) -> Array:
    """Transmitted solar gains [W], shape (n_steps, n); ``day_index`` (n_steps,) integer day."""
    h = np.asarray(hour_local, dtype=float)
    h = h[:, None] if h.ndim == 1 else h
    days = np.asarray(day_index)
    days = days[:, None] if days.ndim == 1 else days
    span = SUN_HOURS[1] - SUN_HOURS[0]
    shape = np.clip(np.sin(np.pi * (h - SUN_HOURS[0]) / span), 0.0, None)
    shape = np.where((h >= SUN_HOURS[0]) & (h <= SUN_HOURS[1]), shape, 0.0)
    d0 = int(days.min())
    clear = rng.uniform(0.0, 1.0, (int(days.max()) - d0 + 1, n))
    peak = np.broadcast_to(np.asarray(gains.solar_peak_w, float), (n,))
    return peak * shape * np.take_along_axis(clear, np.broadcast_to(days - d0, shape.shape)
                                             .astype(int), axis=0)
