"""Calibration of class probabilities, as the classifier benches report it."""

from __future__ import annotations

import numpy as np


def ece(proba: np.ndarray, y: np.ndarray, n_bins: int = 10) -> float:
    """Expected calibration error of the top class over ``n_bins`` confidence bins [-]."""
    top = proba.max(axis=1)
    hit = (proba.argmax(axis=1) == y).astype(float)
    idx = np.minimum((top * n_bins).astype(int), n_bins - 1)
    return float(sum(abs(hit[idx == b].mean() - top[idx == b].mean()) * np.mean(idx == b)
                     for b in range(n_bins) if np.any(idx == b)))
