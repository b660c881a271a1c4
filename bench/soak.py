"""Soak: 30 scheduled nights in a row at high speed — memory, file descriptors, timing.

Run:  .venv/bin/python bench/soak.py [--nights 30] [--speed 43200] [--interval 300]

The same machinery as ``tests/test_reliability_soak.py`` (6 nights in CI):
:func:`reliability_fixtures.soak_run` — the daemon (``impctl daemon``'s
:class:`~impctl.daemon.service.Daemon`, with its logging) with a campaign of ``--nights``
nights (a third constrained, the rest normal at 21/22 °C) and the simulator (heavy,
well-insulated house, 0 °C), in one process of their own on a virtual-time event loop
(``tests/virtual_daemon.py``): simulated time passes only when both wait, so the table is the
same on a busy machine. After each night (assessed, nothing left to restore) the process
records its VmRSS, open file descriptors and CPU time from /proc. "late" is the night's start
(after its checks and the journal) minus its scheduled preheat start (20:00 local), in
simulated minutes.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from reliability_fixtures import soak_run  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nights", type=int, default=30)
    parser.add_argument("--speed", type=float, default=43200.0, help="clock factor")
    parser.add_argument("--interval", type=float, default=300.0,
                        help="night.sample_interval_s [simulated s]")
    args = parser.parse_args()

    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="impctl-soak-") as tmp:
        rows = soak_run(Path(tmp), args.nights, speed=args.speed,
                        sample_interval_s=args.interval)
    wall = time.monotonic() - started

    print(f"impctl soak: {len(rows)} scheduled nights, clock {args.speed:g}×, samples every "
          f"{args.interval:g} s (simulated), {wall:.0f} s wall")
    print()
    print(f"{'#':>3} {'kind':<11} {'window (local)':<17} {'state':<8} {'valid':<5} "
          f"{'late min':>8} {'samples':>7} {'RSS MB':>7} {'fds':>4} {'CPU s':>6}  reasons")
    for i, r in enumerate(rows, 1):
        why = "; ".join(x for x in r.reasons if x != "window ended") or "-"
        print(f"{i:>3} {r.kind:<11} {r.window_start:%Y-%m-%d %H:%M}  {r.state:<8} "
              f"{'yes' if r.valid else 'no':<5} {r.late_min:>8.1f} {r.samples:>7} "
              f"{r.rss_kb / 1024:>7.1f} {r.fds:>4} {r.cpu_s:>6.1f}  {why}")
    print()
    rss = [r.rss_kb / 1024 for r in rows]
    late = [r.late_min for r in rows]
    days = {(b.window_start - a.window_start).days for a, b in zip(rows, rows[1:], strict=False)}
    cpu = [(b.cpu_s - a.cpu_s) for a, b in zip(rows, rows[1:], strict=False)]
    print(f"VmRSS after night 1 / 2 / last / max: {rss[0]:.1f} / {rss[min(1, len(rss) - 1)]:.1f}"
          f" / {rss[-1]:.1f} / {max(rss):.1f} MB (growth after night 2: "
          f"{rss[-1] - rss[min(1, len(rss) - 1)]:+.2f} MB)")
    print(f"open file descriptors after each night: {sorted(set(r.fds for r in rows))}")
    print(f"nights one simulated day apart: {days == {1} or len(rows) == 1}; every window at "
          f"22:00 local: {all(r.window_start.strftime('%H:%M') == '22:00' for r in rows)}")
    print(f"late: median {statistics.median(late):.1f} min, max {max(late):.1f} min simulated; "
          f"first 5 mean "
          f"{statistics.mean(late[:5]):.1f}, last 5 mean {statistics.mean(late[-5:]):.1f}")
    if cpu:
        print(f"daemon CPU per simulated day: median {statistics.median(cpu):.2f} s")
    print(f"valid nights: {sum(r.valid for r in rows)}/{len(rows)}")
    print()
    print("command: python bench/soak.py " + " ".join(sys.argv[1:]))


if __name__ == "__main__":
    main()
