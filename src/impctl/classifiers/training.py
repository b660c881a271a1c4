"""Training and evaluating the range classifiers on a virtual-population dataset.

* Split BY HOUSEHOLD: a seeded permutation puts ``test_fraction`` of the households aside; none of
  their nights is seen in training.
* Training rows: for every training household its full campaign (all nights) plus
  ``campaigns_per_household`` random campaigns of 0…``max_constrained`` constrained and
  0…``max_normal`` normal nights (:func:`~.campaign.random_campaigns`), so the forests also know
  the few-night campaigns a real house delivers.
  Each training household also gets one campaign as the gateway delivers it (below): the rows
  on which the classifier's determination test is judged (:class:`RangeClassifier`).
* Test rows: each test household once with all its nights ("household level"), and
  ``test_campaigns`` times with a realistic campaign of ``small_campaign`` = (2 constrained, 6
  normal) nights, its constrained nights as the gateway's fixed campaign gets them
  (:func:`~.campaign.gateway_campaigns`: invalid ones retried, at most 3; a household may end
  with fewer).
* Baselines: the training majority class, and the same forest trained on labels shuffled across
  training households (what the features add beyond the class priors).
* Probabilities: calibrated on held-out votes of the training households (out of the bag by
  household)
  (:class:`RangeClassifier`); on the small-campaign test rows the Brier score and expected
  calibration error of the calibrated probabilities, the raw vote shares and the training
  prior, and their reliability bins. Accuracies with 95 % bootstrap intervals over test
  households.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, replace

import numpy as np
import pandas as pd

from ..population.dataset import Dataset
from ..population.ranges import PAPER_TABLE_III, bin_values, labels_of, validate_ranges
from .campaign import (
    CAMPAIGN_FEATURE_NAMES,
    aggregate_nights,
    gateway_campaigns,
    night_cube,
    random_campaigns,
)
from .estimator import RangeClassifier


@dataclass(frozen=True)
class TrainConfig:
    """Split, campaign sampling and forest settings (fixed a priori, not tuned on test data)."""

    test_fraction: float = 0.2
    campaigns_per_household: int = 8
    max_constrained: int = 4
    max_normal: int = 8
    small_campaign: tuple[int, int] = (2, 6)
    #: small campaigns drawn per test household (one draw moves c_f's accuracy by points)
    test_campaigns: int = 5
    #: 100 trees, each on half the rows: about a quarter of 300 full trees' CPU, the same classes,
    #: probabilities and search ranges over three seeds (bench/classify_paired.py; decision
    #: record 0030)
    n_estimators: int = 100
    min_samples_leaf: int = 8
    #: rows drawn for each tree (a fraction of the training rows; None: all, bootstrapped)
    max_samples: float | None = 0.5
    n_jobs: int = -1
    #: calibration map of the class probabilities (:class:`RangeClassifier`); isotonic was
    #: chosen on a development population (seed 1): mean Brier 0.334 against sigmoid's 0.338,
    #: ECE 0.037 against 0.038 over both plants' three classes (bench/classify_calibration.py)
    calibration: str | None = "isotonic"
    #: where the calibration's held-out votes come from (:class:`RangeClassifier`'s ``cv``):
    #: "oob", trees grown on half the households each, every row voted on by those that left
    #: its household out — the classes, probabilities and search ranges of five-fold
    #: cross-validation at about half the training CPU (bench/classify_paired.py; decision
    #: record 0030)
    cv: int | str = "oob"
    #: campaign features the forests use (:data:`~.campaign.CAMPAIGN_FEATURE_NAMES` order);
    #: None: all of them. For measuring what a feature adds (bench/classify_compare.py).
    features: tuple[str, ...] | None = None


@dataclass
class ParameterReport:
    """Accuracy of one parameter's classifier; accuracies are fractions 0–1.

    ``confusion[i][j]`` counts test households of range i predicted as range j (all nights).
    """

    parameter: str
    labels: list[str]
    train_accuracy: float
    test_accuracy: float
    test_accuracy_small: float
    majority_accuracy: float
    shuffled_accuracy: float
    confusion: list[list[int]]
    test_class_counts: list[int]
    paper_train_accuracy: float | None
    paper_test_accuracy: float | None
    n_train_households: int
    n_test_households: int
    test_households: list[int]
    #: multi-class Brier score Σ_k (p_k − [y = k])², mean over test households with the
    #: small campaign: calibrated probabilities, the forest's vote shares, the training prior
    brier: float | None = None
    brier_votes: float | None = None
    brier_prior: float | None = None
    calibrated: bool = False
    #: the classifier reports its classes (else the prior: not determined by the nights), and
    #: the held-out accuracy and majority it was judged on (training households)
    determined: bool = True
    cv_accuracy: float | None = None
    cv_majority: float | None = None
    cv_margin_low: float | None = None
    #: small-campaign accuracy of the calibrated forest (whether or not determined), its 95 %
    #: bootstrap interval, the majority class's, and the margin's interval (fractions)
    forest_accuracy_small: float | None = None
    forest_accuracy_small_ci: tuple[float, float] | None = None
    majority_accuracy_small: float | None = None
    margin_small_ci: tuple[float, float] | None = None
    #: top-label expected calibration error (10 bins) of the small-campaign probabilities:
    #: calibrated forest, vote shares
    ece: float | None = None
    ece_votes: float | None = None
    #: reliability of the small-campaign probabilities, every class one-vs-rest in 10 bins:
    #: [[mean predicted, observed frequency, count], ...] for calibrated and vote shares
    reliability: list[list[float]] | None = None
    reliability_votes: list[list[float]] | None = None

    def as_dict(self) -> dict:
        """Plain-JSON form."""
        return asdict(self)


def household_split(n: int, test_fraction: float, rng: np.random.Generator
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Indices (train, test) of ``n`` households, ``test_fraction`` of them (≥ 1) in test.

    Whole households go to one side: every campaign row is built from one household's nights.
    """
    n_test = max(1, int(round(test_fraction * n)))
    if n - n_test < 2:
        raise ValueError(f"{n} households are too few to split")
    order = rng.permutation(n)
    return np.sort(order[n_test:]), np.sort(order[:n_test])


