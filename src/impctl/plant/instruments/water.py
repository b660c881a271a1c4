"""The heat pump's own flow and return sensors, as the gateway reads them over a season.

Each sensor is off by an offset of its own (a contact sensor on a pipe, within ± a fraction of
a kelvin), and the spread between them follows a circulation flow that wanders from day to day
(a valve or a thermostat changes the flow; the heat and the mean water temperature stay the
plant's). The sensors' lag is the plant's business, step by step; this reads whole series.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from numpy.typing import NDArray

Array = NDArray[np.float64]

#: Day-to-day persistence of the circulation's flow (an AR(1) of its log) [-].
FLOW_PERSISTENCE = 0.7


def water_sensors(flow_c: Array, return_c: Array, index: pd.DatetimeIndex, tz: str,
                  offset_k: float, flow_wander: float, seed: int) -> tuple[Array, Array]:
    """(flow, return) [°C] as the sensors read ``flow_c`` and ``return_c`` (rows × households,
    rows at ``index``): each sensor off by a uniform offset within ±``offset_k`` [K], the
    spread scaled by exp(−x) with x the flow's log wander, an AR(1) over local days (``tz``)
    of stationary SD ``flow_wander`` [-] and persistence :data:`FLOW_PERSISTENCE`. Drawn from a
    generator of its own (``seed``), so whatever else a simulation draws stays the same."""
    n_rows, n = flow_c.shape
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5EA5, 2]))
    off_f, off_r = (rng.uniform(-offset_k, offset_k, n) for _ in range(2))
    local = index.tz_convert(tz).tz_localize(None).normalize()
    day = ((local - local[0]) // pd.Timedelta(days=1)).to_numpy(dtype=int)
    x = np.zeros((day[-1] + 1 if n_rows else 0, n))
    eps = rng.normal(0.0, flow_wander, x.shape)
    for d in range(len(x)):
        x[d] = eps[d] if d == 0 else (FLOW_PERSISTENCE * x[d - 1]
                                      + np.sqrt(1 - FLOW_PERSISTENCE ** 2) * eps[d])
    mid, spread = (flow_c + return_c) / 2.0, (flow_c - return_c) * np.exp(-x[day])
    return mid + spread / 2.0 + off_f, mid - spread / 2.0 + off_r
