"""The range forests as plain arrays: classifying a house without loading scikit-learn.

``impctl fit`` classifies one campaign row per run. With the pickled forests that costs about
1.4 s of CPU — importing scikit-learn (and the scipy.stats it pulls in) and unpickling three
~25 MB forests — to walk 900 trees once. :func:`save_compact` stores each fitted forest as
scikit-learn's own tree arrays (``tree_.feature``, ``threshold``, ``children_left/right``,
``missing_go_to_left``, ``value``) and, for a calibrated model, the sigmoid ``a_``, ``b_`` of
``CalibratedClassifierCV``, in one uncompressed ``forests.npz`` (no pickle: loading runs no
code). :class:`CompactForest` reproduces ``RangeClassifier.predict_proba`` from them.

Every export is checked against scikit-learn before it is written: probe rows around the trees'
thresholds (and with missing features) must give the same probabilities to 1e-9, else no
compact file is written and readers keep using the pickled forests (``load_compact`` returns
None). The pickled forests stay the reference: training and the reports use them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Bumped when the array layout changes; a reader refuses other formats (and falls back).
COMPACT_FORMAT = 1
COMPACT_FILE = "forests.npz"
#: Largest |difference| between scikit-learn's and the arrays' probabilities accepted on export.
EXPORT_TOLERANCE = 1e-9
_LEAF = -1


class CompactForest:
    """One range classifier's forest (and calibration) as arrays.

    Attributes mirror :class:`~.estimator.RangeClassifier` where :func:`~.saved.classify_with`
    reads them: ``classes_`` (range labels), ``ranges``, ``calibrated_``.
    """

    def __init__(self, arrays: dict[str, NDArray]):
        self._a = arrays
        self.classes_ = np.asarray(arrays["labels"]).astype(str)
        self.ranges = [tuple(float(v) for v in r) for r in arrays["ranges"]]
        self.calibrated_ = bool(arrays["sigmoid_a"].size)

    def votes(self, X: ArrayLike) -> NDArray[np.float64]:
        """The forest's vote shares over its own classes, shape (n_samples, n_forest_classes).

        As scikit-learn: features as float32, ``x <= threshold`` goes left, a missing (NaN)
        feature goes where training sent missing values; each tree's leaf class fractions,
        averaged over the trees.
        """
        a = self._a
        x = np.asarray(X, dtype=np.float32).astype(np.float64)
        if x.ndim == 1:
            x = x[None, :]
        rows = np.arange(x.shape[0])[:, None]
        node = np.broadcast_to(a["roots"], (x.shape[0], a["roots"].size)).copy()
        feature, threshold = a["feature"], a["threshold"]
        while True:
            f = feature[node]
            inner = f != _LEAF
            if not inner.any():
                break
            v = x[rows, np.where(inner, f, 0)]
            left = np.where(np.isnan(v), a["missing_left"][node], v <= threshold[node])
            node = np.where(inner, np.where(left, a["left"][node], a["right"][node]), node)
        return a["leaf_proba"][node].mean(axis=1)

    def predict_proba(self, X: ArrayLike) -> NDArray[np.float64]:
        """Probability of each range, shape (n_samples, n_ranges): the calibrated sigmoid of
        the votes when the model was calibrated, else the vote shares."""
        a = self._a
        votes = self.votes(X)
        forest_classes = a["forest_classes"]
        if self.calibrated_:
            votes = _sigmoid_calibrated(votes, a["sigmoid_a"], a["sigmoid_b"])
        out = np.zeros((votes.shape[0], len(self.classes_)))
        out[:, forest_classes] = votes
        return out


def _sigmoid_calibrated(votes: NDArray, a: NDArray, b: NDArray) -> NDArray[np.float64]:
    """scikit-learn's ``_CalibratedClassifier.predict_proba`` (method "sigmoid", one
    calibrated classifier): one-vs-rest sigmoids ``1/(1 + exp(a·p + b))``, normalised."""
    n = votes.shape[1]
    if n == 2:   # one calibrator, on the second class's votes
        p1 = 1.0 / (1.0 + np.exp(a[0] * votes[:, 1] + b[0]))
        proba = np.column_stack([1.0 - p1, p1])
    else:
        proba = 1.0 / (1.0 + np.exp(a[None, :] * votes + b[None, :]))
        total = proba.sum(axis=1, keepdims=True)
        proba = np.divide(proba, total, out=np.full_like(proba, 1.0 / n), where=total != 0)
    proba[(proba > 1.0) & (proba <= 1.0 + 1e-5)] = 1.0
    return proba


def export_arrays(model) -> dict[str, NDArray]:
    """The arrays of a fitted :class:`~.estimator.RangeClassifier` (scikit-learn needed here).

    Raises
    ------
    ValueError
        A model this layout cannot express (several outputs, another calibration, an ensemble
        of calibrated classifiers).
    """
    forest = model.forest_
    feature, threshold, left, right, missing, proba, roots = [], [], [], [], [], [], []
    offset = 0
    for tree in (e.tree_ for e in forest.estimators_):
        if tree.n_outputs != 1:
            raise ValueError("multi-output trees")
        inner = tree.children_left != -1
        roots.append(offset)
        feature.append(np.where(inner, tree.feature, _LEAF).astype(np.int32))
        threshold.append(tree.threshold.astype(np.float64))
        left.append(np.where(inner, tree.children_left + offset, -1).astype(np.int32))
        right.append(np.where(inner, tree.children_right + offset, -1).astype(np.int32))
        missing.append(np.asarray(tree.missing_go_to_left, dtype=bool))
        value = tree.value[:, 0, :].astype(np.float64)
        norm = value.sum(axis=1, keepdims=True)
        norm[norm == 0.0] = 1.0   # as DecisionTreeClassifier.predict_proba
        proba.append(value / norm)
        offset += tree.node_count
    sig_a = sig_b = np.zeros(0)
    calibrator = getattr(model, "calibrator_", None)
    if calibrator is not None:
        if calibrator.method != "sigmoid" or len(calibrator.calibrated_classifiers_) != 1:
            raise ValueError("only one sigmoid-calibrated classifier is expressed")
        cal = calibrator.calibrated_classifiers_[0]
        if list(cal.classes) != list(forest.classes_):
            raise ValueError("calibrator and forest classes differ")
        sig_a = np.array([c.a_ for c in cal.calibrators], dtype=np.float64)
        sig_b = np.array([c.b_ for c in cal.calibrators], dtype=np.float64)
    return {
        "format": np.array(COMPACT_FORMAT), "labels": np.asarray(model.classes_).astype(str),
        "ranges": np.asarray(model.ranges, dtype=np.float64),
        "forest_classes": np.asarray(forest.classes_, dtype=np.int64),
        "roots": np.array(roots, dtype=np.int64), "feature": np.concatenate(feature),
        "threshold": np.concatenate(threshold), "left": np.concatenate(left),
        "right": np.concatenate(right), "missing_left": np.concatenate(missing),
        "leaf_proba": np.concatenate(proba), "sigmoid_a": sig_a, "sigmoid_b": sig_b,
    }


def probe_rows(arrays: dict[str, NDArray], n_features: int, n_rows: int = 300,
               seed: int = 0) -> NDArray[np.float64]:
    """Rows that exercise the trees: feature values at, just below and just above split
    thresholds (float32 rounding included), and a missing feature in a tenth of the cells."""
    rng = np.random.default_rng(seed)
    inner = arrays["feature"] != _LEAF
    x = np.empty((n_rows, n_features))
    for j in range(n_features):
        thr = arrays["threshold"][inner & (arrays["feature"] == j)]
        thr = thr[np.isfinite(thr)]   # +inf: a split of missing against present values
        if thr.size == 0:
            x[:, j] = rng.normal(size=n_rows)
            continue
        base = rng.choice(thr, n_rows)
        step = rng.choice([-1.0, 0.0, 1.0], n_rows) * np.maximum(np.abs(base), 1.0) * 1e-6
        x[:, j] = np.float32(base + step)
    x[rng.random(x.shape) < 0.1] = np.nan
    return x


def save_compact(models: dict, directory: str | Path) -> Path | None:
    """Write ``forests.npz`` for ``models`` (parameter → fitted RangeClassifier) into
    ``directory`` when every forest exports and reproduces scikit-learn's probabilities on
    probe rows; else remove any old file and return None (readers use the pickles)."""
    import os

    directory = Path(directory)
    target = directory / COMPACT_FILE
    try:
        payload = {}
        for name, model in models.items():
            arrays = export_arrays(model)
            rows = probe_rows(arrays, int(model.n_features_in_))
            names = getattr(model, "feature_names_in_", None)
            if names is not None:
                import pandas as pd

                rows_in = pd.DataFrame(rows, columns=list(names))
            else:
                rows_in = rows
            diff = np.abs(CompactForest(arrays).predict_proba(rows)
                          - model.predict_proba(rows_in)).max()
            if not diff <= EXPORT_TOLERANCE:
                raise ValueError(f"{name}: arrays differ from scikit-learn by {diff:.2g}")
            payload.update({f"{name}/{k}": v for k, v in arrays.items()})
    except Exception:  # an optional speed-up: never let it fail the training that saves models
        target.unlink(missing_ok=True)
        return None
    tmp = directory / (COMPACT_FILE + ".tmp.npz")
    np.savez(tmp, **payload)
    os.replace(tmp, target)
    return target


def load_compact(directory: str | Path, names: list[str]) -> dict[str, CompactForest] | None:
    """The compact forests ``names`` of ``directory``, or None when the file is missing,
    unreadable, of another format or lacks one of them (the caller loads the pickles)."""
    path = Path(directory) / COMPACT_FILE
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as npz:
            data = {k: npz[k] for k in npz.files}
    except (OSError, ValueError):
        return None
    out = {}
    for name in names:
        arrays = {k.split("/", 1)[1]: v for k, v in data.items() if k.startswith(name + "/")}
        if "format" not in arrays or int(arrays["format"]) != COMPACT_FORMAT:
            return None
        out[name] = CompactForest(arrays)
    return out or None
