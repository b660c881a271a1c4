"""When a ``now`` night may run: inside the night window, ending with it, unless forced.

A ``now`` night taken inside the window or its preheat runs its preheat from then and ends
when the configured window ends; a rest shorter than a night needs does not run, and outside
the window only a forced one (``--force``) runs, a whole window's length from its preheat.
Checked on the function, on ``impctl trigger`` and on the in-process daemon with the real
simulator: a request left waiting into the morning never switches the heating off.
"""

from __future__ import annotations

from datetime import datetime, timedelta

import pytest
from cli_fixtures import run_impctl
from daemon_fixtures import daemon_mapping, write_config
from reliability_fixtures import TZ, daemon_rig, run_virtual

from impctl.clock import VirtualClock
from impctl.config.load import config_from_mapping
from impctl.daemon.nights.schedule import now_window

WINDOW = {"window": "22:00-05:00", "preheat_h": 2.0, "sample_interval_s": 300}


def _cfg(tmp_path, preheat_h: float = 2.0):
    clock = VirtualClock(datetime(2026, 1, 12, 12, 0, tzinfo=TZ), 1.0)
    return config_from_mapping(daemon_mapping(tmp_path / "state", 502, clock,
                                              night={**WINDOW, "preheat_h": preheat_h}))


def _at(day: int, hour: int, minute: int = 0) -> datetime:
    return datetime(2026, 1, day, hour, minute, tzinfo=TZ)


@pytest.mark.parametrize(("now", "preheat_h", "window"), [
    (_at(12, 20, 30), 2.0, (_at(12, 22, 30), _at(13, 5))),   # in the preheat: to 05:00
    (_at(13, 1), 0.5, (_at(13, 1, 30), _at(13, 5))),         # in the window: to 05:00
    (_at(12, 21, 59), 2.0, (_at(12, 23, 59), _at(13, 5))),
])
def test_a_now_night_inside_the_window_ends_with_it(tmp_path, now, preheat_h, window):
    assert now_window(_cfg(tmp_path, preheat_h), now, forced=False) == window


@pytest.mark.parametrize(("now", "preheat_h", "why"), [
    (_at(13, 4, 30), 2.0, "only 0.0 h of the night window 22:00-05:00 left"),
    (_at(13, 3), 0.5, "only 1.5 h of the night window 22:00-05:00 left"),
    (_at(13, 10), 2.0, "outside the night window 22:00-05:00"),
    (_at(13, 5, 1), 2.0, "outside the night window 22:00-05:00"),
])
def test_a_now_night_without_a_night_left_does_not_run_unless_forced(tmp_path, now, preheat_h,
                                                                       why):
    cfg = _cfg(tmp_path, preheat_h)
    assert why in now_window(cfg, now, forced=False)
    start = now + timedelta(hours=preheat_h)
    assert now_window(cfg, now, forced=True) == (start, start + timedelta(hours=7))


def test_trigger_now_says_at_once_when_too_little_of_the_window_is_left(tmp_path):
    clock = VirtualClock(_at(13, 4, 30), 1.0)
    config = write_config(tmp_path / "config.toml", daemon_mapping(
        tmp_path / "state", 502, clock, night=WINDOW))
    done = run_impctl("trigger", "--kind", "constrained", "--now", "--config", str(config))
    assert done.returncode == 2
    assert "only 0.0 h of the night window 22:00-05:00 left" in done.stderr
    assert "--force" in done.stderr and len(done.stderr.strip().splitlines()) == 1


def test_a_request_still_waiting_at_the_windows_end_is_refused_without_a_write(tmp_path):
    """Queued inside the window (no --force needed then), taken at 04:30 — behind a night
    that ran, or a daemon that was busy — with a 2 h preheat: no night, no write."""
    async def body():
        async with daemon_rig(tmp_path, speed=600.0, epoch=_at(13, 4, 30),
                              night=WINDOW) as rig:
            rig.store.add_request("constrained", 21.0, "now")
            writes = sum(rig.sim.stats.writes.values())
            await rig.daemon._poll_requests()
            assert rig.store.nights() == []
            assert rig.store.pending_requests() == []
            assert sum(rig.sim.stats.writes.values()) == writes
            assert any("not run: only 0.0 h of the night window" in message
                       for _, _, message in rig.store.events(20))
            # forced, the same request runs its night (the operator's --force)
            nid = await rig.trigger("constrained")
            night = rig.store.night(nid)
            assert night.window_end - night.window_start == timedelta(hours=7)
            assert night.window_start > _at(13, 6, 29)
    run_virtual(body(), 120)
