"""Issue 12, items 2, 5, 6 and the log/JSON expectations, as an operator meets them: real
``impctl daemon`` and ``impctl`` subprocesses, a real ``impctl-sim`` subprocess on loopback, a
real SQLite store, real signals.

* a second daemon on the same store exits 2 naming the running one's PID and touches nothing;
* ``impctl status`` says whether the daemon is alive (PID + heartbeat age), and plainly when it
  is not — also after ``kill -9`` in the middle of a night;
* ``impctl trigger``: --now/--tonight exclusive, --now in daytime needs --force, a warning when
  no daemon runs, requests expire, --cancel;
* connect failures are logged at WARNING; log timestamps carry their UTC offset.
"""

from __future__ import annotations

import json
import re
import time
from datetime import datetime
from zoneinfo import ZoneInfo

from cli_fixtures import run_impctl
from daemon_fixtures import (
    OWNER_MODE,
    OWNER_SETPOINT_RAW,
    daemon_mapping,
    free_port,
    owner_state,
    run_cli,
    sim_process,
    start_daemon,
    stop_process,
    store_query,
    wait_until,
    write_config,
)

from impctl.clock import VirtualClock

TZ = ZoneInfo("Europe/Ljubljana")
OWNER = (OWNER_SETPOINT_RAW, OWNER_MODE)
ONE_CONSTRAINED = {"enabled": True, "mode": "fixed", "constrained_nights": 1,
                   "normal_setpoints_c": [], "fit_when_complete": False}
#: ISO 8601 local time with its offset, e.g. 2026-11-23T20:19:33.802+01:00.
STAMP = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}[+-]\d\d:\d\d ")


def _status(config) -> dict:
    done = run_impctl("status", "--json", "--config", str(config))
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_second_daemon_refused_and_status_tells_a_dead_daemon(tmp_path):
    # 600×: the 7 h window lasts 42 s, time enough for the checks below mid-night.
    epoch = datetime(2026, 1, 12, 20, 30, tzinfo=TZ)
    with sim_process(tmp_path, epoch, 600.0) as sim:
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            tmp_path / "state", sim.port, sim.clock, campaign=ONE_CONSTRAINED,
            night={"window": "22:00-05:00", "preheat_h": 0.5}))
        db = tmp_path / "state" / "impctl.db"
        d = start_daemon(config, db, tmp_path / "daemon.log")
        try:
            wait_until(lambda: owner_state(sim.port) == (225, 0), 60,
                       "the night to switch off", proc=d.proc)
            # Exactly the step: a second daemon in a terminal, mid-night.
            second = run_cli("daemon", "--config", str(config), timeout_s=30)
            assert second.returncode == 2
            [line] = second.stderr.splitlines()
            assert f"PID {d.proc.pid}" in line and "already drives the heat pump" in line
            # It restored nothing: the night goes on, supervised by the first daemon.
            assert owner_state(sim.port) == (225, 0)
            assert store_query(db, lambda s: s.night(1).state) == "active"
            # Nor does a foreground night start next to it.
            fg = run_cli("trigger", "--kind", "normal", "--now", "--force", "--foreground",
                         "--config", str(config), timeout_s=30)
            assert fg.returncode == 2 and f"PID {d.proc.pid}" in fg.stderr
            st = _status(config)
            assert st["daemon"]["running"] and st["daemon"]["responding"]
            assert st["daemon"]["pid"] == d.proc.pid
            assert 0 <= st["daemon"]["heartbeat_age_s"] < 30
            assert st["current_night"]["supervised"] is True
            # What runs at the next night: the campaign's constrained night (this one is not
            # valid yet), with numbers, not strings, for the write counters.
            assert st["next_night"]["kind"] == "constrained"
            assert st["next_night"]["source"] == "schedule"
            assert st["writes_today"]["2042"] == {"used": 1, "limit": 12}
            text = run_impctl("status", "--config", str(config)).stdout
            assert f"daemon:    running (PID {d.proc.pid}, heartbeat" in text
            assert "next:      constrained night (T_max 22.5 → T_min 19.5 °C, campaign)" in text

            d.proc.kill()  # kill -9 mid-night
            d.proc.wait(10)
        finally:
            stop_process(d.proc)
        st = _status(config)
        assert st["daemon"]["running"] is False and st["daemon"]["pid"] == d.proc.pid
        assert st["current_night"]["supervised"] is False
        text = run_impctl("status", "--config", str(config)).stdout
        assert f"daemon:    NOT RUNNING: nothing watches the heat pump (last PID {d.proc.pid}" \
            in text
        assert "night 1 is NOT supervised" in text
        assert "RESTORE PENDING: loop1_setpoint, loop1_mode" in text
        # nights --json: machine-readable, the night as the dead daemon left it.
        nights = json.loads(run_impctl("nights", "--json", "--config", str(config)).stdout)
        assert [(n["id"], n["kind"], n["state"]) for n in nights] == [(1, "constrained",
                                                                      "active")]
        assert nights[0]["samples"] > 0 and nights[0]["window_start"].endswith("+00:00")
        assert run_cli("restore", "--config", str(config)).returncode == 0
        assert owner_state(sim.port) == OWNER
        log = d.output()
        # Log lines carry their offset; a mode is an integer.
        assert all(STAMP.match(x) for x in log.splitlines() if x.strip()), log[:500]
        assert "journaled owner's state: setpoint 21.0 °C, loop-1 mode 1\n" in log


