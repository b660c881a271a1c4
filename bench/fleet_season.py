"""Benchmark of ``impctl fleet fit`` on households that bring a season: their IMP nights and N
owner nights each, as the gateway exports them. Prints households/s and /hour, the CPU seconds
per household in the workers' batches (the IMP fit and the season model), each worker's
resident memory after its batches, and what 10,000 such households would take.

Run:  .venv/bin/python bench/fleet_season.py [--households 96] [--owner-nights 28]
          [--workers 1,2] [--seed 31] [--data DIR]

Input: ``--households`` houses of the realistic plant simulated over a winter by the season
simulator of ``bench/season.py`` (the IMP campaign every other night from the first, the owner's
nights between), each cut when its N-th plain owner night is over and written as one NIGHTS
CSV per household (``write_nights``: the fleet's folder input, the format of ``impctl export``);
generated once and kept in ``--data``. The fleet runs on the default local cluster with
``--workers`` worker processes, no classifiers (the whole prior ranges, as ``bench/fleet.py``);
the machine's other load skews the figures, so keep it quiet.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import pandas as pd  # noqa: E402


def make_input(n: int, owner_nights: int, seed: int, data: Path) -> Path:
    """One NIGHTS CSV per household under ``data`` (reused when complete)."""
    import math
    from dataclasses import replace

    from season import cutoff  # bench/season.py: the cut after the N-th plain owner night

    from impctl.imp.nights_csv import write_nights
    from impctl.population.households import sample_households
    from impctl.population.imp_run.season import SeasonConfig, simulate_season
    from impctl.population.imp_run.season_nights import household_nights
    from impctl.population.realism import sample_params

    target = data / f"season-{n}-{owner_nights}-{seed}"
    if target.is_dir() and len(list(target.glob("*.csv"))) == n:
        return target
    target.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    houses, params = sample_households(n, seed=seed), sample_params(n, seed)
    # enough nights for N plain owner nights after the campaign's alternate nights
    nights = max(40, 2 * owner_nights + 24)
    season = simulate_season(houses, params, SeasonConfig(nights=nights), seed=seed)
    for h in range(n):
        end = cutoff(season, h, owner_nights)
        rows = household_nights(season, h, upto_sample=end)
        # most gateways do not read the household electricity
        rows = [replace(r, p_house_w=math.nan, p_house_series_w=None) for r in rows]
        write_nights(rows, target / f"h{h:05d}.csv")
    print(f"generated {n} households × {nights} simulated nights in "
          f"{time.perf_counter() - t0:.0f} s → {target}", flush=True)
    return target


def run(data: Path, workers: int, work: Path) -> float:
    """Fit the fleet on ``workers`` local worker processes (``bench/fleet.py``'s run, which
    prints the throughput and CPU figures); print the season's and memory figures;
    households/s."""
    from fleet import run_fleet  # bench/fleet.py

    from impctl.fleet.run import DEFAULT_BATCH

    wall, out = run_fleet(data, workers, DEFAULT_BATCH, work)
    fleet = pd.read_parquet(out)
    rate = len(fleet) / wall
    rss = fleet.groupby("worker")["worker_rss_mb"].max()
    print(f"  {workers} worker(s): {3600 * rate:,.0f} households/hour (cluster start and "
          f"preload included); {fleet['cpu_s_per_household'].median():.3f} CPU-s per household "
          f"in the batches (median); season model fitted for "
          f"{int(fleet['season_hlc_w_per_k'].notna().sum())} (median "
          f"{fleet['season_owner_nights'].median():.0f} owner nights used); resident memory per "
          f"worker after its batches, largest [MB]: {', '.join(f'{v:.0f}' for v in rss)}",
          flush=True)
    return rate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=96)
    ap.add_argument("--owner-nights", type=int, default=28)
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "impctl-bench")
    args = ap.parse_args()
    print(f"command: python bench/fleet_season.py {' '.join(sys.argv[1:])}")
    print(f"machine: {os.uname().machine}, {os.cpu_count()} cores")
    data = make_input(args.households, args.owner_nights, args.seed, args.data)
    rates = {}
    with tempfile.TemporaryDirectory(prefix="impctl-fleet-season-") as tmp:
        for w in [int(x) for x in args.workers.split(",")]:
            rates[w] = run(data, w, Path(tmp))
    best = max(rates, key=lambda w: rates[w])
    print(f"10,000 such households at {rates[best]:.2f} households/s ({best} workers): "
          f"{10_000 / rates[best] / 60:.1f} min")
    if len(rates) > 1:
        lo, hi = min(rates), max(rates)
        print(f"throughput {hi} against {lo} worker(s): {rates[hi] / rates[lo]:.2f}×")


if __name__ == "__main__":
    main()
