"""What the gateway reads: room and outdoor sensors, heat meter (RH §5).

* Room: the air temperature at one point and one instant, through the housing's first-order lag
  (τ = ``t_air_lag_s``), plus a placement offset, Gaussian noise and rounding to the resolution.
* Outdoor: the true T_out plus an offset and noise, rounded to 0.1 K (the Kronoterm register).
* Heat meter: the heat pump's thermal output × (1 + systematic error + per-sample noise); with
  ``meter_positive_only`` negative heat (defrost) reads 0.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..params import Sensors

Array = NDArray[np.float64]

#: Resolution of the outdoor-temperature register [K].
T_OUT_QUANTUM_K = 0.1
#: Steps of noise drawn at once.
_BLOCK = 256


def quantise(x: Array, quantum: Array) -> Array:
    """Round to multiples of ``quantum`` (0 = no rounding)."""
    q = np.asarray(quantum, dtype=float)
    if np.all(q > 0):
        return np.round(x / q) * q
    safe = np.where(q > 0, q, 1.0)
    return np.where(q > 0, np.round(x / safe) * safe, x)


class SensorBank:
    """The sensors of ``n`` houses; :meth:`read` once per step."""

    def __init__(self, sensors: Sensors, n: int, rng: np.random.Generator) -> None:
        def b(v):
            return np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()

        self.rng = rng
        self.n = n
        self.noise, self.quantum = b(sensors.t_air_noise_k), b(sensors.t_air_quantum_k)
        self.lag_s, self.offset = b(sensors.t_air_lag_s), b(sensors.t_air_offset_k)
        self.out_noise, self.out_offset = b(sensors.t_out_noise_k), b(sensors.t_out_offset_k)
        self.meter_gain = 1.0 + b(sensors.meter_gain_error)
        self.meter_noise = b(sensors.meter_noise)
        self.positive_only = b(sensors.meter_positive_only) > 0
        self.any_air_noise = bool(np.any(self.noise > 0))
        self.any_out_noise = bool(np.any(self.out_noise > 0))
        self.any_meter_noise = bool(np.any(self.meter_noise > 0))
        self.all_positive = bool(self.positive_only.all())
        self.any_positive = bool(self.positive_only.any())
        self.all_quantised = bool(np.all(self.quantum > 0))
        self.any_quantised = bool(np.any(self.quantum > 0))
        self.lagged: Array | None = None
        self.alpha: Array | None = None
        self._alpha_dt = -1.0
        self._noise = np.empty((0, 3, n))
        self._k = 0

    def _draw(self) -> Array:
        """Standard normals for (air, out, meter) of one step, drawn in blocks for speed."""
        if self._k >= len(self._noise):
            # float32: the noise needs no more digits, and draws twice as fast.
            self._noise = self.rng.standard_normal((_BLOCK, 3, self.n), dtype=np.float32)
            self._k = 0
        self._k += 1
        return self._noise[self._k - 1]

    def reset(self, t_air_c: Array) -> None:
        """Start the sensor housing at ``t_air_c`` [°C]."""
        self.lagged = np.broadcast_to(np.asarray(t_air_c, dtype=float), (self.n,)).copy()

    def read(self, dt: float, t_air_c: Array, t_out_c: Array,
             heat_w: Array) -> tuple[Array, Array, Array]:
        """Advance the lag by ``dt`` s → (T_air sensed [°C], T_out sensed [°C], heat [W])."""
        if self.lagged is None:
            self.reset(t_air_c)
        if dt != self._alpha_dt:
            self.alpha = np.where(self.lag_s > 0,
                                  -np.expm1(-dt / np.maximum(self.lag_s, 1e-9)), 1.0)
            self._alpha_dt = dt
        self.lagged = self.lagged + self.alpha * (t_air_c - self.lagged)
        air = self.lagged + self.offset
        noisy = self.any_air_noise or self.any_out_noise or self.any_meter_noise
        z = self._draw() if noisy else None
        if self.any_air_noise:
            air = air + self.noise * z[0]
        out = t_out_c + self.out_offset
        if self.any_out_noise:
            out = out + self.out_noise * z[1]
        heat = heat_w * self.meter_gain
        if self.any_meter_noise:
            heat = heat * (1.0 + self.meter_noise * z[2])
        if self.all_positive:
            heat = np.maximum(heat, 0.0)
        elif self.any_positive:
            heat = np.where(self.positive_only, np.maximum(heat, 0.0), heat)
        out = np.round(out * (1.0 / T_OUT_QUANTUM_K)) * T_OUT_QUANTUM_K
        if self.all_quantised:
            air = np.round(air / self.quantum) * self.quantum
        elif self.any_quantised:
            air = quantise(air, self.quantum)
        return air, out, heat
