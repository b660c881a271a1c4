"""Crash anywhere: ``impctl daemon`` killed with SIGKILL at random instants of constrained and
normal nights (and while it recovers from the previous kill), then restarted.

Real processes: an ``impctl-sim`` subprocess, the daemon exactly as systemd starts it, real
SIGKILL, a real SQLite file read through other connections. What is checked after every kill
and every restart is listed in :func:`reliability_fixtures.crash_run`: integrity_check, the
journal holds the owner's values whenever the heat pump is not in the owner's state, the
restart restores and verifies them, no committed sample is lost, running nights become
``interrupted`` and not valid, and no journal entry ever holds a value impctl wrote itself.

CI runs 20 kill points (two rigs of 10 side by side; the second talks through a proxy that
holds every write 0.2 s, so kills also catch writes in flight that land after the daemon is
dead); ``bench/crash.py`` runs 100 and prints where they fell.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

from reliability_fixtures import crash_run

POINTS_PER_RIG = 10


def test_sigkill_at_random_points_then_restart_restores_everything(tmp_path):
    dirs = [tmp_path / f"rig{i}" for i in range(2)]
    for d in dirs:
        d.mkdir()
    with ThreadPoolExecutor(len(dirs)) as pool:
        runs = [pool.submit(crash_run, d, POINTS_PER_RIG, seed=i, slow_writes_s=0.2 * i)
                for i, d in enumerate(dirs)]
        kills = [k for run in runs for k in run.result()]
    assert len(kills) == 20
    assert {"constrained", "normal"} <= {k.kind for k in kills}
    # Most kills left the heat pump in the experiment's state, so the restarts restored.
    assert sum(k.heat_pump != (210, 1) for k in kills) >= 5, [k.phase for k in kills]
    assert any(k.heat_pump[1] == 0 for k in kills)  # heating off at the kill
