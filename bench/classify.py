"""Time to generate the virtual population and to train the range classifiers; their accuracy.

Run:  .venv/bin/python bench/classify.py [--households 900] [--seed 0] [--repeat 3]
          [--plant iso|realistic] [--constrained-setpoint C|cycle] [--constrained-per-day N]
          [--constrained-jitter-k K] [--stop-at-t-min yes|no]

``--plant realistic`` draws the households' realism (emitters, heat pumps, gains, sensors) and
runs their nights on :mod:`impctl.plant` (60 s steps; the ≤ 5 s target is for the ideal 5R1C).

Generates the 900-household dataset (15 weather days × 4 IMP nights each — the gateway's plans,
1 constrained + 3 normal, :func:`impctl.imp.imp_plans`; ``--constrained-per-day 3``: 6 — =
54,000 nights,
vectorised 5R1C at 10-min steps; target ≤ 5 s), trains the three Random-Forest range
classifiers (target ≤ 15 s; the shuffled-label baseline forests are timed separately, they are
evaluation, not training), and prints the accuracy table next to the baselines and the paper's
Table III. Wall-clock times on this machine; the best of ``--repeat`` runs is reported.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np

from impctl.classifiers.report import format_report
from impctl.classifiers.training import TrainConfig, train_classifiers
from impctl.population.dataset import generate_dataset
from impctl.population.imp_run.setup import ImpSimConfig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--households", type=int, default=900)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--plant", choices=("iso", "realistic"), default="iso")
    parser.add_argument("--constrained-setpoint", default=None, metavar="C",
                        help="T_set of the population's constrained nights [°C] (default the "
                             "gateway's, impctl.imp.protocol); 'cycle': every kind at every "
                             "normal setpoint (the population before branch h14q)")
    parser.add_argument("--constrained-per-day", type=int, default=None, metavar="N",
                        help="constrained replays per weather day (default ImpSimConfig's 1)")
    parser.add_argument("--constrained-jitter-k", type=float, default=None, metavar="K",
                        help="draw each constrained night's T_set within ±K of its setpoint")
    parser.add_argument("--stop-at-t-min", choices=("yes", "no"), default=None,
                        help="constrained nights stop at T_min (default: as the gateway records "
                             "them on the plant, ImpSimConfig.for_plant: yes on the realistic "
                             "plant, no on the ideal 5R1C)")
    parser.add_argument("--figure", default=None,
                        help="write the reliability diagram (calibrated vs vote shares) here")
    args = parser.parse_args()
    print(f"python {platform.python_version()}, numpy {np.__version__}, "
          f"{os.cpu_count()} CPUs, {platform.machine()}")
    print(f"command: {' '.join([os.path.basename(sys.executable), *sys.argv])}\n")

    kw: dict = {}
    if args.constrained_setpoint is not None:
        c_sp = args.constrained_setpoint
        kw["constrained_setpoint_c"] = None if c_sp == "cycle" else float(c_sp)
    if args.constrained_per_day is not None:
        kw["constrained_per_day"] = args.constrained_per_day
    if args.constrained_jitter_k is not None:
        kw["constrained_jitter_k"] = args.constrained_jitter_k
    if args.stop_at_t_min is not None:
        kw["stop_at_t_min"] = args.stop_at_t_min == "yes"
    imp = ImpSimConfig.for_plant(args.plant, **kw)
    print(f"constrained nights stop at T_min: {imp.stop_at_t_min} (band {imp.band_k:g} K)")
    gen_s = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        dataset = generate_dataset(args.households, args.seed, plant=args.plant, imp=imp)
        gen_s.append(time.perf_counter() - t0)
    print(f"plant: {args.plant}")
    print(f"dataset: {args.households} households, {len(dataset.nights):,} nights, "
          f"{len(dataset.nights.columns)} columns")
    print(f"generate: best {min(gen_s):.2f} s of {args.repeat} (target ≤ 5 s); "
          f"runs {', '.join(f'{s:.2f}' for s in gen_s)}")

    cfg = TrainConfig()
    train_s = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        train_classifiers(dataset, cfg, args.seed, with_baselines=False)
        train_s.append(time.perf_counter() - t0)
    print(f"train (3 forests, incl. campaign rows and evaluation): best {min(train_s):.2f} s "
          f"of {args.repeat} (target ≤ 15 s); runs {', '.join(f'{s:.2f}' for s in train_s)}")
    t0 = time.perf_counter()
    _, reports = train_classifiers(dataset, cfg, args.seed, with_baselines=True)
    print(f"train + shuffled-label baselines (6 forests): {time.perf_counter() - t0:.2f} s\n")
    print(format_report(reports, small=cfg.small_campaign))
    if args.figure:
        from impctl.classifiers.report import reliability_figure

        reliability_figure(reports, args.figure)
        print(f"reliability figure: {args.figure}")


if __name__ == "__main__":
    main()
