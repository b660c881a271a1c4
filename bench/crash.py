"""Crash anywhere, at scale: SIGKILL ``impctl daemon`` at 100 random points, restart each time.

Run:  .venv/bin/python bench/crash.py [--points 100] [--rigs 2] [--seed 0] [--speed 7200]

The same machinery as ``tests/test_reliability_crash.py`` (20 points in CI):
:func:`reliability_fixtures.crash_run` with an ``impctl-sim`` subprocess and the daemon started
exactly as systemd does; every second rig talks through a proxy that holds each write
``--slow-writes`` seconds, so kills also catch writes in flight. Every kill and every restart
is checked (integrity_check, journal, owner's setpoint and mode restored and verified through
an independent Modbus client, no committed sample lost, running nights interrupted and not
valid, journal never holding impctl's own values); a failed check stops the run with the
kill's number. Prints where the kills fell (what the store and the heat pump showed at the
kill) and how long the restart took to put the owner's settings back.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from reliability_fixtures import crash_run  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100, help="kill points in all")
    parser.add_argument("--rigs", type=int, default=2,
                        help="independent simulator + daemon pairs run side by side")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--speed", type=float, default=7200.0, help="clock factor")
    parser.add_argument("--slow-writes", type=float, default=0.2,
                        help="every second rig talks through a proxy holding each write this "
                             "long [s] (writes in flight at the kill); 0 = never")
    parser.add_argument("-v", "--verbose", action="store_true", help="one line per kill")
    args = parser.parse_args()

    per_rig = [args.points // args.rigs + (i < args.points % args.rigs)
               for i in range(args.rigs)]
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="impctl-crash-") as tmp:
        dirs = [Path(tmp) / f"rig{i}" for i in range(args.rigs)]
        for d in dirs:
            d.mkdir()
        log = print if args.verbose else None
        with ThreadPoolExecutor(args.rigs) as pool:
            runs = [pool.submit(crash_run, d, n, args.seed * 1000 + i, speed=args.speed,
                                slow_writes_s=args.slow_writes * (i % 2), log=log)
                    for i, (d, n) in enumerate(zip(dirs, per_rig, strict=True))]
            kills = [k for run in runs for k in run.result()]
    wall = time.monotonic() - started

    command = "python bench/crash.py " + " ".join(sys.argv[1:])
    print(f"impctl crash bench: {len(kills)} SIGKILLs, {args.rigs} rig(s), clock {args.speed:g}×, "
          f"seed {args.seed}, {wall:.0f} s wall — every check passed")
    print()
    phases = Counter(k.phase for k in kills)
    w = max(len(p) for p in [*phases, "where the kill fell"])
    print(f"{'where the kill fell':<{w}} {'kills':>5}  {'constrained':>11} {'normal':>6} "
          f"{'recovery':>8}")
    for phase, count in phases.most_common():
        kinds = Counter(k.kind for k in kills if k.phase == phase)
        print(f"{phase:<{w}} {count:>5}  {kinds['constrained']:>11} {kinds['normal']:>6} "
              f"{kinds['recovery']:>8}")
    print(f"{'all':<{w}} {len(kills):>5}  "
          f"{sum(k.kind == 'constrained' for k in kills):>11} "
          f"{sum(k.kind == 'normal' for k in kills):>6} "
          f"{sum(k.kind == 'recovery' for k in kills):>8}")
    print()
    restored = [k.recovered_s for k in kills if k.heat_pump != (210, 1) and k.recovered_s]
    if restored:
        print(f"restart → owner's setpoint and mode verified on the heat pump (kills that left "
              f"it changed, n = {len(restored)}): median {statistics.median(restored):.2f} s, "
              f"max {max(restored):.2f} s wall (process start included)")
    print(f"journal entries pending at the kill: "
          f"{dict(sorted(Counter(k.pending for k in kills).items()))}")
    print(f"samples committed (and kept) by the last kill of each rig: "
          f"{[k.samples for k in kills if k.n == max(x.n for x in kills)]}")
    print()
    print(f"command: {command.strip()}")


if __name__ == "__main__":
    main()
