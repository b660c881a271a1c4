"""Benchmark of ``impctl fleet fit`` on households that bring a season: their IMP nights and N
owner nights each, as the gateway exports them. Prints households/s and /hour, the CPU seconds
per household in the workers' batches (the IMP fit and the season model), each worker's
resident memory after its batches, and what 10,000 such households would take.

Run:  .venv/bin/python bench/fleet_season.py [--households 96] [--owner-nights 28]
          [--workers 1,2] [--seed 31] [--data DIR] [--next-morning] [--input csv|parquet]
          [--batch-size N] [--model-dir DIR]

Input: ``--households`` houses of the realistic plant simulated over a winter by the season
simulator of ``bench/season.py`` (the IMP campaign every other night from the first, the owner's
nights between), each cut when its N-th plain owner night is over and written as one NIGHTS
CSV per household (``write_nights``: the fleet's folder input, the format of ``impctl export``);
generated once and kept in ``--data``. The fleet runs on the default local cluster with
``--workers`` worker processes, no classifiers unless ``--model-dir`` (the whole prior ranges, as
``bench/fleet.py``);
the machine's other load skews the figures, so keep it quiet.

``--input parquet``: the same households as one Parquet dataset with a ``household`` column,
sorted by household in row groups of 65,536 rows (the layout the how-to gives), instead of one
CSV per household.

``--next-morning``: an aggregator's daily run. The same season cut after N and after N + 1
owner nights (one simulation); the fleet is fitted on the first cut, then on the second with
the first run's FLEET as ``--previous`` (each household's IMP nights unchanged: its IMP fit
carried over, its season search warm-started) — the figures of that second run, and the
season model's values against a full fit of the same second cut (median and largest relative
difference); and once more on the second cut from the morning run's FLEET (no new night: every
row carried over whole).
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
from benchlib.fleet_rates import steady_rate  # noqa: E402


def make_input(n: int, owner_nights: int, seed: int, data: Path, simulated: int | None = None
               ) -> Path:
    """One NIGHTS CSV per household under ``data`` (reused when complete); the season
    simulated long enough for ``simulated`` owner nights (default ``owner_nights``), so that
    two cuts can come from one simulation."""
    import math
    from dataclasses import replace

    from season import cutoff  # bench/season.py: the cut after the N-th plain owner night

    from impctl.imp.files.nights_csv import write_nights
    from impctl.population.households import sample_households
    from impctl.population.realism import sample_params
    from impctl.population.season_run.nights import household_nights
    from impctl.population.season_run.season import SeasonConfig, simulate_season

    simulated = simulated or owner_nights
    target = data / (f"season-{n}-{owner_nights}-{seed}" if simulated == owner_nights
                     else f"season-{n}-{owner_nights}-of-{simulated}-{seed}")
    if target.is_dir() and len(list(target.glob("*.csv"))) == n:
        return target
    target.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    houses, params = sample_households(n, seed=seed), sample_params(n, seed)
    # enough nights for N plain owner nights after the campaign's alternate nights
    nights = max(40, 2 * simulated + 24)
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


def as_parquet(folder: Path) -> Path:
    """The NIGHTS CSVs of ``folder`` as one Parquet dataset (``--input parquet``; cached)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    target = folder.with_name(folder.name + "-rg65536.parquet")
    if target.exists():
        return target
    frames = []
    for f in sorted(folder.glob("*.csv")):
        df = pd.read_csv(f, keep_default_na=False, na_values=[""],
                         dtype={c: str for c in ("night", "kind", "label", "phase", "emitter")})
        df.insert(0, "household", f.stem)
        frames.append(df)
    df = pd.concat(frames, ignore_index=True)
    df["timestamp"] = pd.to_datetime(df["timestamp"], utc=True, format="ISO8601")
    tmp = target.with_suffix(".tmp")
    pq.write_table(pa.Table.from_pandas(df, preserve_index=False), tmp, row_group_size=65_536)
    tmp.rename(target)
    return target


def run(data: Path, workers: int, work: Path, previous: Path | None = None,
        batch: int | None = None) -> tuple[float, Path]:
    """Fit the fleet on ``workers`` local worker processes (``bench/fleet.py``'s run, which
    prints the throughput and CPU figures); print the season's and memory figures; (the steady
    rate once every worker runs [households/s] — what a large fleet sees, the start spread
    thin: ``benchlib.fleet_rates.steady_rate`` — and the FLEET)."""
    from fleet import run_fleet  # bench/fleet.py

    from impctl.fleet.run import DEFAULT_BATCH

    started = time.time()
    wall, out = run_fleet(data, workers, batch or DEFAULT_BATCH, work, previous)
    fleet = pd.read_parquet(out)
    rate = len(fleet) / wall
    steady, first_s = steady_rate(out, started)
    rss = fleet.groupby("worker")["worker_rss_mb"].max()
    print(f"  {workers} worker(s): {3600 * rate:,.0f} households/hour (cluster start and "
          f"preload included; the first batch after {first_s:.1f} s, then {steady:.2f} "
          f"households/s); {fleet['cpu_s_per_household'].median():.3f} CPU-s per household "
          f"in the batches (median); season model fitted for "
          f"{int(fleet['season_hlc_w_per_k'].notna().sum())} (median "
          f"{fleet['season_owner_nights'].median():.0f} owner nights used); resident memory per "
          f"worker after its batches, largest [MB]: {', '.join(f'{v:.0f}' for v in rss)}",
          flush=True)
    if previous is not None:
        print(f"  IMP fit carried over for {int(fleet['imp_fit_reused'].sum())} (the whole row, "
              f"no new night: {int(fleet['nights_unchanged'].sum())}), season search "
              f"warm-started for {int(fleet['season_warm_start'].fillna(False).sum())} of "
              f"{len(fleet)}", flush=True)
    return steady, out


