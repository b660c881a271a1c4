"""A scikit-learn estimator that puts a parameter into one of its ranges with a random forest.

:mod:`impctl.classifiers` imports this module lazily, so light consumers (the daemon) do not load
scikit-learn.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, ClassifierMixin

from ..population.ranges import DEFAULT_RANGES, bin_values, labels_of

#: Fewest training households worth calibrating on (each is left out of about half the
#: calibration's trees); below that the forest keeps its vote shares (a calibration map
#: fitted to a handful of houses is noise).
MIN_CALIBRATION_GROUPS = 200
#: Accuracy over the majority class [fraction] the held-out calibrated classes must reach
#: with 95 % confidence (the lower bound of a bootstrap over households) for the classifier to
#: report them; below it the parameter is not determined by the nights and its probabilities
#: are the training prior (class frequencies), said so. The bound, not the point margin: c_f on
#: the realistic plant sits 3–5 points over its majority, and a point rule flipped its verdict
#: from one training seed to the next (bench/classify_calibration.py, seeds 0 / 1 / 3).
MIN_MARGIN = 0.05


class VoteShares(ClassifierMixin, BaseEstimator):
    """Passes precomputed vote shares through as ``predict_proba``: lets scikit-learn's
    ``CalibratedClassifierCV`` fit its calibration map on held-out votes."""

    def fit(self, X: ArrayLike, y: ArrayLike) -> VoteShares:
        """Record the classes (the columns of ``X``)."""
        self.classes_ = np.unique(y)
        return self

    def predict_proba(self, X: ArrayLike) -> NDArray[np.float64]:
        """``X`` itself: the vote shares."""
        return np.asarray(X, dtype=float)

    def predict(self, X: ArrayLike) -> NDArray:
        """The class with the most votes."""
        return self.classes_[np.argmax(np.asarray(X), axis=1)]


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
    min_samples_leaf : int, default 8
        Larger leaves: smoother probabilities and a smaller model. 8 keeps the compact
        forests the size they had when the forest saw 80 % of the households (5): on a
        development population 30 % fewer nodes, Brier equal or better on every class.
    max_features : {"sqrt", "log2"}, int, float or None, default "sqrt"
    max_samples : int, float or None, default None
        Rows drawn (with replacement) for each tree: a count, a fraction of the training rows,
        or None for as many as there are (scikit-learn's bootstrap).
    random_state : int or None
    n_jobs : int or None
        Trees built in parallel (``-1``: all cores).
    calibration : {"sigmoid", "isotonic"} or None, default "isotonic"
        A forest's vote shares are not probabilities (they crowd towards the middle). With
        ``groups`` given to :meth:`fit` (at least :data:`MIN_CALIBRATION_GROUPS`), the groups
        (households) give held-out votes (``cv``: each row voted on only by trees that never
        saw its household, so no campaign of a house votes on its own calibration), and
        scikit-learn's ``CalibratedClassifierCV`` fits its map from these held-out votes to
        class frequencies; the forest itself is then trained on every row. Without enough
        groups the forest keeps its vote shares (``calibrated_`` False).
    cv : int or "oob", default "oob"
        Where the calibration's held-out votes come from. "oob": out of the bag by group —
        ``oob_trees`` trees, each grown as the forest grows its trees but from the rows of a
        random half of the groups, and each row's votes the mean of the trees that never saw
        its household (about half of them); an int: that many
        cross-validation folds by group, stratified by range, each voted on by a whole forest
        trained on the other folds (five forests' work against the bag's two).
    oob_trees : int or None, default None
        Trees of the "oob" votes; None: twice ``n_estimators``, so that each row is voted on
        by about as many trees as a new house is by the forest (its votes as fine-grained as
        the ones the calibration map will be applied to).
    min_margin : float, default :data:`MIN_MARGIN`
        The held-out calibrated classes must beat the majority class by this much accuracy
        with 95 % confidence (on the rows ``score_rows`` of :meth:`fit`, bootstrapped over
        groups); otherwise the parameter is *not determined* by the features
        (``determined_`` False) and :meth:`predict_proba` returns the training prior for
        every row.

    Attributes
    ----------
    classes_ : ndarray of str
        Range labels, in range order.
    forest_ : sklearn.ensemble.RandomForestClassifier
    calibrator_ : sklearn.calibration.CalibratedClassifierCV or None
        Maps the forest's vote shares (:meth:`predict_votes`) to probabilities.
    calibrated_ : bool
    prior_ : ndarray
        Training class frequencies, per range.
    determined_ : bool
    cv_accuracy_, cv_majority_ : float
        Held-out accuracy (``cv``) of the calibrated classes, and the majority class's, on the
        score rows (NaN when not calibrated).
    cv_margin_low_ : float
        Lower bound of the 95 % bootstrap interval of their difference (NaN when not
        calibrated).
    n_features_in_ : int
    feature_names_in_ : ndarray of str (when fitted on a DataFrame)
    """

    #: models pickled before these settings existed unpickle without them: theirs were
    #: None, 5 folds and no bag
    max_samples: int | float | None = None
    cv: int | str = 5
    oob_trees: int | None = None

    def __init__(
        self,
        ranges: tuple[tuple[float, float], ...] = DEFAULT_RANGES["floor_area"],
        n_estimators: int = 300,
        min_samples_leaf: int = 8,
        max_features: str | int | float | None = "sqrt",
        max_samples: int | float | None = None,
        random_state: int | None = None,
        n_jobs: int | None = None,
        calibration: str | None = "isotonic",
        cv: int | str = "oob",
        oob_trees: int | None = None,
        min_margin: float = MIN_MARGIN,
    ):
        self.ranges = ranges
        self.n_estimators = n_estimators
        self.min_samples_leaf = min_samples_leaf
        self.max_features = max_features
        self.max_samples = max_samples
        self.random_state = random_state
        self.n_jobs = n_jobs
        self.calibration = calibration
        self.cv = cv
        self.oob_trees = oob_trees
        self.min_margin = min_margin

    def fit(self, X: ArrayLike, y: ArrayLike, groups: ArrayLike | None = None,
            score_rows: ArrayLike | None = None) -> RangeClassifier:
        """Fit on features ``X`` (n_samples, n_features; NaN allowed) and parameter values ``y``;
        ``groups`` (e.g. the household of each row) enables the calibration and the
        determination test, judged on ``score_rows`` (indices or a boolean mask; default all
        rows: e.g. only the rows of the campaigns the product classifies)."""
        from sklearn.ensemble import RandomForestClassifier

        self.classes_ = np.array(labels_of(tuple(self.ranges)))
        index = bin_values(y, tuple(self.ranges))
        self.prior_ = np.bincount(index, minlength=len(self.classes_)) / len(index)
        forest = RandomForestClassifier(
            n_estimators=self.n_estimators,
            min_samples_leaf=self.min_samples_leaf,
            max_features=self.max_features,
            max_samples=self.max_samples,
            random_state=self.random_state,
            n_jobs=self.n_jobs,
        )
        self.calibrator_ = None
        self.cv_accuracy_ = self.cv_majority_ = self.cv_margin_low_ = float("nan")
        self.determined_ = True
        n_groups = 0 if groups is None else len(np.unique(groups))
        if self.calibration is not None and n_groups >= MIN_CALIBRATION_GROUPS:
            self._calibrate(forest, X, index, np.asarray(groups), score_rows)
        self.forest_ = forest.fit(X, index)
        self.calibrated_ = self.calibrator_ is not None
        self.n_features_in_ = self.forest_.n_features_in_
        if hasattr(self.forest_, "feature_names_in_"):
            self.feature_names_in_ = self.forest_.feature_names_in_
        return self

    def _calibrate(self, forest, X, index, groups, score_rows) -> None:
        """Out-of-fold votes → ``calibrator_``; the determination test on ``score_rows``."""
        from sklearn.base import clone
        from sklearn.calibration import CalibratedClassifierCV
        from sklearn.frozen import FrozenEstimator
        from sklearn.model_selection import StratifiedGroupKFold, cross_val_predict

        if len(np.unique(index)) < 2:
            return
        # columns: the classes present in ``index``, in order (as the final forest's)
        if self.cv == "oob":
            votes = self._out_of_bag_votes(X, index, groups)
        else:
            split = StratifiedGroupKFold(self.cv, shuffle=True, random_state=self.random_state)
            folds = list(split.split(np.zeros(len(index)), index, groups))
            votes = cross_val_predict(clone(forest), X, index, cv=folds,
                                      method="predict_proba")
        passthrough = FrozenEstimator(VoteShares().fit(votes, index))
        self.calibrator_ = CalibratedClassifierCV(passthrough, method=self.calibration).fit(
            votes, index)
        rows = np.arange(len(index)) if score_rows is None else np.asarray(score_rows)
        rows = np.flatnonzero(rows) if rows.dtype == bool else rows
        proba = self.calibrator_.predict_proba(votes[rows])
        pred = np.asarray(self.calibrator_.classes_)[np.argmax(proba, axis=1)]
        gain = (pred == index[rows]).astype(float) - (index[rows] == np.argmax(self.prior_))
        self.cv_accuracy_ = float(np.mean(pred == index[rows]))
        self.cv_majority_ = float(np.mean(index[rows] == np.argmax(self.prior_)))
        # per group, then groups resampled: a house's rows are not independent evidence
        _, g = np.unique(groups[rows], return_inverse=True)
        per_group = np.bincount(g, gain) / np.bincount(g)
        draws = np.random.default_rng(0).integers(0, len(per_group), (2000, len(per_group)))
        self.cv_margin_low_ = float(np.percentile(per_group[draws].mean(axis=1), 2.5))
        self.determined_ = bool(self.cv_margin_low_ >= self.min_margin)

    def _out_of_bag_votes(self, X, index, groups) -> NDArray[np.float64]:
        """Each row's vote shares from the trees grown on a random half of the groups that
        left its group out (``cv="oob"``); columns: the classes present in ``index``."""
        from joblib import Parallel, delayed
        from sklearn.tree import DecisionTreeClassifier

        present = np.unique(index)
        _, group = np.unique(groups, return_inverse=True)
        n_groups = int(group.max()) + 1
        n_trees = self.oob_trees or 2 * self.n_estimators
        rng = np.random.default_rng(self.random_state)
        # exactly half the groups in each tree's bag: every tree as strong as the next
        bags = np.argsort(rng.random((n_trees, n_groups)), axis=1) < n_groups // 2
        seeds = rng.integers(0, 2**31 - 1, n_trees)
        x = X.to_numpy(dtype=float) if hasattr(X, "to_numpy") else np.asarray(X, float)

        # each tree draws its rows as the forest's trees draw theirs (with replacement, as many
        # as ``max_samples`` asks of all rows), from its bag's rows
        if self.max_samples is None:
            draws = len(index)
        elif isinstance(self.max_samples, int | np.integer):
            draws = int(self.max_samples)
        else:
            draws = max(1, round(self.max_samples * len(index)))

        def grow(t: int):
            seen = bags[t][group]
            rows = np.flatnonzero(seen)
            tree_rng = np.random.default_rng(seeds[t])
            weight = np.bincount(tree_rng.integers(0, len(rows), draws), minlength=len(rows))
            tree = DecisionTreeClassifier(min_samples_leaf=self.min_samples_leaf,
                                          max_features=self.max_features,
                                          random_state=int(seeds[t]))
            tree.fit(x[rows], index[rows], sample_weight=weight.astype(float))
            votes = np.zeros((int((~seen).sum()), len(present)))
            votes[:, np.searchsorted(present, tree.classes_)] = tree.predict_proba(x[~seen])
            return ~seen, votes

        total = np.zeros((len(index), len(present)))
        count = np.zeros(len(index))
        for left_out, votes in Parallel(n_jobs=self.n_jobs, prefer="threads")(
                delayed(grow)(t) for t in range(n_trees)):
            total[left_out] += votes
            count[left_out] += 1
        # a row no tree left out (P = 2^-trees) gets the prior's shares: no vote of its own
        prior = np.bincount(index, minlength=int(present.max()) + 1)[present] / len(index)
        return np.where(count[:, None] > 0, total / np.maximum(count, 1)[:, None], prior)

    def predict_proba(self, X: ArrayLike) -> NDArray[np.float64]:
        """Probability of each range, shape (n_samples, n_ranges), as the product reports it:
        the calibrated probabilities (:meth:`predict_calibrated`), or the training prior on
        every row when the parameter is not determined (``determined_`` False)."""
        if not getattr(self, "determined_", True):
            return np.tile(self.prior_, (_n_rows(X), 1))
        return self.predict_calibrated(X)

    def predict_calibrated(self, X: ArrayLike) -> NDArray[np.float64]:
        """The forest's probabilities, shape (n_samples, n_ranges): calibrated when the fit
        could calibrate (``calibrated_``), else its vote shares; whether or not the parameter
        is determined."""
        votes = self.predict_votes(X)
        if getattr(self, "calibrator_", None) is None:
            return votes
        present = np.asarray(self.forest_.classes_, int)
        return self._expand(self.calibrator_.predict_proba(votes[:, present]),
                            self.calibrator_.classes_)

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


def _n_rows(X: ArrayLike) -> int:
    return int(getattr(X, "shape", (len(X),))[0])  # type: ignore[arg-type]
