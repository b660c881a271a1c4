"""One daemon per heat pump, and a calm ``impctl status`` while a daemon supervises a night:
real ``impctl daemon`` and ``impctl`` subprocesses, a real ``impctl-sim`` subprocess on
loopback, real signals.

* a second daemon with another ``state_dir`` on the same heat pump (spelt ``localhost``
  instead of ``127.0.0.1``) exits 2 naming the first one's PID and state directory, and
  touches nothing;
* during a normal night the journal holds the owner's settings: status says a daemon
  supervises the night and restores at its end, and shouts only once nothing does (kill -9).
"""

from __future__ import annotations

import contextlib
import json
import os
from datetime import datetime
from pathlib import Path
from types import SimpleNamespace
from zoneinfo import ZoneInfo

from cli_fixtures import run_impctl
from daemon_fixtures import (
    OWNER_MODE,
    OWNER_SETPOINT_RAW,
    daemon_mapping,
    owner_state,
    run_cli,
    sim_process,
    start_daemon,
    stop_process,
    store_query,
    wait_until,
    write_config,
)

from impctl.modbus.config import LinkConfig

TZ = ZoneInfo("Europe/Ljubljana")
OWNER = (OWNER_SETPOINT_RAW, OWNER_MODE)
#: What a normal night journals: the owner's setpoint and loop-1 mode.
REGISTERS = ["loop1_setpoint", "loop1_mode"]


def _status(config: Path) -> tuple[dict, str]:
    as_json = run_impctl("status", "--json", "--config", str(config))
    as_text = run_impctl("status", "--config", str(config))
    assert as_json.returncode == 0 and as_text.returncode == 0, as_json.stderr + as_text.stderr
    return json.loads(as_json.stdout), as_text.stdout


@contextlib.contextmanager
def _normal_night(tmp_path: Path):
    """A daemon on state directory "first" running a normal night on the simulator; "second"
    is another configuration for the same heat pump (spelt ``localhost``)."""
    morning = datetime(2026, 1, 12, 3, 0, tzinfo=TZ)
    with sim_process(tmp_path, morning, 1200.0) as sim:
        # A 3.5 h window at 1200×: the normal night (with its preheat) lasts ~11 s of wall time.
        night = {"window": "02:30-06:00", "preheat_h": 0.25}
        first = write_config(tmp_path / "first.toml", daemon_mapping(
            tmp_path / "first", sim.port, sim.clock, night=night))
        second = write_config(tmp_path / "second.toml", daemon_mapping(
            tmp_path / "second", sim.port, sim.clock, night=night,
            heatpump={"host": "localhost"}))
        db = tmp_path / "first" / "impctl.db"
        d = start_daemon(first, db, tmp_path / "first.log")
        try:
            wait_until(lambda: "next night job at" in d.output(), 30, "the daemon", proc=d.proc)
            queued = run_cli("trigger", "--kind", "normal", "--setpoint", "22", "--now",
                             "--force", "--config", str(first))
            assert queued.returncode == 0, queued.stderr
            wait_until(lambda: owner_state(sim.port)[0] == 220, 30, "the normal night",
                       proc=d.proc)
            yield SimpleNamespace(sim=sim, first=first, second=second, db=db, d=d)
        finally:
            stop_process(d.proc)


def test_a_second_daemon_on_the_same_heat_pump_is_refused(tmp_path):
    with _normal_night(tmp_path) as r:
        d = r.d
        # Another configuration, another state directory, the same heat pump.
        other = run_cli("daemon", "--config", str(r.second), timeout_s=30)
        assert other.returncode == 2, other.stderr
        [line] = other.stderr.splitlines()
        assert f"PID {d.proc.pid}" in line and f"state_dir {tmp_path / 'first'}" in line
        assert f"heat pump at tcp 127.0.0.1:{r.sim.port} unit 20" in line, line
        # Nor does a foreground night start on it.
        fg = run_cli("trigger", "--kind", "normal", "--now", "--force", "--foreground",
                     "--config", str(r.second), timeout_s=30)
        assert fg.returncode == 2 and f"PID {d.proc.pid}" in fg.stderr, fg.stderr
        assert store_query(tmp_path / "second" / "impctl.db", lambda s: s.nights()) in (
            None, [])
        assert owner_state(r.sim.port)[0] == 220  # the night goes on, untouched
        assert store_query(r.db, lambda s: s.night(1).state) == "active"
        d.proc.kill()
        d.proc.wait(10)
        # The kernel dropped the dead daemon's heat-pump lock: once the first store's
        # journal is restored, the second daemon may drive the heat pump.
        assert run_cli("restore", "--config", str(r.first)).returncode == 0
        assert owner_state(r.sim.port) == OWNER
        d2 = start_daemon(r.second, tmp_path / "second" / "impctl.db",
                          tmp_path / "second.log")
        try:
            wait_until(lambda: "next night job at" in d2.output(), 30, "the second daemon",
                       proc=d2.proc)
        finally:
            assert stop_process(d2.proc) == 0


def test_status_is_calm_while_a_daemon_supervises_the_night(tmp_path):
    with _normal_night(tmp_path) as r:
        d = r.d
        # A normal night in progress: the owner's settings are journaled, and that is
        # normal; status says who brings them back instead of shouting.
        st, text = _status(r.first)
        assert "RESTORE PENDING" not in text, text
        assert (f"restore:   night in progress, supervised by daemon PID {d.proc.pid}; the "
                "heat pump will be restored at its end (loop1_setpoint, loop1_mode)"
                ) in text, text
        assert st["current_night"]["supervised"] is True
        assert st["pending_restore"] == REGISTERS
        assert st["restore"] == {"registers": REGISTERS, "state": "night",
                                 "pid": d.proc.pid, "role": "daemon"}
        d.proc.kill()  # nothing supervises the night any more
        d.proc.wait(10)
        st, text = _status(r.first)
        assert st["restore"]["state"] == "unsupervised" and st["restore"]["pid"] is None
        assert ("RESTORE PENDING: loop1_setpoint, loop1_mode: nothing supervises the heat "
                "pump; start the daemon (it restores first) or run impctl restore") in text, text
        assert run_cli("restore", "--config", str(r.first)).returncode == 0
        assert owner_state(r.sim.port) == OWNER
        st, text = _status(r.first)
        assert st["restore"] is None and "RESTORE" not in text and "restore:" not in text


def test_the_lock_is_keyed_by_the_heat_pumps_address(tmp_path):
    from impctl.daemon.locks.heat_pump import heat_pump_address, lock_path

    tcp = LinkConfig(host="LOCALHOST", port=5020)
    assert heat_pump_address(tcp) == "tcp 127.0.0.1:5020 unit 20"
    assert lock_path(tcp, tmp_path) == lock_path(LinkConfig(host="127.0.0.1", port=5020),
                                                 tmp_path)
    assert lock_path(tcp, tmp_path) != lock_path(LinkConfig(host="127.0.0.1", port=5020,
                                                            device_id=21), tmp_path)
    # /dev/serial/by-id/… names and the tty they point to are one heat pump.
    tty = tmp_path / "ttyUSB0"
    tty.touch()
    by_id = tmp_path / "usb-FTDI_FT232R-if00-port0"
    os.symlink(tty, by_id)
    a = LinkConfig(transport="rtu", serial_port=str(by_id))
    b = LinkConfig(transport="rtu", serial_port=str(tty))
    assert heat_pump_address(a) == heat_pump_address(b) == f"rtu {tty} unit 20"
    assert lock_path(a, tmp_path).parent == tmp_path
