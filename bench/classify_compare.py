"""Two virtual populations, one set of test households: paired class accuracy and Brier score.

Run:  .venv/bin/python bench/classify_compare.py [--seed 0] [--campaigns 5] [--plant realistic]
          [--a '{"constrained_per_day": 1}'] [--b '{"constrained_per_day": 3}'] [--cross]
          [--score-on own|a|b] [--features-a NAME,...] [--features-b NAME,...]
          [--campaigns-as gateway|random]

``--a`` / ``--b`` are :class:`impctl.population.imp_run.setup.ImpSimConfig` keyword arguments
(JSON) on top of the nights the gateway records on ``--plant`` (``ImpSimConfig.for_plant``, as
``impctl train`` makes its population: on the realistic plant constrained nights stop at T_min;
``{"stop_at_t_min": false}`` lets them cool to the window's end).
Each population is generated (900 households, same seed: same households and test split) and
the classifiers trained on it as ``impctl train`` does. Every test household is then scored on
``--campaigns`` random campaigns of 2 constrained + 6 normal nights drawn from its nights with
``replay == 0`` (one constrained night per date, as a real household has) — the constrained
ones as the gateway gets them (``--campaigns-as gateway``: valid ones only, giving up after 3
invalid, so a campaign may hold fewer) — the same draws for both populations: one campaign
per household, as ``bench/classify.py`` reports, moves the c_f accuracy by a few points and
its Brier score by ~0.02 from draw to draw. Prints per parameter accuracy, the majority class,
the Brier scores and 95 % bootstrap intervals (over test households) of the B − A Brier
difference, of each population's margin over the majority and of B's Brier over the prior's.
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
    gateway_campaigns,
    night_cube,
    random_campaigns,
)
from impctl.classifiers.training import TrainConfig, train_classifiers
from impctl.imp import NIGHT_FEATURE_NAMES
from impctl.population.dataset import generate_dataset
from impctl.population.imp_run.setup import ImpSimConfig
from impctl.population.ranges import bin_values

_DATASETS: dict[str, object] = {}


def _dataset(kw: dict, args):
    """Population ``kw`` (generated once per run)."""
    key = json.dumps(kw, sort_keys=True)
    if key not in _DATASETS:
        _DATASETS[key] = generate_dataset(args.households, args.seed, plant=args.plant,
                                          imp=ImpSimConfig.for_plant(args.plant, **kw))
    return _DATASETS[key]


def _train(kw: dict, args, features: str | None) -> tuple:
    """(models, reports) of the classifiers trained on population ``kw`` as ``impctl train``
    does; ``features``: comma-separated campaign features they use (None: all)."""
    features = None if features is None else tuple(features.split(","))
    return train_classifiers(_dataset(kw, args), TrainConfig(features=features), args.seed,
                             with_baselines=False)


def _score(kw: dict, args, trained: tuple) -> tuple[dict, np.ndarray]:
    """Per test household and parameter: mean Brier, accuracy and majority hit over campaigns
    of population ``kw``'s nights, scored by ``trained`` = (models, reports)."""
    dataset = _dataset(kw, args)
    models, reports = trained
    values, ids = night_cube(dataset.nights[dataset.nights["replay"] == 0])
    test = np.array(next(iter(reports.values())).test_households)
    k = args.campaigns
    cube = np.repeat(values[np.searchsorted(ids, test)], k, 0)
    rng = np.random.default_rng(args.seed + 12345)
    if args.campaigns_as == "gateway":
        masks = gateway_campaigns(cube, rng, n_constrained=2, n_normal=6)
    else:
        masks = random_campaigns(values[0, :, 0] == 1.0, len(test) * k, rng, n_constrained=2,
                                 n_normal=6)
    n_cons = (masks & (cube[..., 0] == 1.0)).sum(axis=1)
    ix = list(NIGHT_FEATURE_NAMES).index("cooling_time_h")
    invalid = np.isnan(cube[:, cube[0, :, 0] == 1.0, ix]).mean()
    print(f"{json.dumps(kw)}: {invalid:.0%} of the test households' constrained nights invalid; "
          "test campaigns with 0 / 1 / 2 constrained nights: "
          + " / ".join(f"{np.mean(n_cons == c):.0%}" for c in (0, 1, 2)))
    rows = pd.DataFrame(aggregate_nights(cube, masks), columns=list(CAMPAIGN_FEATURE_NAMES))
    truth = dataset.households.set_index("household")
    train = np.setdiff1d(truth.index.to_numpy(), test)
    out = {}
    for name, model in models.items():
        y = bin_values(truth.loc[np.repeat(test, k), name].to_numpy(float), model.ranges)
        counts = np.bincount(bin_values(truth.loc[train, name].to_numpy(float),
                                        model.ranges), minlength=len(model.ranges))
        p = model.predict_proba(rows[list(model.feature_names_in_)])
        onehot = np.eye(p.shape[1])[y]
        brier = np.sum((p - onehot) ** 2, axis=1)
        prior = np.sum((counts / counts.sum() - onehot) ** 2, axis=1)
        out[name] = tuple(v.reshape(-1, k).mean(axis=1) for v in
                          (brier, (p.argmax(axis=1) == y).astype(float),
                           (y == counts.argmax()).astype(float), prior))
    return out, test


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
    ap.add_argument("--score-on", choices=("own", "a", "b"), default="own",
                    help="whose nights the test households are scored on: each population's "
                         "own (default), or both classifiers on A's or on B's nights (e.g. "
                         "both on nights stopped at T_min, as the gateway records them)")
    ap.add_argument("--campaigns-as", choices=("gateway", "random"), default="gateway",
                    help="test campaigns' constrained nights: as the gateway's fixed campaign "
                         "gets them (valid ones until 2, giving up after 3 invalid; default) "
                         "or 2 at random, valid or not (before branch h14x)")
    ap.add_argument("--features-a", default=None,
                    help="comma-separated campaign features A's forests use (default all)")
    ap.add_argument("--features-b", default=None,
                    help="comma-separated campaign features B's forests use (default all)")
    args = ap.parse_args()
    print(f"command: {' '.join([os.path.basename(sys.executable), *sys.argv])}")
    kw_a, kw_b = json.loads(args.a), json.loads(args.b)
    if args.cross and args.score_on != "own":
        ap.error("--cross and --score-on exclude each other")
    trained_a = _train(kw_a, args, args.features_a)
    trained_b = trained_a if args.cross else _train(kw_b, args, args.features_b)
    nights_a = {"own": kw_a, "a": kw_a, "b": kw_b}[args.score_on]
    nights_b = {"own": kw_b, "a": kw_a, "b": kw_b}[args.score_on]
    a, test_a = _score(nights_a, args, trained_a)
    b, test_b = _score(nights_b, args, trained_b)
    assert (test_a == test_b).all()
    boot = np.random.default_rng(0).integers(0, len(test_a), (4000, len(test_a)))

    def ci(v: np.ndarray, scale: float = 1.0, fmt: str = "+.3f") -> str:
        m = v[boot].mean(axis=1) * scale
        lo, hi = np.percentile(m, [2.5, 97.5])
        return f"{v.mean() * scale:{fmt}} [{lo:{fmt}}, {hi:{fmt}}]"

    on = {"own": "", "a": "; both scored on A's nights", "b": "; both scored on B's nights"}
    feats = "".join(f"; {side} uses {f}" for side, f in (("A", args.features_a),
                                                          ("B", args.features_b)) if f)
    by_a = " scored by the classifiers of A" if args.cross else ""
    print(f"A = {args.a}; B = {args.b}{feats}{by_a}{on[args.score_on]}; "
          f"{len(test_a)} test households × {args.campaigns} "
          "campaigns of 2 + 6 nights; 95 % bootstrap intervals over households\n")
    print("| parameter | accuracy A / B % | majority % | Brier A / B | Brier B − A | "
          "margin over majority A / B (points) | Brier prior | Brier B − prior |")
    print("|---|---|---|---|---|---|---|---|")
    for name in a:
        (ba, aa, ma, _), (bb, ab, _, pb) = a[name], b[name]
        print(f"| {name} | {aa.mean() * 100:.1f} / {ab.mean() * 100:.1f} | {ma.mean() * 100:.1f} "
              f"| {ba.mean():.3f} / {bb.mean():.3f} | {ci(bb - ba)} | "
              f"{ci(aa - ma, 100, '+.1f')} / {ci(ab - ma, 100, '+.1f')} | {pb.mean():.3f} | "
              f"{ci(bb - pb)} |")


if __name__ == "__main__":
    main()
