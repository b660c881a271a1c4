"""One process, one virtual-time event loop: the in-process simulator and the daemon (the same
:class:`~impctl.daemon.service.Daemon` that ``impctl daemon`` runs, with its logging), until
``--nights`` scheduled nights are over; after each (assessed, nothing left to restore) a JSON
line with the process's VmRSS, open file descriptors and CPU time read from /proc/self at that
simulated instant — the same phase on every run, however busy the machine.

Run by :func:`reliability_fixtures.soak_run`::

    python tests/virtual_daemon.py SPEC.json ROWS.jsonl

SPEC.json: ``{"mapping": daemon config mapping (its heat-pump port is set here), "epoch":
ISO instant, "speed": clock factor, "nights": N}``.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import sys
from datetime import datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from daemon_fixtures import HEAVY_HOUSE, OWNER_SETPOINT_C  # noqa: E402
from impctl_sim import KronotermSimulator, SimConfig, constant_weather  # noqa: E402

from impctl.clock import VirtualClock  # noqa: E402
from impctl.clock import loop as vtime  # noqa: E402
from impctl.config import config_from_mapping  # noqa: E402
from impctl.daemon.service import Daemon  # noqa: E402
from impctl.store import Store  # noqa: E402

_RUNNING = ("planned", "preparing", "active", "restoring")


def proc_self() -> dict[str, float]:
    """VmRSS [kB], open file descriptors and CPU time [s] of this process."""
    status = Path("/proc/self/status").read_text()
    rss = next(int(line.split()[1]) for line in status.splitlines()
               if line.startswith("VmRSS:"))
    fields = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
    cpu_s = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return {"rss_kb": rss, "fds": len(os.listdir("/proc/self/fd")), "cpu_s": cpu_s}


async def main(spec: dict, rows_path: Path) -> int:
    clock = VirtualClock.on_loop(datetime.fromisoformat(spec["epoch"]), spec["speed"])
    simcfg = SimConfig(clock=clock, house=HEAVY_HOUSE, weather=constant_weather(0.0),
                       setpoint_c=OWNER_SETPOINT_C, plant_kind="iso")
    async with KronotermSimulator(simcfg) as sim:
        mapping = spec["mapping"]
        mapping["heatpump"]["port"] = sim.port
        cfg = config_from_mapping(mapping, "soak spec")
        daemon = Daemon(cfg, clock=clock)
        task = asyncio.create_task(daemon.run(), name="impctl daemon")
        seen: list[int] = []
        with rows_path.open("w") as rows:
            while len(seen) < spec["nights"] and not task.done():
                await asyncio.sleep(0.02)  # the loop's time: 0.02 × speed simulated seconds
                if daemon.store is None:
                    continue
                done = [n.id for n in daemon.store.nights()
                        if n.valid is not None and n.state not in _RUNNING]
                if len(done) == len(seen) or daemon.store.journal_pending():
                    continue
                for night_id in done[len(seen):]:
                    rows.write(json.dumps({"night_id": night_id, **proc_self()}) + "\n")
                    rows.flush()
                    seen.append(night_id)
        daemon.stop.set()
        status = await task
    with Store(cfg.db_path) as store:
        assert not store.journal_pending()
    return status


if __name__ == "__main__":
    from impctl.cli.device.commands import _setup_logging

    spec_path, rows_file = Path(sys.argv[1]), Path(sys.argv[2])
    spec = json.loads(spec_path.read_text())
    _setup_logging(spec["mapping"].get("log_level", "info"), spec["mapping"]["timezone"])
    logging.getLogger("impctl_sim").setLevel(logging.WARNING)
    sys.exit(vtime.run(main(spec, rows_file)))
