"""Two forest settings, one population per seed, the same test campaigns: paired class scores,
the fit's search ranges, and the training CPU.

Run:  .venv/bin/python bench/classify_paired.py [--seeds 0,1,2] [--households 900]
          [--plant realistic] [--campaigns 5] [--a '{}'] [--b '{"n_estimators": 100}']

``--a`` / ``--b`` are :class:`impctl.classifiers.training.TrainConfig` keyword arguments (JSON);
``{}`` is ``impctl train``'s own setting. For every seed the population is generated once
(``impctl train``'s nights for the plant) and both settings are trained on it as
``impctl train`` trains them (same split, same campaigns; the shuffled-label baselines left out:
they are the report's, not the product's). Every held-out household is scored on
``--campaigns`` campaigns of 2 constrained + 6 normal nights as the gateway's fixed campaign
delivers them, the same draws for A and B. Per seed and parameter, A and B side by side:

* whether the parameter is determined;
* accuracy of the reported classes [%] (the prior's most probable class where not determined);
* Brier score and top-label ECE (10 bins) of the reported probabilities;
* the fit's search range (:func:`impctl.classifiers.files.saved.credible_hull`, the whole
  prior range where not determined): coverage [%] (the true value inside it) and width (the range's
  high / low, the factor the fit searches over);
* B − A of accuracy, Brier and coverage with a 95 % bootstrap interval over test households.

Then the CPU seconds each setting took to train (this process's user + system time around
``train_classifiers``, its worker threads included).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys

import numpy as np
import pandas as pd

from impctl.classifiers.campaign import (
    CAMPAIGN_FEATURE_NAMES,
    aggregate_nights,
    gateway_campaigns,
    night_cube,
)
from impctl.classifiers.files.saved import credible_hull
from impctl.classifiers.training import TrainConfig, train_classifiers
from impctl.population.dataset import generate_dataset
from impctl.population.imp_run.setup import ImpSimConfig
from impctl.population.ranges import bin_values

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from benchlib.calibration import ece  # noqa: E402


def _cpu_s() -> float:
    use = resource.getrusage(resource.RUSAGE_SELF)
    return use.ru_utime + use.ru_stime




def _scores(model, x: pd.DataFrame, values: np.ndarray) -> dict[str, np.ndarray]:
    """Per campaign row: hit, Brier, hull covers the truth, hull high / low."""
    y = bin_values(values, model.ranges)
    p = model.predict_proba(x[list(model.feature_names_in_)])
    hulls = np.array([credible_hull(model.ranges, row) for row in p]) \
        if getattr(model, "determined_", True) else \
        np.tile([model.ranges[0][0], model.ranges[-1][1]], (len(p), 1))
    return {"hit": (p.argmax(axis=1) == y).astype(float),
            "brier": np.sum((p - np.eye(p.shape[1])[y]) ** 2, axis=1),
            "cover": ((hulls[:, 0] <= values) & (values <= hulls[:, 1])).astype(float),
            "width": hulls[:, 1] / hulls[:, 0],
            "proba": p, "y": y}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--households", type=int, default=900)
    ap.add_argument("--campaigns", type=int, default=5)
    ap.add_argument("--plant", choices=("iso", "realistic"), default="realistic")
    ap.add_argument("--a", default="{}", help="TrainConfig keywords of A (JSON)")
    ap.add_argument("--b", action="append", default=None,
                    help="TrainConfig keywords of B (JSON); repeat for C, D, … (each against A)")
    args = ap.parse_args()
    print(f"command: {' '.join([os.path.basename(sys.executable), *sys.argv])}")
    configs = {"A": TrainConfig(**json.loads(args.a))}
    for i, b in enumerate(args.b or ['{"n_estimators": 100}']):
        configs["BCDEFG"[i]] = TrainConfig(**json.loads(b))
    k = args.campaigns
    for seed in (int(s) for s in args.seeds.split(",")):
        dataset = generate_dataset(args.households, seed, plant=args.plant,
                                   imp=ImpSimConfig.for_plant(args.plant))
        trained, cpu = {}, {}
        for key, cfg in configs.items():
            start = _cpu_s()
            trained[key], reports = train_classifiers(dataset, cfg, seed, with_baselines=False)
            cpu[key] = _cpu_s() - start
        test = np.array(next(iter(reports.values())).test_households)
        values, ids = night_cube(dataset.nights[dataset.nights["replay"] == 0])
        cube = np.repeat(values[np.searchsorted(ids, test)], k, 0)
        masks = gateway_campaigns(cube, np.random.default_rng(seed + 12345), 2, 6)
        x = pd.DataFrame(aggregate_nights(cube, masks), columns=list(CAMPAIGN_FEATURE_NAMES))
        truth = dataset.households.set_index("household")
        boot = np.random.default_rng(0).integers(0, len(test), (2000, len(test)))

        def ci(diff: np.ndarray, scale: float, fmt: str, boot=boot) -> str:
            v = diff.reshape(-1, k).mean(axis=1) * scale
            lo, hi = np.percentile(v[boot].mean(axis=1), [2.5, 97.5])
            return f"{v.mean():{fmt}} [{lo:{fmt}}, {hi:{fmt}}]"

        print(f"\nseed {seed}: plant {args.plant}, {args.households} households, {len(test)} "
              f"held out × {k} gateway campaigns; training CPU "
              + ", ".join(f"{key} {c:.1f} s" for key, c in cpu.items()))
        for other in list(configs)[1:]:
            _table(trained, other, x, truth, test, k, ci)


def _table(trained: dict, other: str, x: pd.DataFrame, truth: pd.DataFrame, test: np.ndarray,
           k: int, ci) -> None:
    """A against ``other``, one row per parameter."""
    trained = {"A": trained["A"], "B": trained[other]}
    print(f"\nA against {other}:")
    print("| parameter | determined A / B | accuracy % A / B | B − A points | "
          "Brier A / B | B − A | ECE A / B | search range covers % A / B | B − A points | "
          "width (high/low) A / B |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in trained["A"]:
        v = truth.loc[np.repeat(test, k), name].to_numpy(float)
        s = {key: _scores(trained[key][name], x, v) for key in trained}
        a, b = s["A"], s["B"]
        det = " / ".join("yes" if getattr(trained[key][name], "determined_", True) else "no"
                         for key in trained)
        print(f"| {name} | {det} | {a['hit'].mean() * 100:.1f} / {b['hit'].mean() * 100:.1f}"
              f" | {ci(b['hit'] - a['hit'], 100, '+.1f')} | {a['brier'].mean():.3f} / "
              f"{b['brier'].mean():.3f} | {ci(b['brier'] - a['brier'], 1, '+.3f')} | "
              f"{ece(a['proba'], a['y']):.3f} / {ece(b['proba'], b['y']):.3f} | "
              f"{a['cover'].mean() * 100:.1f} / {b['cover'].mean() * 100:.1f} | "
              f"{ci(b['cover'] - a['cover'], 100, '+.1f')} | "
              f"{np.median(a['width']):.2f} / {np.median(b['width']):.2f} |", flush=True)


if __name__ == "__main__":
    main()