def brier_score(proba: np.ndarray, y: np.ndarray) -> float:
    """Multi-class Brier score: mean over rows of Σ_k (p_k − [y = k])² (0 best, 2 worst)."""
    onehot = np.eye(proba.shape[1])[y]
    return float(np.mean(np.sum((proba - onehot) ** 2, axis=1)))


def reliability_bins(proba: np.ndarray, y: np.ndarray, n_bins: int = 10) -> list[list[float]]:
    """Every class one-vs-rest: [[mean predicted, observed frequency, count]] per non-empty
    probability bin."""
    p = proba.ravel()
    hit = (np.eye(proba.shape[1])[y]).ravel()
    idx = np.minimum((p * n_bins).astype(int), n_bins - 1)
    out = []
    for b in range(n_bins):
        m = idx == b
        if m.any():
            out.append([float(p[m].mean()), float(hit[m].mean()), int(m.sum())])
    return out


def expected_calibration_error(proba: np.ndarray, y: np.ndarray, n_bins: int = 10) -> float:
    """Top-label expected calibration error: the most probable class's probability against
    how often it is right, |frequency − mean probability| weighted over ``n_bins`` equal-width
    bins (0 perfect)."""
    top = proba.max(axis=1)
    hit = (proba.argmax(axis=1) == y).astype(float)
    idx = np.minimum((top * n_bins).astype(int), n_bins - 1)
    return float(sum(abs(hit[idx == b].mean() - top[idx == b].mean()) * np.mean(idx == b)
                     for b in range(n_bins) if np.any(idx == b)))


