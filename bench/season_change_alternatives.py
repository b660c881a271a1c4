"""The change test's alternatives bench/season_change.py measures against the product's.

* a two-sided CUSUM on the residuals of the night model fitted to a reference window
  (:func:`cusum_sequence`, ``--method cusum``), measured before choosing the GLR;
* the GLR as :class:`Variant` has it (:func:`glr_variant`): with a free step in the gains level
  at the step's night (``--method glr-level``), or other fewest nights on each side of the
  step (``--min-side``) — measured and not adopted (decision record 0036).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from impctl import change

#: CUSUM: reference nights, the step it is tuned to [W/K], its threshold (set like the GLR's,
#: for ≤ 1 in 20 false alarms on the calibration seasons).
CUSUM_REF, CUSUM_STEP_W_K, CUSUM_H = 20, 14.0, 120.0
#: ``--method glr-level``: its thresholds with and without the household electricity [-], set
#: like the product's (``--calibrate --method glr-level``, the 640 calibration seasons).
LEVEL_THRESHOLDS = (4.50, 4.35)


def cusum_sequence(rows: change.NightRows) -> tuple[int, int]:
    """(nights read at the alarm, -1 if none; the night the CUSUM last left zero) of a
    two-sided CUSUM tuned to ±:data:`CUSUM_STEP_W_K` on the residuals of the night model
    fitted to the first :data:`CUSUM_REF` nights."""
    n = len(rows)
    if n <= CUSUM_REF + 1:
        return -1, -1
    X = rows.design()
    keep = np.r_[True, np.ptp(X[:CUSUM_REF, 1:], axis=0) > 1e-9]
    X = X[:, keep]
    beta, *_ = np.linalg.lstsq(X[:CUSUM_REF], rows.q_w[:CUSUM_REF], rcond=None)
    r_ref = rows.q_w[:CUSUM_REF] - X[:CUSUM_REF] @ beta
    sigma = max(math.sqrt(float(r_ref @ r_ref) / max(CUSUM_REF - X.shape[1], 1)), 1e-9)
    up = down = 0.0
    since_up = since_down = CUSUM_REF
    for t in range(CUSUM_REF, n):
        r = (rows.q_w[t] - X[t] @ beta) / sigma
        m = CUSUM_STEP_W_K * rows.dt_k[t] / sigma       # the step's shift, in σ
        up, down = max(0.0, up + m * r - m * m / 2), max(0.0, down - m * r - m * m / 2)
        since_up = t + 1 if up == 0 else since_up
        since_down = t + 1 if down == 0 else since_down
        if up >= CUSUM_H or down >= CUSUM_H:
            return t + 1, min(since_up if up >= CUSUM_H else since_down, n - 1)
    return -1, -1


@dataclass(frozen=True)
class Variant:
    """A variant of the product's statistic the bench measures (``--method glr-level``,
    ``--min-side``, ``--thresholds``): a free step in the gains level at the step's night or
    not, the fewest usable nights before and after the step, the thresholds [-] with and
    without the household electricity."""

    level: bool
    before: int
    after: int
    thresholds: tuple[float, float]

    def threshold(self, rows: change.NightRows) -> float:
        """The alarm threshold [-] for ``rows``' design."""
        return self.thresholds[0 if rows.has_house_electricity else 1]


def glr_variant(rows: change.NightRows, v: Variant) -> tuple[float, int, float, float]:
    """:func:`impctl.season.change.glr` as ``v`` has it: (largest |t| of the step in H — given
    a free step in the gains level at the same night with ``v.level`` —, its night index k,
    δ̂_k [W/K], se(δ̂_k) [W/K]) over every k with ``v.before`` nights before and ``v.after``
    from k on. A gains step (heat off by the same watts whatever T_air − T_out) goes into the
    level; what is left is a change of heat in proportion to T_air − T_out. Same whitener."""
    return change.glr(rows, v.before, v.after, v.level)


def variant_sequence(rows: change.NightRows, v: Variant) -> tuple[int, int, float, float]:
    """:func:`impctl.season.change.detect_sequence` with :func:`glr_variant`: (nights read at
    the first alarm, -1 if none; the step's night index, δ̂ [W/K], se [W/K] then)."""
    threshold = v.threshold(rows)
    for m in range(max(change.MIN_NIGHTS, 2 * change.MIN_SIDE), len(rows) + 1):
        stat, k, delta, se = glr_variant(rows.head(m), v)
        if math.isfinite(stat) and stat >= threshold:
            return m, k, delta, se
    return -1, -1, math.nan, math.nan
