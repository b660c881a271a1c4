"""The owner recording over a season: the store's size, retention, the daemon's memory.

Run:  nice .venv/bin/python bench/owner_season.py [--days 200] [--keep-days 100]
          [--sample-s 300] [--inputs] [--runs both|all|kept]

The real daemon (:class:`~impctl.daemon.service.Daemon`) against the in-process simulator
(the ideal plant with 5-min steps, a winter's weather) on the virtual-time loop records the
house for ``--days`` simulated days with the product's rows (``[record] interval_s`` 300 s);
no IMP night runs. A snapshot every ``--sample-s`` seconds: a row's size in the store does not
depend on how many snapshots it averages (a gateway takes one a minute; 300 s here keeps the
run to minutes). Every 25 days it prints the store's size on disk (database and WAL), the
rows and records kept, and the process's VmRSS and open files; then the same with records
kept ``--keep-days`` days (deleted by the daemon once a day), whose size must level off.
``--inputs`` adds a row of the house's own sensors to every owner row ([inputs]: what a house
with a smart meter and room sensors stores besides).
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import sys
import tempfile
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from daemon_fixtures import HEAVY_HOUSE, daemon_mapping  # noqa: E402
from impctl_sim import KronotermSimulator, SimConfig  # noqa: E402

from impctl.clock import VirtualClock  # noqa: E402
from impctl.clock import loop as vtime  # noqa: E402
from impctl.config import config_from_mapping  # noqa: E402
from impctl.daemon.service import Daemon  # noqa: E402
from impctl.store.recording.house_inputs import HouseInputRow  # noqa: E402

EPOCH = datetime(2025, 10, 1, 12, 0, tzinfo=UTC)
SPEED = 3000.0


def _proc() -> tuple[float, int]:
    rss = next(int(line.split()[1]) for line in Path("/proc/self/status").read_text()
               .splitlines() if line.startswith("VmRSS:"))
    return rss / 1024, len(os.listdir("/proc/self/fd"))


class _Inputs:
    """The house's own sensors at every snapshot (as [inputs] would read them over MQTT)."""

    def row(self, night_id, snap) -> HouseInputRow:
        return HouseInputRow(night_id, snap.timestamp, house_power_w=450.0,
                             house_power_age_s=12.0, p_house_w=450.0, t_rooms_c=21.3,
                             t_rooms_age_s=40.0, rooms=3, t_out_ref_c=1.5,
                             t_out_ref_age_s=300.0, occupants=2.0, occupants_age_s=600.0,
                             t_out_c=snap.t_out_c.value)


async def season(work: Path, days: int, keep_days: int, sample_s: float,
                 inputs: bool) -> list[dict]:
    from impctl.weather import winter_weather

    clock = VirtualClock.on_loop(EPOCH, SPEED)
    weather = winter_weather(start=EPOCH - timedelta(days=2), days=days + 5, step_s=3600,
                             seed=3, tz="Europe/Ljubljana")
    cfg_sim = SimConfig(clock=clock, house=HEAVY_HOUSE, weather=weather, plant_kind="iso",
                        step_s=300.0)
    rows = []
    async with KronotermSimulator(cfg_sim) as sim:
        mapping = daemon_mapping(work / "state", sim.port, clock, log_level="warning",
                                 record={"keep_days": keep_days, "sample_interval_s": sample_s})
        mapping["clock"] = {"epoch": EPOCH.isoformat(), "speed": SPEED}
        cfg = config_from_mapping(mapping, "bench")
        daemon = Daemon(cfg, clock=clock)
        if inputs:
            daemon.house_inputs = _Inputs()
        task = asyncio.create_task(daemon.run())
        t0 = time.perf_counter()
        for day in range(25, days + 1, 25):
            until = EPOCH + timedelta(days=day)
            while clock.now() < until:
                if task.done():
                    raise RuntimeError(f"the daemon stopped: {task!r}")
                # the loop's time: 50 simulated min, so a figure is taken at its day, not
                # up to two days after it
                await asyncio.sleep(1.0)
            store = daemon.store
            summary = store.owner_summary()
            rss, fds = _proc()
            rows.append({"day": day, "mb": store.size_bytes() / 1e6, "rows": summary.rows,
                         "records": summary.count, "rss_mb": rss, "fds": fds,
                         "wall_s": time.perf_counter() - t0,
                         "fc06": sum(sim.stats.writes.values())})
            r = rows[-1]
            print(f"  day {day:3d}: store {r['mb']:6.2f} MB, {r['rows']:6d} rows, "
                  f"{r['records']:3d} records; VmRSS {r['rss_mb']:.1f} MB, {fds} open "
                  f"files; {r['wall_s']:.0f} s wall; writes to the heat pump {r['fc06']}",
                  flush=True)
        daemon.stop.set()
        await task
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--days", type=int, default=200)
    parser.add_argument("--keep-days", type=int, default=100)
    parser.add_argument("--sample-s", type=float, default=300.0)
    parser.add_argument("--inputs", action="store_true")
    parser.add_argument("--runs", choices=("both", "all", "kept"), default="both",
                        help="the season kept all, kept --keep-days, or both in turn")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    runs = {"all": [10 * args.days], "kept": [args.keep_days],
            "both": [10 * args.days, args.keep_days]}[args.runs]
    if args.keep_days > args.days and args.runs == "both":
        runs = runs[:1]  # kept longer than the season: the same run twice
    for keep in runs:
        what = "kept all season" if keep > args.days else f"kept {keep} days"
        print(f"owner recording, {args.days} simulated days, rows of 300 s, "
              f"{what}{', with [inputs]' if args.inputs else ''}:", flush=True)
        with tempfile.TemporaryDirectory(prefix="impctl-season-") as tmp:
            rows = vtime.run(season(Path(tmp), args.days, keep, args.sample_s, args.inputs))
        last = rows[-1]
        per_100 = last["mb"] / last["day"] * 100 if keep > args.days else None
        print(f"  → {last['mb']:.1f} MB after {last['day']} days"
              + (f" ({per_100:.1f} MB per 100 days, {last['mb'] / last['rows'] * 1e6:.0f} "
                 "bytes per row)" if per_100 else "") + "\n", flush=True)


if __name__ == "__main__":
    main()
