"""Does the model describe the nights? Tests on the standardised one-step innovations.

Under a correct model the standardised innovations z_k = e_k/√S_k of the Kalman filter are
independent N(0, 1) (CTSM-R's residual analysis; the Annex 58 guidelines ask for white
residuals). Two tests, each at level :data:`ALPHA`/2 (Bonferroni, so the verdict's false-alarm
rate is at most ALPHA on a correct model):

* **whiteness**: the Ljung–Box statistic Q = n(n+2) Σ_{k=1..h} r_k²/(n − k) over the first
  :data:`LAGS` lags, the autocorrelations r_k pooled over the nights (only pairs of observed
  samples inside one night), against χ²_h;
* **variance**: the innovations' variance does not change between nights (Bartlett's test of
  equal variances, the nights as groups): a model whose error differs from night to night
  (a wrong emitter on held nights, a wrong mass on free-cooling ones) fails it even when the
  likelihood has tuned the overall noise level to the data.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

ALPHA = 0.05
LAGS = 12


def ljung_box(z: np.ndarray, observed: np.ndarray, lags: int = LAGS) -> tuple[float, float]:
    """(Q, p-value) of series z (N, T) observed where ``observed``, pooled over rows."""
    z = np.where(observed, z, 0.0)
    n = int(observed.sum())
    mu = z.sum() / max(n, 1)
    d = np.where(observed, z - mu, 0.0)
    denom = float((d * d).sum())
    if n <= lags + 2 or denom <= 0:
        return float("nan"), float("nan")
    q = 0.0
    for k in range(1, lags + 1):
        pair = observed[:, k:] & observed[:, :-k]
        r = float((d[:, k:] * d[:, :-k] * pair).sum()) / denom
        q += r * r / (n - k)
    q *= n * (n + 2)
    return q, float(stats.chi2.sf(q, lags))


def variance_test(z: np.ndarray, observed: np.ndarray) -> tuple[float, float]:
    """(Bartlett statistic, p-value) of equal innovation variance across the nights."""
    groups = [row[m] for row, m in zip(z, observed, strict=True) if m.sum() >= 5]
    if len(groups) < 2:
        return float("nan"), float("nan")
    res = stats.bartlett(*groups)
    return float(res.statistic), float(res.pvalue)


def adequacy(z: np.ndarray, observed: np.ndarray, alpha: float = ALPHA) -> dict:
    """The two tests on one household's innovations and the verdict (adequate or not)."""
    q, p_lb = ljung_box(z, observed)
    b, p_var = variance_test(z, observed)
    zz = z[observed]
    white = not (p_lb < alpha / 2)
    steady = not (p_var < alpha / 2)
    return {"ljung_box_q": q, "ljung_box_p": p_lb, "lags": LAGS, "bartlett": b,
            "bartlett_p": p_var, "innovation_sd": float(np.std(zz)) if zz.size else float("nan"),
            "lag1_autocorrelation": _lag1(z, observed), "white": white,
            "equal_variance": steady, "adequate": bool(white and steady), "alpha": alpha}


def _lag1(z: np.ndarray, observed: np.ndarray) -> float:
    pair = observed[:, 1:] & observed[:, :-1]
    a, b = z[:, 1:][pair], z[:, :-1][pair]
    if a.size < 3 or np.std(a) == 0 or np.std(b) == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])
