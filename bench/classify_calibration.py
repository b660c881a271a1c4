"""Class accuracy and calibration on held-out households, as the product reports the classes.

Run:  .venv/bin/python bench/classify_calibration.py [--plant realistic|iso] [--households 900]
          [--seed 0] [--campaigns 5] [--calibration sigmoid|isotonic] [--min-samples-leaf N]

Generates the population (``impctl train``'s nights for the plant), trains the classifiers as
``impctl train`` does (80 % of the households, split by household) and scores each held-out
household on ``--campaigns`` campaigns of 2 constrained + 6 normal nights as the gateway's
fixed campaign delivers them (valid constrained nights only, giving up after 3 invalid),
drawn from its nights with ``replay == 0``. Per parameter: accuracy of the classes the product
reports (the prior's most probable class where a parameter is not determined), of the
calibrated forest, the majority class, the margin over it — each with a 95 % bootstrap
interval over test households — the Brier score and the top-label expected calibration error
(ECE, 10 bins) of the reported probabilities, the calibrated forest's, the vote shares' and
the prior's. Models without ``predict_calibrated`` (older code) report their
``predict_proba`` as calibrated.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np
import pandas as pd

from impctl.classifiers.campaign import (
    CAMPAIGN_FEATURE_NAMES,
    aggregate_nights,
    gateway_campaigns,
    night_cube,
)
from impctl.classifiers.training import TrainConfig, train_classifiers
from impctl.population.dataset import generate_dataset
from impctl.population.imp_run.setup import ImpSimConfig
from impctl.population.ranges import bin_values

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from benchlib.calibration import ece  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=900)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--campaigns", type=int, default=5)
    ap.add_argument("--plant", choices=("iso", "realistic"), default="realistic")
    ap.add_argument("--calibration", default=None,
                    help="calibration map (default TrainConfig's)")
    ap.add_argument("--min-samples-leaf", type=int, default=None,
                    help="the forests' smallest leaf (default TrainConfig's)")
    args = ap.parse_args()
    print(f"command: {' '.join([os.path.basename(sys.executable), *sys.argv])}")
    dataset = generate_dataset(args.households, args.seed, plant=args.plant,
                               imp=ImpSimConfig.for_plant(args.plant))
    kw: dict = {}
    if args.calibration is not None:
        kw["calibration"] = None if args.calibration == "none" else args.calibration
    if args.min_samples_leaf is not None:
        kw["min_samples_leaf"] = args.min_samples_leaf
    cfg = TrainConfig(**kw)
    models, reports = train_classifiers(dataset, cfg, args.seed, with_baselines=False)
    test = np.array(next(iter(reports.values())).test_households)
    values, ids = night_cube(dataset.nights[dataset.nights["replay"] == 0])
    k = args.campaigns
    cube = np.repeat(values[np.searchsorted(ids, test)], k, 0)
    masks = gateway_campaigns(cube, np.random.default_rng(args.seed + 12345), 2, 6)
    rows = pd.DataFrame(aggregate_nights(cube, masks), columns=list(CAMPAIGN_FEATURE_NAMES))
    truth = dataset.households.set_index("household")
    train = np.setdiff1d(truth.index.to_numpy(), test)
    boot = np.random.default_rng(0).integers(0, len(test), (2000, len(test)))

    def ci(per_row: np.ndarray, scale: float = 100.0, fmt: str = ".1f") -> str:
        v = per_row.reshape(-1, k).mean(axis=1) * scale
        lo, hi = np.percentile(v[boot].mean(axis=1), [2.5, 97.5])
        return f"{v.mean():{fmt}} [{lo:{fmt}}, {hi:{fmt}}]"

    print(f"plant {args.plant}, {args.households} households (seed {args.seed}), "
          f"{len(test)} held out × {k} gateway campaigns of 2 + 6 nights; 95 % bootstrap "
          "intervals over test households; the forests' nodes (the size of forests.npz): "
          f"{sum(t.tree_.node_count for m in models.values() for t in m.forest_.estimators_):,}"
          "\n")
    print("| parameter | determined | reported accuracy % | calibrated forest % | majority % | "
          "margin (points) | Brier reported / calibrated / votes / prior | "
          "ECE reported / calibrated / votes |")
    print("|---|---|---|---|---|---|---|---|")
    for name, model in models.items():
        y = bin_values(truth.loc[np.repeat(test, k), name].to_numpy(float), model.ranges)
        counts = np.bincount(bin_values(truth.loc[train, name].to_numpy(float), model.ranges),
                             minlength=len(model.ranges))
        x = rows[list(model.feature_names_in_)]
        p_out = model.predict_proba(x)
        p_cal = getattr(model, "predict_calibrated", model.predict_proba)(x)
        p_votes = model.predict_votes(x)
        p_prior = np.tile(counts / counts.sum(), (len(y), 1))
        onehot = np.eye(p_out.shape[1])[y]
        hit_out = (p_out.argmax(axis=1) == y).astype(float)
        hit_cal = (p_cal.argmax(axis=1) == y).astype(float)
        major = (y == counts.argmax()).astype(float)
        briers = " / ".join(f"{np.mean(np.sum((p - onehot) ** 2, axis=1)):.3f}"
                            for p in (p_out, p_cal, p_votes, p_prior))
        eces = " / ".join(f"{ece(p, y):.3f}" for p in (p_out, p_cal, p_votes))
        det = "yes" if getattr(model, "determined_", True) else "no"
        if hasattr(model, "cv_margin_low_"):
            det += (f" (held-out {model.cv_accuracy_:.1%} vs {model.cv_majority_:.1%}, "
                    f"margin ≥ {100 * model.cv_margin_low_:+.1f})")
        print(f"| {name} | {det} | {ci(hit_out)} | {ci(hit_cal)} | "
              f"{major.mean() * 100:.1f} | {ci(hit_cal - major, fmt='+.1f')} | {briers} | "
              f"{eces} |")


if __name__ == "__main__":
    main()
