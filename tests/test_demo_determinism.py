"""The demo's campaign is the same on a quiet and on a busy machine: simulated time advances
only when the simulator and the daemon both wait (the virtual-time loop), so the same seed
stores the same nights and the same samples, bit for bit, beside CPU-burning processes.

Real simulator on loopback Modbus TCP, the real daemon, real SQLite files; the busy run has
two ``python -c 'while 1: pass'`` processes beside it (the machine's cores, and more).
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import asdict

from impctl.clock import loop as vtime
from impctl.demo.campaign import run_campaign
from impctl.demo.options import DemoOptions, Progress, demo_weather, house_and_realism
from impctl.store import Store


def _campaign(out, plant: str) -> tuple[list, list]:
    opts = DemoOptions(out=out, plant=plant, speed=20000.0 if plant == "iso" else 10000.0,
                       constrained_nights=1, normal_nights=1, owner_days_before=1,
                       owner_days_after=1)
    house, realism = house_and_realism(opts)
    lines: list[str] = []
    db = vtime.run(run_campaign(opts, house, Progress(lines.append), None, demo_weather(opts),
                                realism))
    with Store(db) as store:
        # the IMP nights and the owner's recorded days between and around them
        nights = store.nights(kinds=("constrained", "normal", "owner"))
        samples = [[asdict(s) for s in store.samples(n.id)] for n in nights]
    return [(n.kind, n.setpoint_c, n.state, n.valid, n.started, n.ended, n.reasons)
            for n in nights], samples


def test_the_same_campaign_quiet_and_beside_cpu_burners(tmp_path):
    quiet = _campaign(tmp_path / "quiet", "iso")
    burners = [subprocess.Popen([sys.executable, "-c", "while 1: pass"]) for _ in range(2)]
    try:
        busy = _campaign(tmp_path / "busy", "iso")
    finally:
        for p in burners:
            p.kill()
            p.wait()
    nights, samples = quiet
    imp = [(n[0], n[2], n[3]) for n in nights if n[0] != "owner"]
    assert imp == [("constrained", "done", True), ("normal", "done", True)], nights
    assert sum(n[0] == "owner" for n in nights) >= 3
    # every night and day has its rows; the demo stops inside a last day's record, which it
    # closes: no record is left recording, the short day labelled
    assert all(n[2] == "done" for n in nights), nights
    assert all(len(s) > 20 for s in samples[:-1]) and nights[-1][0] == "owner"
    assert nights[-1][3] is False and nights[-1][6][0].startswith("data missing"), nights[-1]
    assert busy == quiet
