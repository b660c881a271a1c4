"""bench/fit.py --speed: the issue's speed figures (``impctl fit`` wall time per file, the
in-process fit per household); --season-speed: the season model's (:func:`season_speed`)."""

from __future__ import annotations

import atexit
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchlib.fit_protocol import VAL_SEED, true_ranges
from impctl.fit.estimator import NightFit
from impctl.population.households import sample_households
from impctl.population.imp_run.synth import imp_schedule, run_schedule, sample_nights


def speed(args) -> None:
    """The issue's three speed figures: ``impctl fit`` wall time on the demo's export and on 8
    nights of 1-minute rows (subprocess, imports and classification included), and the
    in-process fit per household at 5-minute rows (one core)."""
    import os
    import subprocess

    from impctl.imp.files.nights_csv import write_nights

    houses = sample_households(4, seed=VAL_SEED)
    sched = imp_schedule(4, seed=VAL_SEED)
    sim, sp = run_schedule(houses, sched)
    tmp = _scratch("impctl-bench-fit-")
    files = []
    if args.demo_csv:
        files.append(("demo export (" + Path(args.demo_csv).name + ")", Path(args.demo_csv)))
    minute = sample_nights(sim, sp, sched, 0, sample_step_s=60.0, quantise_k=0.1,
                           power_noise=0.05, seed=VAL_SEED)
    files.append(("8 nights of 1-minute rows", write_nights(minute, tmp / "minute.csv")))
    env = dict(os.environ, OMP_NUM_THREADS="1")
    print("\n### speed (target: impctl fit ≤ 5 s wall per file, in-process ≤ 1 s per household "
          f"at 5-minute rows, one core); each command run {args.repeat} times, min / median")
    if args.model_dir:
        from impctl.classifiers.files.compact import COMPACT_FILE

        have = (Path(args.model_dir) / COMPACT_FILE).is_file()
        what = "compact forests" if have else "pickled forests only: retrain for the fast path"
        print(f"classifiers: {args.model_dir} ({what})")
    out = tmp / "fit.json"
    cmds = []
    for label, path in files:
        cmd = [str(Path(sys.executable).parent / "impctl"), "fit", "--nights", str(path),
               "--json", str(out)]
        cmds.append(cmd + (["--model-dir", str(args.model_dir)] if args.model_dir else []))
        print(f"{label}: OMP_NUM_THREADS=1 {' '.join(cmds[-1])}")
    print("| what | rows | wall s | CPU s (user+sys) | fit s (in JSON) "
          "| load average before / after |")
    print("|---|---|---|---|---|---|")
    for (label, path), cmd in zip(files, cmds, strict=True):
        walls, cpus, fits = [], [], []
        load0 = os.getloadavg()[0]
        for _ in range(args.repeat):
            before = os.times()
            t0 = time.perf_counter()
            done = subprocess.run(cmd, env=env, capture_output=True, text=True)
            walls.append(time.perf_counter() - t0)
            after = os.times()
            cpus.append(after.children_user - before.children_user
                        + after.children_system - before.children_system)
            if done.returncode != 0:
                break
            import json

            fits.append(json.loads(out.read_text())["fit"]["time_s"])
        if done.returncode != 0:
            print(f"| {label} | – | failed: {done.stderr.strip().splitlines()[-1]} | | | |")
            continue
        rows = sum(1 for _ in open(path)) - 1
        print(f"| {label} | {rows} | {min(walls):.1f} / {np.median(walls):.1f} "
              f"| {min(cpus):.1f} / {np.median(cpus):.1f} | {min(fits):.2f} / "
              f"{np.median(fits):.2f} | {load0:.1f} / {os.getloadavg()[0]:.1f} |", flush=True)
    times, cpu = [], []
    for i in range(houses.n_houses):
        nights = sample_nights(sim, sp, sched, i, sample_step_s=300.0, quantise_k=0.1,
                               power_noise=0.05, seed=VAL_SEED + i)
        c0 = time.process_time()
        times.append(NightFit().fit(nights, true_ranges(houses.take(i))).fit_time_s_)
        cpu.append(time.process_time() - c0)
    print(f"| in-process NightFit.fit, 5-minute rows, {len(times)} households | 8 nights "
          f"| median {np.median(times):.2f}, max {np.max(times):.2f} "
          f"| median {np.median(cpu):.2f}, max {np.max(cpu):.2f} | – |")
    print(f"load average during the run: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores "
          "(other work slows every figure)")


#: The season speed figures' winter: households' seed, nights, and the owner nights fitted.
SEASON_SEED, SEASON_NIGHTS, SEASON_OWNER_NIGHTS = 31, 70, 56


def _scratch(prefix: str) -> Path:
    """A scratch directory removed when the bench ends (the nights it writes are megabytes)."""
    path = Path(tempfile.mkdtemp(prefix=prefix))
    atexit.register(shutil.rmtree, path, True)
    return path


