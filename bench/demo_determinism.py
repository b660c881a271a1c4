"""The demo's numbers do not depend on how busy the machine is: quiet vs beside CPU burners.

Run:  nice .venv/bin/python bench/demo_determinism.py [--plant realistic] [--seed 0]
          [--nights 2+6] [--burners 6] [--model-dir DIR] [--out DIR]

Runs ``impctl demo`` twice with the same seed and the same classifier cache: once as the
machine is, once beside ``--burners`` processes each running ``python -c 'while 1: pass'``
(started before, killed after). Prints the summary.json numbers side by side (HLC, C_m, τ
with their intervals, nights run and valid, every night's kind, setpoint and verdict), the
wall times, and whether the two runs agree to the last digit. The classifier cache is
trained first when it does not fit (``impctl train``, timed and reported separately: the demo
wall times are with a warm cache). The load average before each run is printed: "quiet" is
the machine as it is, other jobs included.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

IMPCTL = [sys.executable, "-c", "from impctl.cli import main; main()"]


def _load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def _warm_cache(model_dir: Path, plant: str, seed: int, households: int) -> str:
    from impctl.demo.run import _models_unfit

    why = _models_unfit(model_dir, plant)
    if why is None:
        return f"classifier cache {model_dir}: warm (reused)"
    t0 = time.perf_counter()
    subprocess.run([*IMPCTL, "train", "--households", str(households), "--seed", str(seed),
                    "--plant", plant, "--out", str(model_dir)], check=True,
                   capture_output=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    return (f"classifier cache {model_dir}: trained ({households} households, "
            f"{time.perf_counter() - t0:.0f} s wall; {why})")


def _demo(args, out: Path, burners: int) -> tuple[dict, float, str, list[str]]:
    procs = [subprocess.Popen([sys.executable, "-c", "while 1: pass"]) for _ in range(burners)]
    try:
        time.sleep(1.0 if burners else 0.0)  # the burners are running before the demo starts
        load = _load()
        cmd = [*IMPCTL, "demo", "--plant", args.plant, "--seed", str(args.seed),
               "--nights", args.nights, "--model-dir", str(args.model_dir), "--out", str(out)]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - t0
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait()
    if proc.returncode != 0:
        raise SystemExit(f"impctl demo failed ({proc.returncode}): {proc.stderr.strip()}")
    lines = [ln for ln in proc.stdout.splitlines() if " not valid: " in ln or " refused: " in ln]
    return json.loads((out / "summary.json").read_text()), wall, load, lines


def _numbers(summary: dict) -> dict[str, str]:
    rows = {}
    for q in summary["lumped"]:
        rows[f"{q['name']} [{q['unit']}]"] = (f"{q['estimate']:.6g} ({q['low']:.4g} … "
                                              f"{q['high']:.4g})")
    rows["nights run / valid"] = f"{summary['nights_run']} / {summary['nights_valid']}"
    rows["nights"] = " ".join(f"{k[0]}{sp:g}{'+' if ok else '-'}"
                              for k, sp, ok in summary["campaign"]["nights"])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plant", choices=["realistic", "iso"], default="realistic")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--nights", default="2+6")
    parser.add_argument("--burners", type=int, default=6)
    parser.add_argument("--households", type=int, default=900,
                        help="for training the classifier cache when it does not fit")
    parser.add_argument("--model-dir", type=Path, default=None,
                        help="classifier cache [default: the demo's]")
    parser.add_argument("--out", type=Path, default=Path("demo-determinism"))
    args = parser.parse_args()
    if args.model_dir is None:
        from impctl.classifiers.files.saved import default_model_dir

        args.model_dir = default_model_dir()
        if args.plant != "realistic":
            args.model_dir = args.model_dir.with_name(f"{args.model_dir.name}-{args.plant}")
    cache = _warm_cache(args.model_dir, args.plant, args.seed, args.households)
    quiet, wall_q, load_q, lines_q = _demo(args, args.out / "quiet", 0)
    busy, wall_b, load_b, lines_b = _demo(args, args.out / "busy", args.burners)
    a, b = _numbers(quiet), _numbers(busy)
    same = quiet["lumped"] == busy["lumped"] and quiet["campaign"] == busy["campaign"]

    print(f"impctl demo, {args.plant} plant, seed {args.seed}, nights {args.nights}: quiet vs "
          f"beside {args.burners} CPU burners ({os.cpu_count()} cores)")
    print(cache)
    print()
    print(f"{'':<22} {'quiet':<40} {f'{args.burners} burners':<40}")
    for key in a:
        print(f"{key:<22} {a[key]:<40} {b[key]:<40}")
    print(f"{'wall time [s]':<22} {wall_q:<40.1f} {wall_b:<40.1f}")
    print(f"{'load avg before':<22} {load_q:<40} {load_b:<40}")
    print()
    for name, lines in (("quiet", lines_q), ("busy", lines_b)):
        for line in lines:
            print(f"{name}: {line}")
    print("summary.json lumped + campaign identical: " + ("yes" if same else "NO"))
    print()
    nice = os.nice(0)   # the niceness it ran at, so the command says how it was run
    print("command: " + (f"nice -n {nice} " if nice else "") + "python "
           + " ".join(shlex.quote(a) for a in sys.argv))


if __name__ == "__main__":
    main()
