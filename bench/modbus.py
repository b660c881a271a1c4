"""Modbus link and simulator speed over loopback TCP.

Run:  .venv/bin/python bench/modbus.py [--quick]

1. Time of one full snapshot read (``HeatPumpClient.snapshot``: every FC 03 block of a poll,
   decoded) against the simulator on 127.0.0.1, extended and compact register sets.
2. Simulated seconds per wall-clock second the simulator sustains while one client polls a
   snapshot every simulated minute, for increasing clock factors. "Sustained" means the model
   stayed within two steps of the clock at the end and ≥ 95 % of the polls happened. Simulator
   and client share one process and one event loop here (as in the tests); a simulator in its
   own process, as in the demo, has the whole CPU for itself.
3. The simulator alone (no client) with the clock far ahead: the model's own ceiling.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import platform
import statistics
import sys
import time
from datetime import UTC, datetime

import pymodbus
from impctl_sim import KronotermSimulator, SimConfig

from impctl.clock import VirtualClock
from impctl.heatpump import Generation, HeatPumpClient, HeatPumpConfig, LinkConfig

EPOCH = datetime(2026, 1, 12, 20, tzinfo=UTC)


def _client(sim: KronotermSimulator) -> HeatPumpClient:
    link = LinkConfig(port=sim.port, timeout_s=1.0, drain_s=0.0)
    return HeatPumpClient(HeatPumpConfig(link=link), clock=sim.clock)


async def snapshot_times(generation: Generation, n: int) -> tuple[list[float], int]:
    """Wall times of ``n`` snapshots [s] and FC 03 requests per snapshot."""
    config = SimConfig(clock=VirtualClock(EPOCH, 1.0), generation=generation)
    async with KronotermSimulator(config) as sim:
        hp = _client(sim)
        await hp.connect(max_wait_s=5)
        for _ in range(20):
            await hp.snapshot()
        before = hp.link.stats.requests
        times = []
        for _ in range(n):
            t0 = time.perf_counter()
            await hp.snapshot()
            times.append(time.perf_counter() - t0)
        per = (hp.link.stats.requests - before) // n
        hp.close()
    return times, per


async def sustained(factor: float, wall_s: float, step_s: float) -> dict[str, float]:
    """Run the simulator at ``factor`` with one client polling every simulated minute."""
    config = SimConfig(clock=VirtualClock(EPOCH, factor), step_s=step_s)
    async with KronotermSimulator(config) as sim:
        hp = _client(sim)
        await hp.connect(max_wait_s=5)
        interval = 60.0 / factor
        t_model0, t0 = sim.plant.time_s, time.perf_counter()
        polls = 0
        while (now := time.perf_counter()) - t0 < wall_s:
            await hp.snapshot()
            polls += 1
            next_due = t0 + polls * interval
            await asyncio.sleep(max(0.0, next_due - time.perf_counter()))
        wall = now - t0
        advanced = sim.plant.time_s - t_model0
        lag = sim.stats.lag_s
        hp.close()
    expected = wall * factor / 60.0
    return {"factor": factor, "rate": advanced / wall, "lag": lag, "polls": polls,
            "expected": expected,
            "ok": float(lag <= 2 * step_s and polls >= 0.95 * expected)}


async def model_alone(wall_s: float, step_s: float) -> float:
    """Simulated s per wall s of the simulator with no client (the clock far ahead)."""
    config = SimConfig(clock=VirtualClock(EPOCH, 1e9), step_s=step_s)
    async with KronotermSimulator(config) as sim:
        t_model0, t0 = sim.plant.time_s, time.perf_counter()
        await asyncio.sleep(wall_s)
        return (sim.plant.time_s - t_model0) / (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer snapshots, shorter runs")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)
    n, wall_s = (100, 1.5) if args.quick else (500, 4.0)
    print(f"# command: python bench/modbus.py{' --quick' if args.quick else ''}")
    print(f"# {platform.python_implementation()} {platform.python_version()}, pymodbus "
          f"{pymodbus.__version__}, {platform.machine()}, loopback TCP, one process")
    print()
    print("1. one full snapshot read (all FC 03 blocks, decoded), after 20 warm-up reads")
    header = f"{'set':>9} {'FC03/snap':>10} {'n':>5} {'median ms':>10} {'p95 ms':>8} {'min ms':>8}"
    print(header)
    print("-" * len(header))
    for gen in (Generation.EXTENDED, Generation.COMPACT):
        times, per = asyncio.run(snapshot_times(gen, n))
        ms = sorted(t * 1000 for t in times)
        print(f"{gen.value:>9} {per:>10} {n:>5} {statistics.median(ms):>10.2f} "
              f"{ms[int(0.95 * len(ms)) - 1]:>8.2f} {ms[0]:>8.2f}")
    print()
    step_s = 10.0
    print(f"2. simulator speed, one client polling a snapshot every simulated minute "
          f"(model step {step_s:g} s, {wall_s:g} s wall per row)")
    header = (f"{'factor':>9} {'sim s/s':>10} {'lag at end s':>13} {'polls':>7} "
              f"{'due':>7} {'sustained':>9}")
    print(header)
    print("-" * len(header))
    for factor in (600, 3600, 10_000, 20_000, 36_000, 72_000):
        row = asyncio.run(sustained(float(factor), wall_s, step_s))
        print(f"{factor:>9} {row['rate']:>10.0f} {row['lag']:>13.0f} {row['polls']:>7} "
              f"{row['expected']:>7.0f} {'yes' if row['ok'] else 'no':>9}")
    print()
    print("3. simulator alone (no client, clock far ahead): model steps + register publishing")
    for step in (10.0, 60.0):
        rate = asyncio.run(model_alone(wall_s / 2, step))
        print(f"   step {step:>4g} s: {rate:>12.0f} sim s/s")
    print()
    print("sim s/s = simulated seconds the model advanced per wall-clock second; lag = how far "
          "the model trailed the clock at the end; due = polls a client every simulated minute "
          "should have made")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
