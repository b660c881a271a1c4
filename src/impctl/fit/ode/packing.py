"""Nights side by side for the batched night model: :class:`PackedNights` (padded to the longest
night, inputs smoothed, the two timestamp conventions) and :func:`pack_nights`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from scipy.special import chdtri

from ...imp.night import NightSamples
from ..nights.quality import reading_noise, residual_blocks, t_air_resolution_k
from .parameters import DTYPE, FURNITURE_TAU_S

TIMESTAMPS = ("instant", "interval")


def rows_at(x: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """``x[index]`` for a 1-D integer index of ``x``'s first dimension, by ``index_select``:
    the same values, two to three times faster than advanced indexing on a CPU (the fit
    gathers each night's arrays for its rows many times per iteration)."""
    return x.index_select(0, index)


@dataclass
class PackedNights:
    """Nights side by side (tensors float64; N nights, K nodes = the longest night's samples).

    Attributes
    ----------
    night_ids, kinds : per night
    timestamps : "instant" or "interval" (see :func:`pack_nights`)
    grid_s : (N, K) node times [s] from each night's fit start: the night's own samples,
        the last one repeated after its end
    t_out_c, t_air_c : (N, K) values at the nodes [°C] (held after a night's last sample)
    t_out_slope, t_air_slope : (N, K) slope on the interval that starts at node k [K/s]
    t_air_in_c, t_air_in_slope : (N, K) the smoothed T_air that drives DEMAND rows, and its slope
    q_w : (N, K) heat power belonging to node k [W] (the value a sample reports)
    q_in_w : (N, K) mean heat power over the interval that starts at node k [W]
    q_mean_w : (N,) mean power over the night [W] (time-weighted)
    t_fur_slope : (N, K) dT_fur/dt [K/s] of a node that follows the (30-min smoothed) measured
        T_air with the time constant :data:`FURNITURE_TAU_S`
    mask : (N, K) bool, node k is one of the night's samples
    next_node : (N, K) long, index of the night's next sample (itself for the last one)
    last : (N, K) bool, node k is the night's last sample
    """

    night_ids: list[str]
    kinds: list[str]
    timestamps: str
    grid_s: torch.Tensor
    t_out_c: torch.Tensor
    t_out_slope: torch.Tensor
    t_air_c: torch.Tensor
    t_air_slope: torch.Tensor
    t_air_in_c: torch.Tensor
    t_air_in_slope: torch.Tensor
    q_w: torch.Tensor
    q_in_w: torch.Tensor
    q_mean_w: torch.Tensor
    t_fur_slope: torch.Tensor
    mask: torch.Tensor
    next_node: torch.Tensor
    last: torch.Tensor
    power_ok: torch.Tensor | None = None  # (N, K) bool: the power sample can be compared
    #: the meter measures the heat into an emitter node that holds ``emitter_share`` of C_m
    #: (``NightFit(emitter_lag=True)``, :func:`build_rows`)
    emitter_lag: bool = False
    #: (N,) a night's measured gain less the campaign's pinned one [W] (None: 0 on every
    #: night; ``impctl.fit.gain``)
    gain_w: torch.Tensor | None = None

    @property
    def n_nights(self) -> int:
        return len(self.night_ids)

    @property
    def constrained(self) -> torch.Tensor:
        return torch.tensor([k == "constrained" for k in self.kinds])

    def demand_mask(self) -> torch.Tensor:
        """(N, K) bool: the nodes a DEMAND row compares — :attr:`mask` without the last
        sample ("instant" power is the mean until the next sample) and without the power
        samples that cannot be compared. Computed once per packing: every optimiser
        iteration's rows read it."""
        cached = self.__dict__.get("_demand_mask")
        if cached is None:
            cached = self.mask
            if self.timestamps == "instant":
                cached = cached & ~self.last
            if self.power_ok is not None:
                cached = cached & self.power_ok
            self.__dict__["_demand_mask"] = cached
        return cached


def smooth(t: np.ndarray, y: np.ndarray, width_s: float) -> np.ndarray:
    """Centred moving average of samples within ±width/2 [s] (window shrinks at the ends)."""
    if width_s <= 0 or len(t) < 3:
        return y.copy()
    lo = np.searchsorted(t, t - width_s / 2, side="left")
    hi = np.searchsorted(t, t + width_s / 2, side="right")
    c = np.concatenate([[0.0], np.cumsum(y)])
    return (c[hi] - c[lo]) / (hi - lo)


#: Level of the test that a held night's T_air is one constant level within its readings' noise
#: (:func:`held_driver`).
HELD_FLAT_LEVEL = 0.95


def held_driver(t: np.ndarray, t_air: np.ndarray, width_s: float) -> np.ndarray:
    """The T_air [°C] that drives a held night's DEMAND row, at its samples (``t`` [s]).

    The night's mean when its hourly means are one constant level within the readings' noise
    (χ² test at :data:`HELD_FLAT_LEVEL`; the noise from the night's second differences, at
    least its resolution/√12), else the centred moving average of width ``width_s`` [s].
    The massless air node turns any T_air change into heat at once, about 1.4 kW/K in a
    150 m² house, and the mass can follow a slow change, so a slow drift in the driver is
    absorbed best by a smaller C_m: the noise a moving average leaves (σ/√12 over an hour) pulls
    C_m and τ low. On the realistic plant with only the sensors' noise (room 0–0.3 K) the
    moving average alone gave τ 14.6 % median error (low), this rule 3.2 % (decision record
    0026)."""
    t = np.asarray(t, float)
    y = np.asarray(t_air, float)
    smoothed = smooth(t, y, width_s)
    if len(y) < 4:
        return smoothed
    noise = max(reading_noise(y), (t_air_resolution_k(y) or 0.0) / np.sqrt(12.0))
    hours = residual_blocks((y - y.mean())[None], np.ones((1, len(y)), bool), t[None])
    if hours["blocks"] < 2 or noise <= 0.0:
        return smoothed
    if hours["lf"] / noise ** 2 <= chdtri(hours["blocks"] - 1, 1.0 - HELD_FLAT_LEVEL):
        return np.full_like(y, y.mean())
    return smoothed


def furniture_rate(t: np.ndarray, t_air: np.ndarray, tau_s: float, steady: bool) -> np.ndarray:
    """dT_fur/dt [K/s] at the samples of a node following ``t_air`` (piecewise linear) with
    time constant ``tau_s`` (exact per interval). It starts in step with T_air (``steady``:
    at rest, a held night from its day) or lagging a steady slope (a cooling night)."""
    t_air = smooth(t, np.asarray(t_air, float), 1800.0)
    h = np.diff(t)
    slope = np.diff(t_air) / np.where(h > 0, h, 1.0)
    e = np.zeros(len(t))           # T_fur − T_air
    if not steady and len(slope):
        e[0] = -tau_s * slope[0]
    alpha = np.exp(-h / tau_s)
    for k in range(len(h)):
        e[k + 1] = e[k] * alpha[k] - slope[k] * tau_s * (1.0 - alpha[k])
    return -e / tau_s


def pack_nights(nights: Sequence[NightSamples], offsets_s: Sequence[float], *,
                timestamps: str = "instant", smooth_air_s: float = 0.0,
                smooth_out_s: float = 0.0,
                power_ok: Sequence[np.ndarray] | None = None) -> PackedNights:
    """Put prepared nights (already cut to their fit windows) side by side, each on its own
    sample times (padded to the longest night by repeating its last sample: zero-length
    intervals that change nothing).

    Parameters
    ----------
    nights : nights whose samples all belong to the fit (see ``fit.prepare_nights``)
    offsets_s : per night, the time [s] in its ``time_s`` that becomes grid time 0
    timestamps : {"instant", "interval"}
        "instant": temperatures are readings at the stamp, ``q_hc`` the mean power until the
        next stamp. "interval": every value is the mean over the interval that starts at the
        stamp (hourly logs, the virtual IMP): temperatures then belong to the interval's middle,
        so the nodes move there, and the power on [middle_k, middle_k+1) is (q_k + q_k+1)/2.
    smooth_air_s : width of the moving average applied to the T_air that drives DEMAND rows [s]
        (a held night whose T_air is one level within its noise is driven by its mean:
        :func:`held_driver`)
    smooth_out_s : width of the moving average applied to T_out [s]: the outdoor temperature
        is an input of every row, and its sensor noise (0.2–0.5 K per reading, real-houses.md
        §5) would otherwise enter as errors in the variables and bias the fit
    power_ok : per night, bool per sample: False where the measured power is not the space
        heating the model describes (a DHW recharge and the recovery after it);
        those samples still drive the model (T_air), their power is not compared
    """
    if timestamps not in TIMESTAMPS:
        raise ValueError(f"timestamps must be one of {TIMESTAMPS}")
    rel = []
    for night, off in zip(nights, offsets_s, strict=True):
        t = np.asarray(night.time_s, float) - off
        if timestamps == "interval":
            span = np.diff(t)
            t = t + 0.5 * np.append(span, span[-1])
        rel.append(np.round(t, 3))
    n, k = len(nights), max(len(t) for t in rel)
    grid, te, te_s, ta, ta_s, tai, tai_s, q, q_in, fur = (np.zeros((n, k)) for _ in range(10))
    mask = np.zeros((n, k), dtype=bool)
    next_node = np.tile(np.arange(k), (n, 1))
    last = np.zeros((n, k), dtype=bool)
    q_mean = np.zeros(n)

    def padded(y, m):
        y = np.asarray(y, float)
        return np.concatenate([y, np.full(k - m, y[-1])])

    for i, (night, t) in enumerate(zip(nights, rel, strict=True)):
        m = len(t)
        grid[i] = padded(t, m)
        t_air = np.asarray(night.t_air_c, float)
        t_out = smooth(t, np.asarray(night.t_out_c, float), smooth_out_s)
        driver = (held_driver(t, t_air, smooth_air_s) if night.kind == "normal"
                  else smooth(t, t_air, smooth_air_s))
        for dst, dst_s, y in ((te, te_s, t_out), (ta, ta_s, t_air), (tai, tai_s, driver)):
            dst[i] = padded(y, m)
            dst_s[i, :m - 1] = np.diff(np.asarray(y, float)) / np.diff(t)
        fur[i, :m] = furniture_rate(t, t_air, FURNITURE_TAU_S, night.kind != "constrained")
        qi = np.asarray(night.q_hc_w, float)
        q[i] = padded(qi, m)
        q_in[i] = q[i]
        if timestamps == "interval":
            q_in[i, :m - 1] = 0.5 * (qi[:-1] + qi[1:])
        mask[i, :m] = True
        next_node[i, :m - 1] += 1
        last[i, m - 1] = True
        span = np.diff(t)
        q_mean[i] = float(np.sum(qi[:-1] * span) / np.sum(span))

    def tt(a):
        return torch.as_tensor(a, dtype=DTYPE)

    return PackedNights(
        night_ids=[x.night_id for x in nights], kinds=[x.kind for x in nights],
        timestamps=timestamps, grid_s=tt(grid),
        t_out_c=tt(te), t_out_slope=tt(te_s), t_air_c=tt(ta), t_air_slope=tt(ta_s),
        t_air_in_c=tt(tai), t_air_in_slope=tt(tai_s), q_w=tt(q), q_in_w=tt(q_in),
        q_mean_w=tt(q_mean), t_fur_slope=tt(fur), mask=torch.as_tensor(mask),
        next_node=torch.as_tensor(next_node), last=torch.as_tensor(last),
        power_ok=None if power_ok is None else torch.as_tensor(np.stack([
            np.concatenate([np.asarray(p, bool), np.ones(k - len(p), bool)]) for p in power_ok])),
    )
