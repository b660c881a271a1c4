"""The change test: one step in the heat-loss coefficient, by a generalised likelihood ratio.

The nights are rows (:mod:`.nights`). The night's heat balance as a grey-box expert writes it,
``q = H·dt − Φ + b_f·fall + b_m·memory + b_d·defrost``, with the gains Φ and the three b's the
house's own, is fitted to all usable nights with a step in H from night k on. The test is the
generalised likelihood ratio for one step at an unknown night (:func:`glr`): the largest
|δ̂_k / se(δ̂_k)| over k, by generalised least squares whose error correlation (the gains
wandering over days, :func:`whitener`, by restricted maximum likelihood) is the house's own;
where the nights carry the household electricity it stands in for the internal gains. The house
has changed when the statistic passes the threshold of the nights' design
(:func:`threshold_for`). Run night after night (:func:`detect_sequence`), it is set to alarm at
most once per house-season in 20 when nothing changed, with 95 % confidence: each threshold is
the one-sided 95 % upper confidence bound of the 95th percentile of the whole season's largest
statistic (an order statistic; the percentile itself would promise one in 20 and, half the
time, miss it) on 1,920 simulated house-seasons without a change, each with its own weather
(``bench/season_change.py --calibrate``, seeds 9001–9006), none of them the bench's held-out
households, which measure it — :data:`THRESHOLD` where every night carries the household
electricity, :data:`THRESHOLD_NO_HOUSE` where it does not: without the meter the internal
gains' wander is left in the errors, and the same statistic passes 3.80 in about one
house-season in thirteen. The emitter (radiators or a screed), whose seasons differ little with
the meter, is not in the record and sets no threshold. The step's night is
the k of the largest statistic; its size δ̂_k [W/K] has a 95 % interval of ±z·se at that k,
widened by :data:`SIZE_SCALE`.

Measured against the alternative, a two-sided CUSUM on the residuals of the same night model
fitted to a 20-night reference window (``bench/season_change.py --method cusum``): on the
calibration seasons, at matched false alarms, they detected about as often; the GLR needs no
reference window (a change in the first weeks is found too) and gives the step's night and
size with an interval. Units in the names.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..imp.night import NightSamples
from .nights import NightRows, night_rows

#: The grid of the slow part's day-to-day correlation φ [-] and its variance ratio to a
#: night's own noise [-] (:func:`whitener`).
AR_PHI = (0.5, 0.7, 0.8, 0.9, 0.95)
AR_RATIO = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0)
#: Usable nights before the test is run at all.
MIN_NIGHTS = 24
#: Fewest usable nights on each side of a step.
MIN_SIDE = 6
#: The alarm threshold on the largest |t| [-] where the nights carry the household electricity,
#: and where they do not (module docstring; :func:`threshold_for`).
THRESHOLD = 3.80
THRESHOLD_NO_HOUSE = 4.15
#: Scale of the size's interval [-] (module docstring).
SIZE_SCALE = 1.0
#: Normal quantile of a two-sided 95 % interval.
Z95 = 1.959964


@dataclass(frozen=True)
class Change:
    """The change test's answer (:func:`detect_change`).

    Attributes
    ----------
    changed : the statistic passed ``threshold``
    since_date : the first night after the step (ISO date of the evening), or None
    delta_hlc_w_k, low_w_k, high_w_k : the step in HLC and its 95 % interval [W/K] (the largest
        statistic's step, also when not changed; NaN with too few nights)
    nights_after : usable owner nights from ``since_date`` on
    nights : usable owner nights read
    statistic : the largest |δ̂/se| [-]
    threshold : the alarm threshold for the nights' design [-] (:func:`threshold_for`)
    """

    changed: bool
    since_date: str | None
    delta_hlc_w_k: float
    low_w_k: float
    high_w_k: float
    nights_after: int
    nights: int
    statistic: float
    threshold: float = THRESHOLD

    def as_dict(self) -> dict:
        """JSON-ready (the fit JSON's ``season.change``), units in the names."""
        def num(x: float) -> float | None:
            return round(float(x), 2) if math.isfinite(x) else None
        return {"changed": self.changed, "since_date": self.since_date if self.changed else None,
                "delta_hlc_w_k": num(self.delta_hlc_w_k) if self.changed else None,
                "lo": num(self.low_w_k) if self.changed else None,
                "hi": num(self.high_w_k) if self.changed else None,
                "nights_after": self.nights_after if self.changed else 0,
                "nights": self.nights, "statistic": num(self.statistic),
                "threshold": self.threshold}


def _days(dates: list[str]) -> np.ndarray:
    """Day numbers of ISO ``dates`` [d]."""
    return np.array([np.datetime64(d, "D").astype(np.int64) for d in dates], float)


def whitener(rows: NightRows, X: np.ndarray) -> np.ndarray:
    """The inverse Cholesky factor of the nights' error correlation: a slow part, the gains
    wandering (an AR(1) over days, φ^|Δd|), on top of each night's own noise; φ and the parts'
    ratio are the restricted-maximum-likelihood (REML) ones on a grid, for the design ``X``
    without a step.

    REML, not plain maximum likelihood: with 24–70 nights and up to eight regressors, the
    plain likelihood takes the residuals for the noise itself and finds the slow part too weak;
    the step's standard error was then too small and a house with nothing changed passed the
    threshold about twice as often as the same statistic with the REML correlation."""
    d = _days(rows.dates)
    lag = np.abs(d[:, None] - d[None, :])
    n = len(d)
    sv = np.linalg.svd(X, compute_uv=False)
    p = int(np.sum(sv > sv[0] * 1e-10)) if len(sv) else 0
    best, best_l = -np.inf, np.eye(n)
    for i, phi in enumerate(AR_PHI):
        corr = phi ** lag
        for ratio in AR_RATIO:
            if ratio == 0.0 and i:   # no slow part: the same for every φ, done at the first
                continue
            s = np.eye(n) + ratio * corr
            try:
                c = np.linalg.cholesky(s)
            except np.linalg.LinAlgError:
                continue
            w = np.linalg.inv(c)
            xw, yw = w @ X, w @ rows.q_w
            beta, *_ = np.linalg.lstsq(xw, yw, rcond=None)
            rss = float(np.sum((yw - xw @ beta) ** 2))
            # The restricted likelihood: the residuals' n − p degrees of freedom, and the
            # information the regressors take, log det(XᵀΣ⁻¹X) over the design's rank p.
            svw = np.linalg.svd(xw, compute_uv=False)[:p]
            ll = (-0.5 * (n - p) * math.log(max(rss / max(n - p, 1), 1e-300))
                  - float(np.sum(np.log(np.diag(c)))) - float(np.sum(np.log(svw))))
            if ll > best:
                best, best_l = ll, w
    return best_l


def glr(rows: NightRows, before: int = MIN_SIDE, after: int = MIN_SIDE,
        level: bool = False) -> tuple[float, int, float, float]:
    """(largest |t|, its night index k, δ̂_k [W/K], se(δ̂_k) [W/K]) of a step in H from night k
    on, over every k with ``before`` nights before it and ``after`` from it on; (NaN, -1, NaN,
    NaN) with too few nights. Generalised least squares with the correlation of
    :func:`whitener`. ``level``: a free step in the gains level at the same night beside it
    (measured and not adopted, decision record 0036)."""
    n = len(rows)
    if n < max(MIN_NIGHTS, before + after):
        return math.nan, -1, math.nan, math.nan
    X0 = rows.design()
    # A regressor the nights do not move (no defrost, no setback) is left out: no column of
    # zeros, whose coefficient nothing determines.
    keep = np.r_[True, np.ptp(X0[:, 1:], axis=0) > 1e-9]
    X0 = X0[:, keep]
    w = whitener(rows, X0)
    x0w, yw = w @ X0, w @ rows.q_w
    best = (0.0, -1, math.nan, math.nan)
    for k in range(before, n - after + 1):
        step = (np.arange(n) >= k).astype(float)
        X = np.column_stack([x0w, *([w @ step] if level else []), w @ (step * rows.dt_k)])
        beta, *_ = np.linalg.lstsq(X, yw, rcond=None)
        r = yw - X @ beta
        dof = n - X.shape[1]
        if dof < 2:
            continue
        sigma = max(math.sqrt(float(r @ r) / dof), 1e-9)
        try:
            cov = np.linalg.inv(X.T @ X) * sigma ** 2
        except np.linalg.LinAlgError:
            continue
        se = math.sqrt(max(cov[-1, -1], 0.0))
        if se <= 0:
            continue
        t = abs(beta[-1]) / se
        if t > best[0]:
            best = (t, k, float(beta[-1]), se)
    return best


def threshold_for(rows: NightRows) -> float:
    """The alarm threshold [-] for ``rows``' design: :data:`THRESHOLD` with the household
    electricity, :data:`THRESHOLD_NO_HOUSE` without (module docstring)."""
    return THRESHOLD if rows.has_house_electricity else THRESHOLD_NO_HOUSE


def detect_change(nights: Sequence[NightSamples]) -> Change:
    """The change test on ``nights`` (a household's nights of any kind; module docstring)."""
    return change_of(night_rows(nights))


def change_of(rows: NightRows) -> Change:
    """The change test on ``rows`` (:func:`night_rows`)."""
    stat, k, delta, se = glr(rows)
    n = len(rows)
    if k < 0:
        return Change(False, None, math.nan, math.nan, math.nan, 0, n,
                      stat if math.isfinite(stat) else math.nan, threshold_for(rows))
    half = Z95 * SIZE_SCALE * se
    threshold = threshold_for(rows)
    changed = bool(stat >= threshold)
    return Change(changed, rows.dates[k], delta, delta - half, delta + half, n - k, n, stat,
                  threshold)


def detect_sequence(rows: NightRows) -> tuple[int, Change]:
    """The test run after each usable night as the gateway would: (the number of nights read
    when it first alarmed, -1 if never; the answer then, or at the last night)."""
    last = change_of(rows)
    for m in range(max(MIN_NIGHTS, 2 * MIN_SIDE), len(rows) + 1):
        c = change_of(rows.head(m))
        if c.changed:
            return m, c
    return -1, last
