"""Speed of the vectorised 5R1C model (Annex C) in house-hours per second.

Run:  .venv/bin/python bench/simulate.py [--quick]

One winter month (31 days) of built-in weather, heating at a 21 °C setpoint with the heating
off 22:00–05:00 (so both demand and free-floating steps occur), for 1, 100, 900 and 10,000
random houses at Δt = 3600 s and 300 s; and the scalar oracle of the tests (a plain Python,
one-house-at-a-time transcription of the standard) on the same inputs for the speed ratio.
Target: ≥ 10 million house-hours/s at 900 houses, Δt = 3600 s.
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import oracle_5r1c  # noqa: E402

from impctl.model import HouseParameters, simulate  # noqa: E402
from impctl.weather import winter_weather  # noqa: E402

DAYS = 31


def random_houses(n: int, seed: int = 0) -> HouseParameters:
    rng = np.random.default_rng(seed)
    a_f = rng.uniform(60, 300, n)
    return HouseParameters(
        floor_area=a_f, wall_height=rng.uniform(2.4, 3.0, n),
        walls_area=a_f * rng.uniform(0.8, 1.6, n), windows_area=a_f * rng.uniform(0.1, 0.2, n),
        c_f=rng.uniform(0.8, 3.7, n), u_walls=rng.uniform(0.2, 2.0, n),
        u_windows=rng.uniform(0.8, 2.8, n), ach_vent=np.zeros(n), ach_infl=np.full(n, 0.3),
    )


def inputs(dt_s: float):
    t_out = winter_weather(days=DAYS, step_s=dt_s, seed=1)
    hour = t_out.index.hour
    sp = np.where((hour >= 22) | (hour < 5), np.nan, 21.0)
    return t_out.to_numpy(), sp


def best_of(fn, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def oracle_rate(dt_s: float, n_houses: int = 3) -> float:
    t_out, sp = inputs(dt_s)
    houses = random_houses(n_houses, seed=5)
    n = len(t_out)
    zeros = [0.0] * n
    sp_list = [None if math.isnan(x) else x for x in sp]
    t0 = time.perf_counter()
    for j in range(n_houses):
        p = {k: float(v[j]) if np.ndim(v) else float(v) for k, v in houses.as_dict().items()}
        oracle_5r1c.run(p, t_out, sp_list, [None] * n, zeros, zeros, dt_s, 21.0)
    elapsed = time.perf_counter() - t0
    return n_houses * n * dt_s / 3600.0 / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="skip 10,000 houses at 300 s")
    args = parser.parse_args()
    print(f"# command: python bench/simulate.py{' --quick' if args.quick else ''}")
    print(f"# {platform.python_implementation()} {platform.python_version()}, numpy "
          f"{np.__version__}, {platform.machine()}, one process; best of 3 (1 for the largest)")
    print(f"# one winter month = {DAYS} days; setpoint 21 °C, heating off 22:00–05:00")
    print()
    header = (f"{'houses':>7} {'dt [s]':>7} {'steps':>6} {'wall [s]':>9} "
              f"{'house-h/s':>12} {'vs oracle':>10}")
    print(header)
    print("-" * len(header))
    for dt_s in (3600.0, 300.0):
        t_out, sp = inputs(dt_s)
        ref = oracle_rate(dt_s)
        for n in (1, 100, 900, 10_000):
            if args.quick and n == 10_000 and dt_s == 300.0:
                continue
            houses = random_houses(n)
            hours = n * len(t_out) * dt_s / 3600.0

            def run(houses=houses, t_out=t_out, sp=sp, dt_s=dt_s):
                simulate(houses, t_out, dt_s, setpoint_c=sp, t_m_init_c=21.0)

            wall = best_of(run, 1 if n == 10_000 else 3)
            rate = hours / wall
            print(f"{n:>7} {dt_s:>7.0f} {len(t_out):>6} {wall:>9.3f} {rate:>12.3e} "
                  f"{rate / ref:>9.1f}x")
        print(f"{'oracle':>7} {dt_s:>7.0f} {len(t_out):>6} {'':>9} {ref:>12.3e} {'1':>9}x")
    print()
    print("house-h/s = simulated house-hours per wall-clock second; oracle = the scalar "
          "per-house Python transcription in tests/oracle_5r1c.py")


if __name__ == "__main__":
    main()
