"""Two virtual populations, one set of test households: paired class accuracy and Brier score.

Run:  .venv/bin/python bench/classify_compare.py [--seed 0] [--campaigns 5] [--plant realistic]
          [--a '{"constrained_per_day": 1}'] [--b '{"constrained_per_day": 3}'] [--cross]

``--a`` / ``--b`` are :class:`impctl.population.virtual_imp.ImpSimConfig` keyword arguments (JSON).
Each population is generated (900 households, same seed: same households and test split) and
the classifiers trained on it as ``impctl train`` does. Every test household is then scored on
``--campaigns`` random campaigns of 2 constrained + 6 normal nights drawn from its nights with
``replay == 0`` (one constrained night per date, as a real household has), the same draws for
both populations: one campaign per household, as ``bench/classify.py`` reports, moves the c_f
accuracy by a few points and its Brier score by ~0.02 from draw to draw. Prints per parameter
accuracy, the majority class, the Brier score and 95 % bootstrap intervals (over test
households) of the B − A Brier difference and of each population's margin over the majority.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np
import pandas as pd

from impctl.classifiers.campaign import (
    CAMPAIGN_FEATURE_NAMES,
    aggregate_nights,
    night_cube,
    random_campaigns,
)
from impctl.classifiers.training import TrainConfig, train_classifiers
from impctl.population.dataset import generate_dataset
from impctl.population.ranges import bin_values
from impctl.population.virtual_imp import ImpSimConfig


def _score(kw: dict, args, trained: tuple | None = None) -> tuple[dict, np.ndarray, tuple]:
    """Per test household and parameter: mean Brier, accuracy and majority hit over campaigns
    of population ``kw``'s nights, scored by ``trained`` = (models, reports) if given, else by
    classifiers trained on that population (returned as the third item)."""
    dataset = generate_dataset(args.households, args.seed, plant=args.plant,
                               imp=ImpSimConfig(**kw))
    if trained is None:
        trained = train_classifiers(dataset, TrainConfig(), args.seed, with_baselines=False)
    models, reports = trained
    values, ids = night_cube(dataset.nights[dataset.nights["replay"] == 0])
    test = np.array(next(iter(reports.values())).test_households)
    k = args.campaigns
    masks = random_campaigns(values[0, :, 0] == 1.0, len(test) * k,
                             np.random.default_rng(args.seed + 12345), n_constrained=2,
                             n_normal=6)
    rows = pd.DataFrame(aggregate_nights(np.repeat(values[np.searchsorted(ids, test)], k, 0),
                                         masks), columns=list(CAMPAIGN_FEATURE_NAMES))
    truth = dataset.households.set_index("household")
    train = np.setdiff1d(truth.index.to_numpy(), test)
    out = {}
    for name, model in models.items():
        y = bin_values(truth.loc[np.repeat(test, k), name].to_numpy(float), model.ranges)
        majority = np.bincount(bin_values(truth.loc[train, name].to_numpy(float),
                                          model.ranges)).argmax()
        p = model.predict_proba(rows)
        brier = np.sum((p - np.eye(p.shape[1])[y]) ** 2, axis=1)
        out[name] = tuple(v.reshape(-1, k).mean(axis=1) for v in
                          (brier, (p.argmax(axis=1) == y).astype(float),
                           (y == majority).astype(float)))
    return out, test, trained


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=900)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--campaigns", type=int, default=5)
    ap.add_argument("--plant", choices=("iso", "realistic"), default="realistic")
    ap.add_argument("--a", default='{"constrained_per_day": 1}')
    ap.add_argument("--b", default='{"constrained_per_day": 3}')
    ap.add_argument("--cross", action="store_true",
                    help="score B's nights with the classifiers trained on A (e.g. A the "
                         "population, B its nights stopped at T_min as the gateway's are)")
    args = ap.parse_args()
    print(f"command: {' '.join([os.path.basename(sys.executable), *sys.argv])}")
    a, test_a, trained_a = _score(json.loads(args.a), args)
    b, test_b, _ = _score(json.loads(args.b), args, trained_a if args.cross else None)
    assert (test_a == test_b).all()
    boot = np.random.default_rng(0).integers(0, len(test_a), (4000, len(test_a)))

    def ci(v: np.ndarray, scale: float = 1.0, fmt: str = "+.3f") -> str:
        m = v[boot].mean(axis=1) * scale
        lo, hi = np.percentile(m, [2.5, 97.5])
        return f"{v.mean() * scale:{fmt}} [{lo:{fmt}}, {hi:{fmt}}]"

    print(f"A = {args.a}; B = {args.b}{' scored by the classifiers of A' if args.cross else ''}; "
          f"{len(test_a)} test households × {args.campaigns} "
          "campaigns of 2 + 6 nights; 95 % bootstrap intervals over households\n")
    print("| parameter | accuracy A / B % | majority % | Brier A / B | Brier B − A | "
          "margin over majority A / B (points) |")
    print("|---|---|---|---|---|---|")
    for name in a:
        (ba, aa, ma), (bb, ab, _) = a[name], b[name]
        print(f"| {name} | {aa.mean() * 100:.1f} / {ab.mean() * 100:.1f} | {ma.mean() * 100:.1f} "
              f"| {ba.mean():.3f} / {bb.mean():.3f} | {ci(bb - ba)} | "
              f"{ci(aa - ma, 100, '+.1f')} / {ci(ab - ma, 100, '+.1f')} |")


if __name__ == "__main__":
    main()