def next_morning(args) -> None:
    """``--next-morning`` (module docstring)."""
    import numpy as np

    n, k = args.households, args.owner_nights
    before = make_input(n, k, args.seed, args.data, simulated=k + 1)
    after = make_input(n, k + 1, args.seed, args.data, simulated=k + 1)
    if args.input == "parquet":
        before, after = as_parquet(before), as_parquet(after)
    w = max(int(x) for x in args.workers.split(","))
    with tempfile.TemporaryDirectory(prefix="impctl-fleet-season-") as tmp:
        print(f"yesterday ({k} owner nights), a full run:")
        _, first = run(before, w, Path(tmp), batch=args.batch_size)
        print(f"today ({k + 1} owner nights), the full run for comparison:")
        full_rate, full = run(after, w, Path(tmp), batch=args.batch_size)
        print("today, --previous yesterday's FLEET:")
        rate, warm = run(after, w, Path(tmp), previous=first, batch=args.batch_size)
        a = pd.read_parquet(full).set_index("household")
        b = pd.read_parquet(warm).set_index("household").loc[a.index]
        for q in ("hlc_w_per_k", "tau_h", "c_m_j_per_k"):
            rel = (b[f"season_{q}"] / a[f"season_{q}"] - 1).abs().dropna()
            print(f"  season {q}: the morning run against the full run: median "
                  f"{100 * rel.median():.3f} %, largest {100 * rel.max():.2f} % "
                  f"({int((rel > 0.01).sum())} of {len(rel)} differ by more than 1 %)")
        same = all(np.allclose(a[c].astype(float), b[c].astype(float), equal_nan=True)
                   for c in ("hlc_w_per_k", "tau_h", "c_m_j_per_k"))
        print(f"  the IMP fit's HLC, τ, C_m the same as the full run's: {same}")
        print("today again (no new night), --previous the morning run's FLEET:")
        again_rate, _ = run(after, w, Path(tmp), previous=warm,
                              batch=args.batch_size)
    print(f"10,000 such households every morning at {rate:.2f} households/s ({w} workers, "
          f"the steady rate): {10_000 / rate / 60:.1f} min (a full run: "
          f"{10_000 / full_rate / 60:.1f} min; with no new night: "
          f"{10_000 / again_rate / 60:.1f} min)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=96)
    ap.add_argument("--owner-nights", type=int, default=28)
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "impctl-bench")
    ap.add_argument("--input", choices=("csv", "parquet"), default="csv",
                    help="one NIGHTS CSV per household, or one Parquet dataset")
    ap.add_argument("--batch-size", type=int, default=None,
                    help="households per task [default: impctl fleet fit's]")
    ap.add_argument("--next-morning", action="store_true",
                    help="the daily run with --previous (module docstring)")
    ap.add_argument("--model-dir", type=Path, default=None,
                    help="classifiers [default: none — the whole prior ranges, whatever the "
                         "user's data directory holds]")
    args = ap.parse_args()
    os.environ["IMPCTL_MODEL_DIR"] = str(args.model_dir or args.data / "no-models")
    print(f"command: python bench/fleet_season.py {' '.join(sys.argv[1:])}")
    print(f"machine: {os.uname().machine}, {os.cpu_count()} cores")
    if args.next_morning:
        next_morning(args)
        return
    data = make_input(args.households, args.owner_nights, args.seed, args.data)
    if args.input == "parquet":
        data = as_parquet(data)
    rates = {}
    with tempfile.TemporaryDirectory(prefix="impctl-fleet-season-") as tmp:
        for w in [int(x) for x in args.workers.split(",")]:
            rates[w] = run(data, w, Path(tmp), batch=args.batch_size)[0]
    best = max(rates, key=lambda w: rates[w])
    print(f"10,000 such households at {rates[best]:.2f} households/s ({best} workers, the "
          f"steady rate): "
          f"{10_000 / rates[best] / 60:.1f} min")
    if len(rates) > 1:
        lo, hi = min(rates), max(rates)
        print(f"throughput {hi} against {lo} worker(s): {rates[hi] / rates[lo]:.2f}×")


if __name__ == "__main__":
    main()