def season_speed(args) -> None:
    """The season model's speed (``--season-speed H``): H households of a simulated winter
    (``bench/season.py``'s export, seed 31, 70 nights), each fitted on its IMP nights and its
    first 56 owner nights. In process, one BLAS thread, CPU seconds (``time.process_time``:
    what the load does not change), the median of ``--repeat`` runs: the fit, the estimate
    against the owner nights (the refits at 7/14/28/56 nights), the morning refit with one more
    owner night warm-started at the fit's θ and its own curve. Then, on the first household's
    nights as NIGHTS.csv, ``impctl fit`` (the IMP fit and the season model) and the morning
    refit ``impctl season --warm-start`` as commands: wall seconds, min / median, and the CPU
    seconds of the command and the processes it forks (median)."""
    import json
    import os
    import subprocess

    from season import cutoff  # bench/season.py: the cut after the N-th owner night
    from threadpoolctl import threadpool_limits

    from impctl.imp.files.nights_csv import write_nights
    from impctl.population.realism import sample_params
    from impctl.population.season_run.nights import household_nights
    from impctl.population.season_run.season import SeasonConfig, simulate_season
    from impctl.season.convergence import convergence
    from impctl.season.fit import fit_nights

    n = args.season_speed
    houses = sample_households(n, seed=SEASON_SEED)
    season = simulate_season(houses, sample_params(n, SEASON_SEED),
                             SeasonConfig(nights=SEASON_NIGHTS), seed=SEASON_SEED)
    print(f"\n### the season model: IMP + {SEASON_OWNER_NIGHTS} owner nights, {n} households "
          f"(seed {SEASON_SEED}), CPU s in process, median of {args.repeat} (targets: the fit "
          "≤ 1 s, the morning refit ≤ 0.3 s)")
    print("| household | IMP / owner nights | fit | against owner nights | morning refit "
          "(+1 night, warm) | its curve |")
    print("|---|---|---|---|---|---|")

    def cpu(f):
        times, out = [], None
        for _ in range(args.repeat):
            c0 = time.process_time()
            out = f()
            times.append(time.process_time() - c0)
        return float(np.median(times)), out

    cols: list[list[float]] = [[], [], [], []]
    first = None
    with threadpool_limits(limits=1, user_api="blas"):
        for h in range(n):
            end, more = (cutoff(season, h, SEASON_OWNER_NIGHTS),
                         cutoff(season, h, SEASON_OWNER_NIGHTS + 1))
            if more is None:
                print(f"| {h} | season too short | | | | |")
                continue
            nights = household_nights(season, h, upto_sample=end)
            later = household_nights(season, h, upto_sample=more)
            t_fit, (fit, _) = cpu(lambda nights=nights: fit_nights(nights))
            t_curve, _ = cpu(lambda nights=nights, fit=fit: convergence(nights, fit))
            t_warm, (warm, _) = cpu(lambda later=later, fit=fit: fit_nights(
                later, start=fit.theta))
            t_warm_curve, _ = cpu(lambda later=later, warm=warm: convergence(later, warm))
            for col, t in zip(cols, (t_fit, t_curve, t_warm, t_warm_curve), strict=True):
                col.append(t)
            first = first or (nights, later)
            print(f"| {h} | {fit.imp_nights} / {fit.owner_nights} | {t_fit:.2f} | {t_curve:.2f} "
                  f"| {t_warm:.2f} | {t_warm_curve:.2f} |", flush=True)
    print("| median / max | | " + " | ".join(f"{np.median(c):.2f} / {np.max(c):.2f}"
                                         for c in cols) + " |")
    if first is None:
        return
    tmp = _scratch("impctl-bench-season-")
    csv, csv_more = (write_nights(first[0], tmp / "nights.csv"),
                     write_nights(first[1], tmp / "nights-more.csv"))
    impctl = str(Path(sys.executable).parent / "impctl")
    env = dict(os.environ, OMP_NUM_THREADS="1", IMPCTL_MODEL_DIR=str(tmp / "no-models"))
    cmds = [("impctl fit (IMP fit and season model, curve included)",
             [impctl, "fit", "--nights", str(csv), "--json", str(tmp / "fit.json")]),
            ("impctl season --warm-start (the morning refit, curve included)",
             [impctl, "season", "--nights", str(csv_more), "--warm-start",
              str(tmp / "fit.json"), "--json", str(tmp / "season.json")])]
    print(f"\n| command, household 0 | wall s min / median of {args.repeat} "
          "| CPU s (user+sys, its processes) median | search s (JSON) |")
    print("|---|---|---|---|")
    for label, cmd in cmds:
        walls, cpus = [], []
        for _ in range(args.repeat):
            before = os.times()
            t0 = time.perf_counter()
            done = subprocess.run(cmd, env=env, capture_output=True, text=True)
            walls.append(time.perf_counter() - t0)
            after = os.times()
            cpus.append(after.children_user - before.children_user
                        + after.children_system - before.children_system)
            if done.returncode != 0:
                print(f"| {label} | failed: {done.stderr.strip().splitlines()[-1]} | | |")
                return
        search = ""
        if "season" in cmd[1]:
            block = json.loads((tmp / "season.json").read_text())["season"]["search"]
            search = f"{block['time_s']:.2f} + curve {block['convergence_time_s']:.2f}"
        print(f"| {label} | {min(walls):.2f} / {np.median(walls):.2f} | {np.median(cpus):.2f} "
              f"| {search} |", flush=True)
    print(f"load average: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
