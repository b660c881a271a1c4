"""A scikit-learn estimator that puts a parameter into one of its ranges with a random forest.

:mod:`impctl.classifiers` imports this module lazily, so light consumers (the daemon) do not load
scikit-learn.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, ClassifierMixin

from ..population.ranges import DEFAULT_RANGES, bin_values, labels_of

#: Fewest held-out households worth calibrating on; below that the forest keeps every training
#: household and its vote shares (a sigmoid fitted to a handful of houses is noise, and the
#: households it takes away can flip a borderline class).
MIN_CALIBRATION_GROUPS = 40


class RangeClassifier(ClassifierMixin, BaseEstimator):
    """Random forest whose classes are the ranges of one house parameter.

    ``fit`` takes the parameter's VALUES and bins them into ``ranges``; ``predict`` returns range
    labels such as ``"60-100"``; ``predict_proba`` has one column per range (also ranges absent
    from the training data, with probability 0).

    Parameters
    ----------
    ranges : tuple of (low, high)
        Contiguous, increasing ranges of the parameter (its unit).
    n_estimators : int, default 300
    min_samples_leaf : int, default 5
        Larger leaves: smoother probabilities and a model a third the size.
    max_features : {"sqrt", "log2"}, int, float or None, default "sqrt"
    random_state : int or None
    n_jobs : int or None
        Trees built in parallel (``-1``: all cores).
    calibration : {"sigmoid", "isotonic"} or None, default "sigmoid"
        A forest's vote shares are not probabilities (they crowd towards the middle). With
        ``groups`` given to :meth:`fit`, ``calibration_fraction`` of the groups (households) is
        held out, the forest is trained on the rest, and scikit-learn's
        ``CalibratedClassifierCV`` maps its votes to calibrated probabilities on the held-out
        households (whole households, so no campaign of a calibration house was seen by the
        forest). Without groups, with fewer than :data:`MIN_CALIBRATION_GROUPS` held-out
        households, or when they miss a class, the forest keeps all rows and its vote shares
        (``calibrated_`` False).
    calibration_fraction : float, default 0.2

    Attributes
    ----------
    classes_ : ndarray of str
        Range labels, in range order.
    forest_ : sklearn.ensemble.RandomForestClassifier
    calibrator_ : sklearn.calibration.CalibratedClassifierCV or None
    calibrated_ : bool
    n_features_in_ : int
    feature_names_in_ : ndarray of str (when fitted on a DataFrame)
    """

    def __init__(
        self,
        ranges: tuple[tuple[float, float], ...] = DEFAULT_RANGES["floor_area"],
        n_estimators: int = 300,
        min_samples_leaf: int = 5,
        max_features: str | int | float | None = "sqrt",
        random_state: int | None = None,
        n_jobs: int | None = None,
        calibration: str | None = "sigmoid",
        calibration_fraction: float = 0.2,
    ):
        self.ranges = ranges
        self.n_estimators = n_estimators
        self.min_samples_leaf = min_samples_leaf
        self.max_features = max_features
        self.random_state = random_state
        self.n_jobs = n_jobs
        self.calibration = calibration
        self.calibration_fraction = calibration_fraction

    def fit(self, X: ArrayLike, y: ArrayLike, groups: ArrayLike | None = None
            ) -> RangeClassifier:
        """Fit on features ``X`` (n_samples, n_features; NaN allowed) and parameter values ``y``;
        ``groups`` (e.g. the household of each row) enables the calibration."""
        from sklearn.ensemble import RandomForestClassifier
        from sklearn.utils import _safe_indexing

        self.classes_ = np.array(labels_of(tuple(self.ranges)))
        index = bin_values(y, tuple(self.ranges))
        fit_rows, cal_rows = np.arange(len(index)), None
        n_cal = 0 if groups is None else len(np.unique(groups)) * self.calibration_fraction
        if self.calibration is not None and n_cal >= MIN_CALIBRATION_GROUPS:
            from sklearn.model_selection import StratifiedGroupKFold

            folds = max(2, int(round(1.0 / self.calibration_fraction)))
            split = StratifiedGroupKFold(folds, shuffle=True, random_state=self.random_state)
            fit_rows, cal_rows = next(split.split(np.zeros(len(index)), index, groups))
        self.forest_ = RandomForestClassifier(
            n_estimators=self.n_estimators,
            min_samples_leaf=self.min_samples_leaf,
            max_features=self.max_features,
            random_state=self.random_state,
            n_jobs=self.n_jobs,
        ).fit(_safe_indexing(X, fit_rows), index[fit_rows])
        self.calibrator_ = None
        if cal_rows is not None and set(index[cal_rows]) == set(self.forest_.classes_):
            from sklearn.calibration import CalibratedClassifierCV
            from sklearn.frozen import FrozenEstimator

            self.calibrator_ = CalibratedClassifierCV(
                FrozenEstimator(self.forest_), method=self.calibration).fit(
                _safe_indexing(X, cal_rows), index[cal_rows])
        self.calibrated_ = self.calibrator_ is not None
        self.n_features_in_ = self.forest_.n_features_in_
        if hasattr(self.forest_, "feature_names_in_"):
            self.feature_names_in_ = self.forest_.feature_names_in_
        return self

    def predict_proba(self, X: ArrayLike) -> NDArray[np.float64]:
        """Probability of each range, shape (n_samples, n_ranges): calibrated when the fit
        could calibrate (``calibrated_``), else the forest's vote shares."""
        model = getattr(self, "calibrator_", None) or self.forest_
        return self._expand(model.predict_proba(X), model.classes_)

    def predict_votes(self, X: ArrayLike) -> NDArray[np.float64]:
        """The forest's vote shares per range (not calibrated), shape (n_samples, n_ranges)."""
        return self._expand(self.forest_.predict_proba(X), self.forest_.classes_)

    def _expand(self, proba, classes) -> NDArray[np.float64]:
        out = np.zeros((proba.shape[0], len(self.classes_)))
        out[:, np.asarray(classes, int)] = proba
        return out

    def predict(self, X: ArrayLike) -> NDArray[np.str_]:
        """Most probable range label per sample."""
        return self.classes_[np.argmax(self.predict_proba(X), axis=1)]

    def score(self, X: ArrayLike, y: ArrayLike, sample_weight: ArrayLike | None = None) -> float:
        """Accuracy against parameter VALUES ``y`` (binned into the ranges)."""
        truth = self.classes_[bin_values(y, tuple(self.ranges))]
        hit = (self.predict(X) == truth).astype(float)
        return float(np.average(hit, weights=sample_weight))
