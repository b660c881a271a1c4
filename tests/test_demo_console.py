"""What the demo tells on the console while its campaign runs: one line per night that fails
(why), and a stopped campaign as one line with exit status 1, never a traceback.

The watch runs on the virtual-time loop against a real store and a real simulator; the
campaign's nights are written into the store as the daemon would record them.
"""

from __future__ import annotations

import asyncio
from datetime import datetime, timedelta
from zoneinfo import ZoneInfo

import pytest
from impctl_sim import KronotermSimulator, SimConfig

from impctl.cli import main
from impctl.clock import VirtualClock
from impctl.clock import loop as vtime
from impctl.config import config_from_mapping
from impctl.demo import DemoError
from impctl.demo.campaign import _watch
from impctl.demo.options import Progress
from impctl.store import Store

TZ = ZoneInfo("Europe/Ljubljana")
EPOCH = datetime(2026, 1, 14, 12, 0, tzinfo=TZ)
REASON = "constrained night reached T_min after 1.2 h of cooling (< 3 h)"


def _config(tmp_path):
    return config_from_mapping({
        "state_dir": str(tmp_path / "state"), "timezone": "Europe/Ljubljana",
        "heatpump": {"host": "127.0.0.1"},
        "campaign": {"mode": "fixed", "constrained_nights": 1, "normal_setpoints_c": [21.0],
                     "normal_nights_per_setpoint": 1, "max_invalid_nights": 2,
                     "fit_when_complete": False}}, "test")


def _night(store: Store, day: int, kind: str, valid: bool, reasons: list[str]) -> None:
    start = datetime(2026, 1, day, 22, 0, tzinfo=TZ)
    night_id = store.create_night(kind, 21.0, start, start + timedelta(hours=7))
    store.set_night_state(night_id, "done", started=start, ended=start + timedelta(hours=7))
    store.assess_night(night_id, valid, reasons)


def test_failed_nights_and_the_stop_are_told_in_one_line_each(tmp_path):
    cfg = _config(tmp_path)
    (tmp_path / "state").mkdir()
    with Store(cfg.db_path) as store:
        _night(store, 12, "constrained", False, [REASON])
        _night(store, 13, "normal", True, ["window ended"])
        _night(store, 14, "constrained", False, [REASON, "coverage 71 % < 80 %"])
    lines: list[str] = []

    async def main_():
        clock = VirtualClock.on_loop(EPOCH, 10000.0)
        async with KronotermSimulator(SimConfig(clock=clock, plant_kind="iso")) as sim:
            daemon = asyncio.ensure_future(asyncio.Event().wait())  # a daemon running on
            try:
                await _watch(cfg, clock, sim, Progress(lines.append), None, daemon)
            finally:
                daemon.cancel()

    with pytest.raises(DemoError) as info:
        vtime.run(main_())
    told = [line.split("] ", 1)[1] for line in lines if " not valid: " in line]
    assert told == [f"night 1 (constrained, 21 °C) not valid: {REASON}",
                    f"night 3 (constrained, 21 °C) not valid: {REASON}; coverage 71 % < 80 %"]
    message = str(info.value)
    assert "\n" not in message and message.startswith("campaign stopped: 2 scheduled nights")
    assert REASON in message


def test_a_stopped_demo_is_one_line_and_exit_1(tmp_path, monkeypatch, capsys):
    import impctl.demo

    def stopped(opts, echo):
        raise DemoError("campaign stopped: 10 scheduled nights were not valid (...)")

    monkeypatch.setattr(impctl.demo, "run_demo", stopped)
    with pytest.raises(SystemExit) as exit_info:
        main(["demo", "--out", str(tmp_path / "d")])
    err = capsys.readouterr().err
    assert exit_info.value.code == 1
    assert err.strip().splitlines() == [
        "Error: demo: campaign stopped: 10 scheduled nights were not valid (...)"]
