"""bench/fit.py --speed: the issue's speed figures (``impctl fit`` wall time per file, the
in-process fit per household)."""

from __future__ import annotations

import sys
import time

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
    import tempfile
    from pathlib import Path

    from impctl.imp.nights_csv import write_nights

    houses = sample_households(4, seed=VAL_SEED)
    sched = imp_schedule(4, seed=VAL_SEED)
    sim, sp = run_schedule(houses, sched)
    tmp = Path(tempfile.mkdtemp(prefix="impctl-bench-fit-"))
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
        from impctl.classifiers.compact import COMPACT_FILE

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