def test_trigger_rules_expiry_and_cancel(tmp_path):
    morning = datetime(2026, 1, 12, 3, 0, tzinfo=TZ)  # inside the night window
    with sim_process(tmp_path, morning, 3600.0) as sim:
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            tmp_path / "state", sim.port, sim.clock, night={"preheat_h": 1.0}))
        db = tmp_path / "state" / "impctl.db"
        both = run_cli("trigger", "--kind", "normal", "--now", "--tonight", "--config",
                       str(config))
        assert both.returncode == 2 and "mutually exclusive" in both.stderr
        assert not db.exists()
        # --tonight: expires at the end of the night it is for; no daemon → a warning.
        tonight = run_cli("trigger", "--kind", "normal", "--tonight", "--config", str(config))
        assert tonight.returncode == 0, tonight.stderr
        assert "NOT RUNNING" in tonight.stderr
        assert "waits until a daemon starts" in tonight.stderr
        [req] = store_query(db, lambda s: s.pending_requests())
        assert req.expires.astimezone(TZ).strftime("%H:%M") == "05:00"
        cancel = run_cli("trigger", "--cancel", "--config", str(config))
        assert cancel.returncode == 0 and "cancelled request 1" in cancel.stdout
        assert store_query(db, lambda s: s.pending_requests()) == []
        # --now with a short expiry (0.0005 real hours = 1.8 s), queued with no daemon.
        # (--force: at 3600× the simulated morning is over by now.)
        stale = run_cli("trigger", "--kind", "constrained", "--now", "--force", "--expires-h",
                        "0.0005", "--config", str(config))
        assert stale.returncode == 0, stale.stderr
        [req] = store_query(db, lambda s: s.pending_requests())
        time.sleep(2.5)
        d = start_daemon(config, db, tmp_path / "daemon.log")
        try:
            wait_until(lambda: "expired unstarted" in d.output(), 30, "the expiry",
                       proc=d.proc)
            time.sleep(1.5)  # a few request polls: nothing may start
            assert store_query(db, lambda s: s.nights()) == []
            assert owner_state(sim.port) == OWNER
        finally:
            assert stop_process(d.proc) == 0
    # Daytime: a --now night needs --force (real-time clock at 14:00 local, no daemon).
    noon = VirtualClock(datetime(2026, 1, 12, 14, 0, tzinfo=TZ), 1.0)
    day_cfg = write_config(tmp_path / "day.toml", daemon_mapping(
        tmp_path / "day", 502, noon))
    refused = run_cli("trigger", "--kind", "normal", "--now", "--config", str(day_cfg))
    assert refused.returncode == 2 and "--force" in refused.stderr
    assert "14:00 CET" in refused.stderr and not (tmp_path / "day").exists()
    forced = run_cli("trigger", "--kind", "normal", "--now", "--force", "--config",
                     str(day_cfg))
    assert forced.returncode == 0, forced.stderr


def test_connect_failure_is_a_warning(tmp_path):
    clock = VirtualClock(datetime(2026, 1, 12, 14, 0, tzinfo=TZ), 1.0)
    mapping = daemon_mapping(tmp_path / "state", free_port(), clock, log_level="warning")
    config = write_config(tmp_path / "config.toml", mapping)
    d = start_daemon(config, tmp_path / "state" / "impctl.db", tmp_path / "daemon.log")
    try:
        wait_until(lambda: "heat pump not reachable" in d.output(), 30,
                   "the connect warning", proc=d.proc)
        time.sleep(1.0)
    finally:
        assert stop_process(d.proc) == 0
    lines = [x for x in d.output().splitlines() if "not reachable" in x]
    assert len(lines) == 1 and " WARNING impctl.daemon: " in lines[0]  # once per outage
    assert STAMP.match(lines[0])


def test_foreground_night_holds_the_lock_and_shows_as_alive(tmp_path):
    import subprocess

    from daemon_fixtures import IMPCTL, ROOT

    morning = datetime(2026, 1, 12, 3, 0, tzinfo=TZ)
    with sim_process(tmp_path, morning, 1200.0) as sim:
        # A 3.5 h window: the night (3.75 h with its preheat) lasts 11 s at 1200×, so it still
        # runs while `impctl status` and a second `impctl daemon` start (a few seconds on a
        # loaded machine); if it ended first, the second daemon would take the lock and run.
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            tmp_path / "state", sim.port, sim.clock,
            night={"window": "02:30-06:00", "preheat_h": 0.25}))
        # --force: at 1200× the 03:00 start is past the window's end (04:00) after 3 s of
        # wall time, which starting two Python processes can take on a loaded machine.
        fg = subprocess.Popen([*IMPCTL, "trigger", "--kind", "normal", "--setpoint", "22",
                               "--now", "--force", "--foreground", "--config", str(config)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              cwd=ROOT)
        try:
            wait_until(lambda: owner_state(sim.port)[0] == 220, 30, "the foreground night",
                       proc=fg)
            st = _status(config)
            assert st["daemon"]["running"] and st["daemon"]["pid"] == fg.pid
            assert st["daemon"]["role"] == "trigger --foreground"
            assert st["daemon"]["heartbeat_age_s"] < 30
            second = run_cli("daemon", "--config", str(config), timeout_s=30)
            assert second.returncode == 2 and f"PID {fg.pid}" in second.stderr
            out, err = fg.communicate(timeout=60)
        finally:
            if fg.poll() is None:
                fg.kill()
                fg.communicate()
        assert fg.returncode == 0, err
        assert out.startswith("night 1: done")
        assert owner_state(sim.port) == OWNER
        assert _status(config)["daemon"]["running"] is False
