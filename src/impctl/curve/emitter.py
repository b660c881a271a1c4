"""The emitter, measured: its heat output against the mean water temperature above the room,
Q = K·ΔT_wⁿ, with K and n and their intervals.

From the steady blocks (:mod:`.blocks`): Q the heat delivered [W], ΔT_w the mean of flow and
return less the room [K]. ln Q = ln K + n·ln ΔT_w is fitted by least squares with a prior on
n, :data:`EXPONENT_PRIOR` (EN 442 radiators 1.3 ± 0.1, underfloor heating ≈ 1.1): a few
nights at similar outdoor temperatures span a narrow range of ΔT_w, which tells K well and n
hardly, and the prior says so instead of inventing an n. The residuals of one night are
correlated (the same weather, the same cycling): their variance is inflated by the blocks'
design effect, the mean over nights of (Σ residuals)² / Σ residuals².

The flow runs above the mean water by half the flow–return spread, which grows with the heat:
spread = Q / ṁc. ṁc [W/K] is the median over the blocks of Q / spread.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

#: Prior of the emitter exponent n: (mean, SD) [-].
EXPONENT_PRIOR = (1.2, 0.2)
#: Physical range of n: draws are kept inside it [-].
EXPONENT_RANGE = (0.9, 1.6)
#: Fewest steady blocks the emitter is fitted from.
MIN_BLOCKS = 3
#: Smallest mean water temperature above the room a block may have [K].
MIN_DELTA_T_K = 1.0
#: Floor of the residual SD of ln Q [-] (a handful of blocks can fit too well).
MIN_SIGMA = 0.03
#: Smallest flow–return spread ṁc is read from [K].
MIN_SPREAD_K = 0.3


class EmitterUnknown(ValueError):
    """The nights do not hold what the emitter is measured from (the message says what)."""


@dataclass(frozen=True)
class EmitterFit:
    """Q = K·ΔT_wⁿ fitted to the steady blocks.

    Attributes
    ----------
    ln_k, exponent : posterior means of ln K (K in W/Kⁿ) and n.
    cov : 2×2 posterior covariance of (ln K, n).
    blocks, nights : blocks and nights used.
    delta_t_k : (lowest, highest) ΔT_w of the blocks [K].
    flow_w_per_k : ṁc [W/K] (inf when no spread was recorded).
    sigma : residual SD of ln Q, design effect included [-].
    """

    ln_k: float
    exponent: float
    cov: np.ndarray
    blocks: int
    nights: int
    delta_t_k: tuple[float, float]
    flow_w_per_k: float
    sigma: float

    def output_w(self, delta_t_k: np.ndarray) -> np.ndarray:
        """Central output at ``delta_t_k`` [W]."""
        return np.exp(self.ln_k) * np.maximum(delta_t_k, 0.0) ** self.exponent

    def draws(self, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
        """``n`` draws of (ln K, n) from the posterior, n kept in :data:`EXPONENT_RANGE`."""
        d = rng.multivariate_normal([self.ln_k, self.exponent], self.cov, size=n)
        lo, hi = EXPONENT_RANGE
        return d[:, 0], np.clip(d[:, 1], lo, hi)

    def interval(self, z: float = 1.96) -> dict:
        """K [W/Kⁿ] and n with their central 95 % intervals (K at the mean ΔT_w's ln K)."""
        sd_k, sd_n = math.sqrt(self.cov[0, 0]), math.sqrt(self.cov[1, 1])
        return {
            "k_w_per_k_n": {"value": math.exp(self.ln_k), "low": math.exp(self.ln_k - z * sd_k),
                            "high": math.exp(self.ln_k + z * sd_k)},
            "exponent": {"value": self.exponent, "low": self.exponent - z * sd_n,
                         "high": self.exponent + z * sd_n},
        }

    def to_dict(self) -> dict:
        """The JSON block ``emitter`` (docs/reference/curve-json.md)."""
        out = self.interval()
        lo, hi = self.delta_t_k
        out.update({
            "blocks": self.blocks, "nights": self.nights,
            "delta_t_k": [round(lo, 2), round(hi, 2)],
            "flow_w_per_k": None if math.isinf(self.flow_w_per_k) else self.flow_w_per_k,
            "exponent_prior": list(EXPONENT_PRIOR),
            "output_at_30k_w": float(self.output_w(np.array(30.0))),
        })
        return out


def fit_emitter(blocks: pd.DataFrame) -> EmitterFit:
    """Fit Q = K·ΔT_wⁿ to ``blocks`` (:func:`impctl.curve.data.blocks.steady_blocks`).

    Raises
    ------
    EmitterUnknown
        Fewer than :data:`MIN_BLOCKS` blocks with flow and return temperatures.
    """
    b = blocks[np.isfinite(blocks["t_water_c"].to_numpy(dtype=float))]
    dt = (b["t_water_c"] - b["t_air_c"]).to_numpy(dtype=float)
    q = b["q_w"].to_numpy(dtype=float)
    keep = (dt >= MIN_DELTA_T_K) & (q > 0)
    b, dt, q = b[keep], dt[keep], q[keep]
    if len(b) < MIN_BLOCKS:
        raise EmitterUnknown(
            f"{len(b)} steady block(s) (a night or half a day) with flow and return temperatures "
            f"(t_flow_c, t_return_c) and the heating on; the emitter needs {MIN_BLOCKS}")
    x = np.column_stack([np.ones(len(dt)), np.log(dt)])
    y = np.log(q)
    groups = b["evening"].to_numpy()
    # The posterior under the prior on n, twice: first with a guessed residual SD, then with
    # the residuals' own, inflated by the design effect of blocks from one night.
    mu_n, sd_n = EXPONENT_PRIOR
    prior_prec = np.diag([0.0, 1.0 / sd_n**2])
    prior_term = prior_prec @ np.array([0.0, mu_n])
    s2 = 0.1**2
    for _ in range(2):
        cov = np.linalg.inv(x.T @ x / s2 + prior_prec)
        mean = cov @ (x.T @ y / s2 + prior_term)
        resid = y - x @ mean
        sigma = max(float(np.sqrt(np.sum(resid**2) / max(len(y) - 1, 1))), MIN_SIGMA)
        s2 = sigma**2 * _design_effect(resid, groups)
    cov = np.linalg.inv(x.T @ x / s2 + prior_prec)
    mean = cov @ (x.T @ y / s2 + prior_term)
    spread = b["spread_k"].to_numpy(dtype=float)
    ok = np.isfinite(spread) & (spread >= MIN_SPREAD_K)
    mdot_c = float(np.median(q[ok] / spread[ok])) if ok.any() else math.inf
    return EmitterFit(float(mean[0]), float(mean[1]), cov, int(len(b)),
                      int(len(set(groups))), (float(dt.min()), float(dt.max())), mdot_c,
                      math.sqrt(s2))


def _design_effect(resid: np.ndarray, groups: np.ndarray) -> float:
    """Mean over groups of (Σe)²/Σe², at least 1: how much one night's blocks repeat each other."""
    ratios = []
    for g in set(groups):
        e = resid[groups == g]
        if len(e) > 1 and np.sum(e**2) > 0:
            ratios.append(np.sum(e) ** 2 / np.sum(e**2))
    return max(1.0, float(np.mean(ratios))) if ratios else 1.0
