"""IMP nights → the filter's tensors: one regular step grid per household, nights padded.

Each night is placed on a grid of the household's step (the median sample spacing): a sample
goes to its nearest grid point; a grid point without a sample is a missing observation (the
filter skips its update) and holds the last inputs. Constrained nights run from switch-off
(the emitter state carries the heat still released, so no emission lag is cut) to the last
sample before heating resumes; normal nights are kept whole. Inputs over [t_k, t_k+1): T_out the
mean of the two readings. The metered power of a row (the mean until the next sample) is a
measurement of the latent heat input of its interval (:mod:`.model`), missing where no row.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from ...imp.features import Q_ON_W
from ...imp.night import NightSamples
from .model import DTYPE

#: A constrained night's heating counts as resumed from this long after switch-off [h] (its
#: first rows may still hold the heat metered before the switch).
RESUME_AFTER_H = 0.5


@dataclass
class Series:
    """One household's nights on its grid (arrays (N, T))."""

    night_ids: list[str]
    kinds: list[str]
    dt_s: float
    y: np.ndarray          # T_air readings, NaN where none
    t_out: np.ndarray      # input over each interval
    q: np.ndarray          # metered power over each interval, NaN where none
    skipped: list[tuple[str, str]]

    @property
    def n_obs(self) -> int:
        return int(np.isfinite(self.y).sum())


def _cut(night: NightSamples, resume_w: float) -> tuple[np.ndarray, ...] | None:
    t = np.asarray(night.time_s, float)
    arr = [np.asarray(a, float) for a in (night.t_air_c, night.t_out_c, night.q_hc_w)]
    ok = np.isfinite(t) & np.isfinite(arr[1]) & np.isfinite(arr[2]) & (t >= -1e-6)
    if night.kind == "constrained":
        on = ok & (arr[2] > resume_w) & (t >= RESUME_AFTER_H * 3600.0)
        if on.any():
            ok &= t < t[on.argmax()]
    if ok.sum() < 3:
        return None
    return t[ok], arr[0][ok], arr[1][ok], arr[2][ok]


def to_series(nights: Sequence[NightSamples], min_hours: float = 1.0,
              resume_w: float = Q_ON_W) -> Series:
    """The household's nights on one grid (nights shorter than ``min_hours`` skipped)."""
    cut, skipped = [], []
    for night in nights:
        c = _cut(night, resume_w)
        span = 0.0 if c is None else (c[0][-1] - c[0][0]) / 3600.0
        if c is None or span < min_hours or np.isfinite(c[1]).sum() < 3:
            skipped.append((night.night_id, f"{night.kind} night covers {span:.1f} h, under "
                            f"the {min_hours:g} h minimum"))
            continue
        cut.append((night, c))
    if not cut:
        return Series([], [], 300.0, *(np.zeros((0, 0)),) * 3, skipped)
    dt = float(np.median(np.concatenate([np.diff(c[0]) for _, c in cut])))
    length = max(int(round((c[0][-1] - c[0][0]) / dt)) + 1 for _, c in cut)
    n = len(cut)
    y = np.full((n, length), np.nan)
    t_out = np.zeros((n, length))
    q = np.zeros((n, length))
    for j, (_, (t, ta, to, qq)) in enumerate(cut):
        k = np.clip(np.round((t - t[0]) / dt).astype(int), 0, length - 1)
        y[j, k] = ta
        # inputs: each grid point takes its sample's values, gaps hold the last ones; T_out
        # over an interval is the mean of its two ends
        idx = np.maximum.accumulate(np.where(np.isin(np.arange(length), k),
                                             np.arange(length), 0))
        to_g, q_g = np.full(length, np.nan), np.full(length, np.nan)
        to_g[k], q_g[k] = to, qq
        to_g = to_g[idx]
        to_g[k.max() + 1:] = to_g[k.max()]
        t_out[j] = 0.5 * (to_g + np.r_[to_g[1:], to_g[-1]])
        q[j] = q_g
    return Series([nt.night_id for nt, _ in cut], [nt.kind for nt, _ in cut], dt, y, t_out, q,
                  skipped)


@dataclass
class Batch:
    """Several households' series padded to (H, N, T) tensors for one filter call."""

    y: torch.Tensor          # (H, N, T, 2): T_air, metered power (0 where missing)
    observed: torch.Tensor   # (H, N, T, 2) bool, False also on padded nights
    u: torch.Tensor          # (H, N, T, 2): T_out, 1
    night_mask: torch.Tensor  # (H, N) bool: a real night
    constrained: torch.Tensor  # (H, N) bool
    dt_s: torch.Tensor       # (H,)
    y0: torch.Tensor         # (H, N) first reading
    t_out0: torch.Tensor     # (H, N)
    q0: torch.Tensor         # (H, N) mean power over the first hour
    quantum_k: torch.Tensor  # (H,) the room sensor's resolution read from the data [K]


def batch(series: Sequence[Series]) -> Batch:
    """Pad the households' series to one batch."""
    h = len(series)
    n = max(len(s.kinds) for s in series)
    t = max(s.y.shape[1] for s in series)
    y = np.full((h, n, t, 2), np.nan)
    u = np.zeros((h, n, t, 2))
    u[..., 1] = 1.0
    mask = np.zeros((h, n), bool)
    cons = np.zeros((h, n), bool)
    y0, to0, q0 = np.full((h, n), 20.0), np.zeros((h, n)), np.zeros((h, n))
    for i, s in enumerate(series):
        nn, tt = s.y.shape
        y[i, :nn, :tt, 0], y[i, :nn, :tt, 1] = s.y, s.q
        u[i, :nn, :tt, 0] = s.t_out
        u[i, :nn, tt:, 0] = s.t_out[:, -1:]
        mask[i, :nn] = True
        cons[i, :nn] = [k == "constrained" for k in s.kinds]
        hour = max(1, int(round(3600.0 / s.dt_s)))
        for j in range(nn):
            first = np.flatnonzero(np.isfinite(s.y[j]))[0]
            y0[i, j], to0[i, j] = s.y[j, first], s.t_out[j, first]
            q0[i, j] = float(np.nanmean(s.q[j, :hour])) if np.isfinite(s.q[j, :hour]).any() \
                else 0.0
    obs = np.isfinite(y)
    as_t = lambda a: torch.as_tensor(a, dtype=DTYPE)  # noqa: E731
    obs &= mask[:, :, None, None]
    return Batch(as_t(np.nan_to_num(y)), torch.as_tensor(obs), as_t(u), torch.as_tensor(mask),
                 torch.as_tensor(cons), as_t([s.dt_s for s in series]), as_t(y0), as_t(to0),
                 as_t(q0), as_t([resolution_k(s.y) for s in series]))


#: Resolution [K] assumed for a room sensor whose readings never change (a held room read as
#: one value all night): the common 0.1 K (real-houses.md §5). Stated as an assumption.
ASSUMED_RESOLUTION_K = 0.1


def resolution_k(y: np.ndarray) -> float:
    """The room sensor's resolution [K]: the smallest change between consecutive readings of a
    night (0 for a continuous sensor: changes under 0.01 K); :data:`ASSUMED_RESOLUTION_K` when
    no reading ever changes — without a floor, a constant reading would make the held nights'
    T_air infinitely precise."""
    d = np.abs(np.diff(y, axis=-1))
    d = d[np.isfinite(d) & (d > 1e-6)]
    if d.size == 0:
        return ASSUMED_RESOLUTION_K
    return float(d.min()) if d.min() >= 0.01 else 0.0
