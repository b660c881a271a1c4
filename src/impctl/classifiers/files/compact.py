"""The range forests as plain arrays: classifying a house without loading scikit-learn.

``impctl fit`` classifies one campaign row per run. With the pickled forests that costs about
1.4 s of CPU — importing scikit-learn (and the scipy.stats it pulls in) and unpickling three
~25 MB forests — to walk 900 trees once. :func:`save_compact` stores each fitted forest as
scikit-learn's own tree arrays (``tree_.feature``, ``threshold``, ``children_left/right``,
``missing_go_to_left``, ``value``), for a calibrated model the calibration map of
``CalibratedClassifierCV`` (sigmoid ``a_``, ``b_``, or isotonic thresholds), and the training
prior with the determination verdict, in one uncompressed ``forests.npz`` (no pickle: loading
runs no code). :class:`CompactForest` reproduces ``RangeClassifier.predict_proba`` from them.

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
COMPACT_FORMAT = 2
COMPACT_FILE = "forests.npz"
#: Largest |difference| between scikit-learn's and the arrays' probabilities accepted on export.
EXPORT_TOLERANCE = 1e-9
_LEAF = -1


class CompactForest:
    """One range classifier's forest (and calibration) as arrays.

    Attributes mirror :class:`~.estimator.RangeClassifier` where :func:`~.saved.classify_with`
    reads them: ``classes_`` (range labels), ``ranges``, ``calibrated_``, ``determined_``,
    ``prior_``.
    """

    def __init__(self, arrays: dict[str, NDArray]):
        self._a = arrays
        self.classes_ = np.asarray(arrays["labels"]).astype(str)
        self.ranges = [tuple(float(v) for v in r) for r in arrays["ranges"]]
        self.method = str(arrays["method"])
        self.calibrated_ = self.method != "none"
        self.determined_ = bool(arrays["determined"])
        self.prior_ = np.asarray(arrays["prior"], dtype=np.float64)

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
        """Probability of each range, shape (n_samples, n_ranges), as
        ``RangeClassifier.predict_proba``: the training prior when the parameter is not
        determined, else :meth:`predict_calibrated`."""
        if not self.determined_:
            x = np.asarray(X)
            return np.tile(self.prior_, (1 if x.ndim == 1 else x.shape[0], 1))
        return self.predict_calibrated(X)

    def predict_calibrated(self, X: ArrayLike) -> NDArray[np.float64]:
        """The calibrated probabilities of the votes when the model was calibrated, else the
        vote shares, shape (n_samples, n_ranges)."""
        a = self._a
        votes = self.votes(X)
        if self.calibrated_:
            votes = _calibrated(votes, self.method, a)
        out = np.zeros((votes.shape[0], len(self.classes_)))
        out[:, a["forest_classes"]] = votes
        return out


def _calibrated(votes: NDArray, method: str, a: dict[str, NDArray]) -> NDArray[np.float64]:
    """scikit-learn's ``_CalibratedClassifier.predict_proba`` (one calibrated classifier,
    method "sigmoid" or "isotonic"): one-vs-rest maps of the votes, normalised."""
    n = votes.shape[1]
    cols = [1] if n == 2 else range(n)   # binary: one map, on the second class's votes
    maps = np.column_stack([_one_map(votes[:, c], i, method, a) for i, c in enumerate(cols)])
    if n == 2:
        proba = np.column_stack([1.0 - maps[:, 0], maps[:, 0]])
    else:
        total = maps.sum(axis=1, keepdims=True)
        proba = np.divide(maps, total, out=np.full_like(maps, 1.0 / n), where=total != 0)
    proba[(proba > 1.0) & (proba <= 1.0 + 1e-5)] = 1.0
    return proba


def _one_map(p: NDArray, i: int, method: str, a: dict[str, NDArray]) -> NDArray[np.float64]:
    if method == "sigmoid":
        return 1.0 / (1.0 + np.exp(a["sigmoid_a"][i] * p + a["sigmoid_b"][i]))
    lo, hi = a["iso_offsets"][i], a["iso_offsets"][i + 1]
    x, y = a["iso_x"][lo:hi], a["iso_y"][lo:hi]
    if x.size == 1:
        return np.full(p.shape, y[0])
    return np.interp(np.clip(p, x[0], x[-1]), x, y)   # IsotonicRegression, out_of_bounds="clip"


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
    method, maps = "none", {}
    calibrator = getattr(model, "calibrator_", None)
    if calibrator is not None:
        method = calibrator.method
        if method not in ("sigmoid", "isotonic") or len(calibrator.calibrated_classifiers_) != 1:
            raise ValueError("only one sigmoid or isotonic calibrated classifier is expressed")
        cal = calibrator.calibrated_classifiers_[0]
        if list(cal.classes) != list(forest.classes_):
            raise ValueError("calibrator and forest classes differ")
        maps = _calibration_arrays(method, cal.calibrators)
    return {
        "format": np.array(COMPACT_FORMAT), "labels": np.asarray(model.classes_).astype(str),
        "ranges": np.asarray(model.ranges, dtype=np.float64),
        "forest_classes": np.asarray(forest.classes_, dtype=np.int64),
        "roots": np.array(roots, dtype=np.int64), "feature": np.concatenate(feature),
        "threshold": np.concatenate(threshold), "left": np.concatenate(left),
        "right": np.concatenate(right), "missing_left": np.concatenate(missing),
        "leaf_proba": np.concatenate(proba), "method": np.array(method),
        "determined": np.array(bool(getattr(model, "determined_", True))),
        "prior": np.asarray(getattr(model, "prior_", np.full(len(model.classes_),
                                                             1.0 / len(model.classes_))),
                            dtype=np.float64),
        **maps,
    }


def _calibration_arrays(method: str, calibrators) -> dict[str, NDArray]:
    """The one-vs-rest calibration maps as arrays: sigmoid (a, b) per map, or every isotonic
    map's thresholds concatenated with their offsets."""
    if method == "sigmoid":
        return {"sigmoid_a": np.array([c.a_ for c in calibrators], dtype=np.float64),
                "sigmoid_b": np.array([c.b_ for c in calibrators], dtype=np.float64)}
    xs = [np.asarray(c.X_thresholds_, dtype=np.float64) for c in calibrators]
    ys = [np.asarray(c.y_thresholds_, dtype=np.float64) for c in calibrators]
    return {"iso_x": np.concatenate(xs), "iso_y": np.concatenate(ys),
            "iso_offsets": np.cumsum([0] + [len(x) for x in xs]).astype(np.int64)}


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
    from ...atomic import replacing

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
            compact = CompactForest(arrays)
            diff = max(np.abs(compact.predict_proba(rows) - model.predict_proba(rows_in)).max(),
                       np.abs(compact.predict_calibrated(rows)
                              - model.predict_calibrated(rows_in)).max())
            if not diff <= EXPORT_TOLERANCE:
                raise ValueError(f"{name}: arrays differ from scikit-learn by {diff:.2g}")
            payload.update({f"{name}/{k}": v for k, v in arrays.items()})
    except Exception:  # an optional speed-up: never let it fail the training that saves models
        target.unlink(missing_ok=True)
        return None
    with replacing(target, suffix=".tmp.npz") as tmp:
        np.savez(tmp, **payload)
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
