"""What the classes can reach when the nights' quantities are known: the information ceiling.

Run:  .venv/bin/python bench/classify_ceiling.py [--train 8000] [--test 4000] [--seed 0]
          [--noise 0,0.05,0.10,0.20,0.18/0.15/0.20]

Night data determine the heat-loss coefficient HLC, the time constant τ and the capacity
C_m = τ·HLC (../shared/reference/identifiability.md §2–3); floor area, c_f and wall U enter the
nights only through them. This bench gives a random forest (the classifiers' settings) the
TRUE HLC, τ and C_m of virtual households of the population prior — each multiplied by a
log-normal error of the given relative SD (one for all, or HLC/τ/C_m), independent per
quantity, to stand for a fit's or a feature's error — and scores its class accuracy on other
households of the same prior against the majority class, with 95 % bootstrap intervals over
test households. No simulated night can carry more than the exact HLC, τ and C_m (plus the
5R1C's split of the conductances, which the nights do not determine, identifiability.md §3),
so a class that stays near its majority here is not determined by night data under this
prior, whatever the features.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np
import pandas as pd
from sklearn.ensemble import RandomForestClassifier

from impctl.population.households import sample_population
from impctl.population.ranges import DEFAULT_RANGES, bin_values


def _features(table: pd.DataFrame, sd: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """log HLC, log τ, log C_m, with log-normal errors of relative SDs ``sd`` (3 values)."""
    cols = ("hlc_w_per_k", "tau_h", "c_m_j_per_k")
    x = np.log(table[list(cols)].to_numpy(float))
    return x + rng.normal(0.0, 1.0, x.shape) * sd[None, :]


def _sds(text: str) -> np.ndarray:
    v = [float(s) for s in text.split("/")]
    return np.array(v * 3 if len(v) == 1 else v)


def _ci(hits: np.ndarray, boot: np.ndarray) -> str:
    m = hits[boot].mean(axis=1) * 100
    lo, hi = np.percentile(m, [2.5, 97.5])
    return f"{hits.mean() * 100:.1f} [{lo:.1f}, {hi:.1f}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train", type=int, default=8000)
    ap.add_argument("--test", type=int, default=4000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--noise", default="0,0.05,0.10,0.20",
                    help="relative SDs of the error put on HLC, τ and C_m (comma-separated; "
                         "an item H/T/C gives each its own)")
    args = ap.parse_args()
    print(f"command: {' '.join([os.path.basename(sys.executable), *sys.argv])}")
    train = sample_population(args.train, args.seed)
    test = sample_population(args.test, args.seed + 1)   # another seed: households never seen
    boot = np.random.default_rng(0).integers(0, args.test, (2000, args.test))
    print(f"{args.train} training / {args.test} test households of the population prior "
          "(impctl.population.households); accuracy % with 95 % bootstrap intervals\n")
    print("| parameter | error SD on HLC / τ / C_m | accuracy | majority | margin (points) |")
    print("|---|---|---|---|---|")
    for name, ranges in DEFAULT_RANGES.items():
        y_train = bin_values(train[name].to_numpy(float), ranges)
        y_test = bin_values(test[name].to_numpy(float), ranges)
        majority = (y_test == np.bincount(y_train).argmax()).astype(float)
        for text in args.noise.split(","):
            sd = _sds(text)
            rng = np.random.default_rng(args.seed + 7)
            forest = RandomForestClassifier(300, min_samples_leaf=5, random_state=args.seed,
                                            n_jobs=1)
            forest.fit(_features(train, sd, rng), y_train)
            hit = (forest.predict(_features(test, sd, rng)) == y_test).astype(float)
            label = " / ".join(f"{v:.0%}" for v in sd) if len(set(sd)) > 1 else f"{sd[0]:.0%}"
            print(f"| {name} | {label} | {_ci(hit, boot)} | {majority.mean() * 100:.1f} | "
                  f"{_ci(hit - majority, boot)} |")


if __name__ == "__main__":
    main()
