"""Soak: scheduled nights one after another at high speed — memory flat, no file-descriptor
growth, the scheduler keeps its timing.

The daemon (the :class:`~impctl.daemon.service.Daemon` of ``impctl daemon``, with its logging)
with a campaign and the simulator, in one process of their own on a virtual-time event loop at
43 200× (a simulated day in 2 s of the loop's time): simulated time passes only when both wait,
so the run is the same on an idle and on a saturated machine. CI runs 6 nights;
``bench/soak.py`` runs 30 and prints the table. After each night, once it is assessed and
restored, the process records its VmRSS, open file descriptors and CPU time from /proc.

"Keeps its timing": one night per simulated day, each at its configured local window (22:00,
across the days), each started inside its own preheat (within the 2 h before the window).
"""

from __future__ import annotations

from datetime import timedelta

from reliability_fixtures import soak_run

NIGHTS = 6
SPEED = 43200.0


def test_nights_in_a_row_memory_flat_no_fd_growth_on_schedule(tmp_path):
    rows = soak_run(tmp_path, NIGHTS, speed=SPEED)
    assert len(rows) == NIGHTS
    first = rows[0].window_start
    for i, row in enumerate(rows):
        # One night per day, at its window, none skipped, none doubled.
        assert row.window_start == first + timedelta(days=i), [r.window_start for r in rows]
        assert (row.window_start.hour, row.window_start.minute) == (22, 0)
        assert 0 <= row.late_min < 120, row
        assert row.state == "done" and row.samples > 0, row
    # After the first night (imports, caches warmed) nothing grows.
    assert rows[-1].fds == rows[0].fds, [r.fds for r in rows]
    assert rows[-1].rss_kb - rows[1].rss_kb <= 4 * 1024, [r.rss_kb for r in rows]
    print("\n" + "\n".join(f"night {r.night_id}: late {r.late_min:.1f} min, RSS "
                           f"{r.rss_kb / 1024:.1f} MB, {r.fds} fds" for r in rows))