def bootstrap_ci(per_group: np.ndarray, n_boot: int = 2000, seed: int = 0
                 ) -> tuple[float, float]:
    """95 % percentile bootstrap interval of the mean of ``per_group`` (one value per
    household), resampling households."""
    draws = np.random.default_rng(seed).integers(0, len(per_group), (n_boot, len(per_group)))
    lo, hi = np.percentile(per_group[draws].mean(axis=1), [2.5, 97.5])
    return float(lo), float(hi)


def _forest(cfg: TrainConfig, ranges, seed: int) -> RangeClassifier:
    return RangeClassifier(ranges, n_estimators=cfg.n_estimators,
                           min_samples_leaf=cfg.min_samples_leaf,
                           max_samples=cfg.max_samples, random_state=seed,
                           n_jobs=cfg.n_jobs, calibration=cfg.calibration, cv=cfg.cv)


def train_classifiers(
    dataset: Dataset,
    config: TrainConfig | None = None,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
    *,
    with_baselines: bool = True,
) -> tuple[dict[str, RangeClassifier], dict[str, ParameterReport]]:
    """Train one :class:`RangeClassifier` per ranged parameter and evaluate it.

    Parameters
    ----------
    dataset : Dataset
        From :func:`~impctl.population.dataset.generate_dataset`; its manifest's ranges are used.
    config : TrainConfig, optional
    seed : int
        Seeds the split, the campaigns and the forests.
    progress : callable, optional
        Called with 1 after each forest is trained.
    with_baselines : bool
        Also train the shuffled-label forests (doubles the training time).

    Returns
    -------
    models : dict parameter → fitted RangeClassifier (trained on the training households)
    reports : dict parameter → ParameterReport
    """
    cfg = config or TrainConfig()
    ranges = validate_ranges({k: tuple(map(tuple, v))
                              for k, v in dataset.manifest["ranges"].items()})
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x7EA1]))
    values, ids = night_cube(dataset.nights)
    layout = values[:, :, 0] == 1.0  # is_constrained is the first night feature
    if not (layout == layout[0]).all():
        raise ValueError("households must share one night layout")
    households = dataset.households.set_index("household").loc[ids]
    n = len(ids)
    train, test = household_split(n, cfg.test_fraction, rng)

    per = cfg.campaigns_per_household
    masks = random_campaigns(layout[0], len(train) * per, rng, cfg.max_constrained,
                             cfg.max_normal)
    # one campaign per training household as the gateway delivers it: the determination test's
    # rows (the campaign the product classifies)
    gate = gateway_campaigns(values[train], rng, n_constrained=cfg.small_campaign[0],
                             n_normal=cfg.small_campaign[1])
    rows = np.concatenate([train, np.repeat(train, per), train])
    masks = np.concatenate([np.ones((len(train), layout.shape[1]), bool), masks, gate])
    score_rows = np.arange(len(rows) - len(train), len(rows))
    x_train = aggregate_nights(values[rows], masks)
    x_train_full = x_train[: len(train)]
    x_test = aggregate_nights(values[test], np.ones((len(test), layout.shape[1]), bool))
    # The small campaigns as the gateway delivers them: invalid constrained nights retried.
    k = max(1, int(cfg.test_campaigns))
    small_rows = np.repeat(test, k)
    small = gateway_campaigns(values[small_rows], rng, n_constrained=cfg.small_campaign[0],
                              n_normal=cfg.small_campaign[1])
    x_small = aggregate_nights(values[small_rows], small)

    unknown = set(cfg.features or ()) - set(CAMPAIGN_FEATURE_NAMES)
    if unknown:
        raise ValueError(f"unknown campaign features: {sorted(unknown)}")
    used = [f for f in CAMPAIGN_FEATURE_NAMES if cfg.features is None or f in cfg.features]

    def frame(x):
        return pd.DataFrame(x, columns=list(CAMPAIGN_FEATURE_NAMES))[used]

    models: dict[str, RangeClassifier] = {}
    reports: dict[str, ParameterReport] = {}
    for name, rs in ranges.items():
        truth = households[name].to_numpy(dtype=float)
        model = _forest(cfg, rs, seed).fit(frame(x_train), truth[rows], groups=rows,
                                           score_rows=score_rows)
        if progress is not None:
            progress(1)
        labels = labels_of(rs)
        y_test = bin_values(truth[test], rs)
        pred = bin_values_from_labels(model.predict(frame(x_test)), labels)
        confusion = np.zeros((len(rs), len(rs)), int)
        np.add.at(confusion, (y_test, pred), 1)
        train_classes = bin_values(truth[train], rs)
        majority = np.bincount(train_classes, minlength=len(rs)).argmax()
        shuffled = float("nan")
        if with_baselines:
            perm = np.empty(n, int)
            perm[train] = rng.permutation(train)
            # vote shares suffice for a baseline's accuracy: no calibration
            sham = _forest(replace(cfg, calibration=None), rs, seed).fit(
                frame(x_train), truth[perm[rows]], groups=rows)
            shuffled = sham.score(frame(x_test), truth[test])
            if progress is not None:
                progress(1)
        y_small = bin_values(truth[small_rows], rs)
        p_out = model.predict_proba(frame(x_small))
        p_cal = model.predict_calibrated(frame(x_small))
        p_votes = model.predict_votes(frame(x_small))
        prior = np.bincount(train_classes, minlength=len(rs)) / len(train_classes)

        def per_house(v):
            return np.asarray(v, float).reshape(-1, k).mean(axis=1)

        hit_cal = per_house(p_cal.argmax(axis=1) == y_small)
        hit_major = per_house(y_small == majority)
        paper = PAPER_TABLE_III.get(name, (None, None))
        reports[name] = ParameterReport(
            parameter=name,
            labels=labels,
            train_accuracy=model.score(frame(x_train_full), truth[train]),
            test_accuracy=float(np.mean(pred == y_test)),
            test_accuracy_small=float(np.mean(p_out.argmax(axis=1) == y_small)),
            majority_accuracy=float(np.mean(y_test == majority)),
            shuffled_accuracy=shuffled,
            confusion=confusion.tolist(),
            test_class_counts=np.bincount(y_test, minlength=len(rs)).tolist(),
            paper_train_accuracy=paper[0],
            paper_test_accuracy=paper[1],
            n_train_households=int(len(train)),
            n_test_households=int(len(test)),
            test_households=ids[test].tolist(),
            brier=brier_score(p_cal, y_small),
            brier_votes=brier_score(p_votes, y_small),
            brier_prior=brier_score(np.tile(prior, (len(y_small), 1)), y_small),
            calibrated=bool(model.calibrated_),
            reliability=reliability_bins(p_cal, y_small),
            reliability_votes=reliability_bins(p_votes, y_small),
            determined=bool(model.determined_),
            cv_accuracy=_finite(model.cv_accuracy_),
            cv_majority=_finite(model.cv_majority_),
            cv_margin_low=_finite(model.cv_margin_low_),
            forest_accuracy_small=float(hit_cal.mean()),
            forest_accuracy_small_ci=bootstrap_ci(hit_cal),
            majority_accuracy_small=float(hit_major.mean()),
            margin_small_ci=bootstrap_ci(hit_cal - hit_major),
            ece=expected_calibration_error(p_cal, y_small),
            ece_votes=expected_calibration_error(p_votes, y_small),
        )
        models[name] = model
    return models, reports


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def bin_values_from_labels(predicted: np.ndarray, labels: list[str]) -> np.ndarray:
    """Range indices of predicted labels."""
    lookup = {label: i for i, label in enumerate(labels)}
    return np.array([lookup[p] for p in predicted], int)
