"""``impctl daemon`` as a real subprocess against an ``impctl-sim`` subprocess.

The two processes share the accelerated wall clock: the simulator writes its clock spec to
``--clock-file`` and the daemon's ``[clock]`` section is built from it. That clock is
load-sensitive (simulated time runs on while a process waits for the CPU), so these tests keep
their simulated spans short, their polls far apart in wall time, and wait on observable state
(the heat pump's registers, the store) with generous guards, never on the clock. Signals are real
(SIGTERM, SIGKILL), the store is a real SQLite file, and the heat pump's state is read straight
from the simulator with a plain pymodbus client.
"""

from __future__ import annotations

import contextlib
import json
import signal
import sqlite3
import subprocess
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path
from zoneinfo import ZoneInfo

import pytest
from cli_fixtures import run_impctl
from daemon_fixtures import (
    IMPCTL,
    OWNER_MODE,
    OWNER_SETPOINT_RAW,
    ROOT,
    DaemonProcess,
    SimProcess,
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

TZ = ZoneInfo("Europe/Ljubljana")
#: 3600×: a 7 h window lasts 7 s, time enough to signal the daemon mid-night even on a
#: loaded machine (the waits poll the heat pump's state, they assert no timing).
SPEED = 3600.0
#: A night whose validity is asserted: 1800×, one 600 s poll per 0.33 s of wall time, which
#: even 2 cores saturated by other processes leave it (a poll takes 20–70 ms then).
VALID_NIGHT_SPEED = 1800.0
#: Guard [s of wall time] for a wait on the daemon: generous, not a deadline it must meet (a
#: daemon that misses its first preheat runs the night a simulated day, 24 s, later).
GUARD_S = 120.0
#: 18:30 local: the first night's preheat (21:00) is 2.5 s away (if the daemon were not up
#: by then, the night would simply run a day later).
EPOCH = datetime(2026, 1, 12, 18, 30, tzinfo=TZ)
#: 03:00 local for manual nights: far from the scheduled one and from the UTC day's end.
MORNING = datetime(2026, 1, 12, 3, 0, tzinfo=TZ)
OWNER = (OWNER_SETPOINT_RAW, OWNER_MODE)


@contextlib.contextmanager
def rig(tmp_path: Path, *, campaign: dict | None = None, night: dict | None = None,
        epoch: datetime = EPOCH, speed: float = SPEED
        ) -> Iterator[tuple[SimProcess, Path, Path]]:
    """A simulator subprocess and a daemon config for it: (sim, config path, db path)."""
    with sim_process(tmp_path, epoch, speed) as sim:
        mapping = daemon_mapping(
            tmp_path / "state", sim.port, sim.clock,
            night={"window": "22:00-05:00", "preheat_h": 1.0, **(night or {})},
            campaign=campaign or {"enabled": False})
        config = write_config(tmp_path / "config.toml", mapping)
        yield sim, config, tmp_path / "state" / "impctl.db"


def _daemon(config: Path, db: Path, log: Path) -> DaemonProcess:
    d = start_daemon(config, db, log)
    wait_until(lambda: "next night job at" in d.output(), GUARD_S, "the daemon to be ready",
               proc=d.proc)
    return d


def _switched_off_with_samples(sim: SimProcess, db: Path, n: int = 3):
    """The heat pump shows loop 1 off and at least ``n`` committed samples say so."""
    def check():
        if owner_state(sim.port)[1] != 0:
            return None
        rows = store_query(db, lambda s: [x for night in s.nights()
                                          for x in s.samples(night.id) if x.loop_mode == 0])
        return rows if rows and len(rows) >= n else None
    return check


ONE_CONSTRAINED = {"enabled": True, "mode": "fixed", "constrained_nights": 1,
                   "normal_setpoints_c": [], "fit_when_complete": False}


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_stop_signal_mid_night_restores_before_exit(tmp_path, sig):
    with rig(tmp_path, campaign=ONE_CONSTRAINED) as (sim, config, db):
        d = _daemon(config, db, tmp_path / "daemon.log")
        try:
            wait_until(_switched_off_with_samples(sim, db), GUARD_S, "the night to switch off",
                       proc=d.proc)
            assert owner_state(sim.port) == (225, 0)  # T_max held, then loop 1 off
            d.proc.send_signal(sig)
            assert d.proc.wait(30) == 0
        finally:
            stop_process(d.proc)
        # Nothing else writes to the simulator: the daemon restored before it exited.
        assert owner_state(sim.port) == OWNER
        nights = store_query(db, lambda s: s.nights())
        assert len(nights) == 1
        assert nights[0].state == "aborted" and nights[0].valid is False
        assert nights[0].reasons[0] == "stop requested (signal)"
        assert store_query(db, lambda s: s.journal_pending()) == []
        log = d.output()
        assert f"received {sig.name}" in log and "impctl daemon stopped" in log
        assert log.index("restored loop1_mode") < log.index("impctl daemon stopped")


def test_a_foreground_night_whose_terminal_goes_away_restores(tmp_path):
    """The SSH session of ``impctl trigger --foreground`` closes mid-night: SIGHUP, and every
    line it writes after that fails (its terminal is gone: a broken pipe here). Nothing else
    would restore a foreground night — no daemon, no ExecStopPost."""
    with sim_process(tmp_path, MORNING, 600.0) as sim:
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            tmp_path / "state", sim.port, sim.clock,
            night={"window": "02:30-06:00", "preheat_h": 0.25}))
        fg = subprocess.Popen([*IMPCTL, "trigger", "--kind", "constrained", "--now", "--force",
                               "--foreground", "--config", str(config)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
        try:
            wait_until(lambda: owner_state(sim.port)[1] == 0, GUARD_S, "the switch-off",
                       proc=fg)
            fg.stdout.close()
            fg.stderr.close()
            fg.send_signal(signal.SIGHUP)
            fg.wait(GUARD_S)
        finally:
            stop_process(fg)
        assert owner_state(sim.port) == OWNER
        night = store_query(tmp_path / "state" / "impctl.db", lambda s: s.night(1))
        assert night.state == "aborted" and night.reasons[0] == "stop requested (signal)"
        assert store_query(tmp_path / "state" / "impctl.db", lambda s: s.journal_pending()) == []


def test_sigkill_mid_night_then_restart_sweeps_and_restores(tmp_path):
    with rig(tmp_path, campaign=ONE_CONSTRAINED) as (sim, config, db):
        d = _daemon(config, db, tmp_path / "daemon.log")
        try:
            wait_until(_switched_off_with_samples(sim, db, 5), GUARD_S,
                       "the night to switch off",
                       proc=d.proc)
            before = {s.ts for s in store_query(db, lambda st: st.samples(1))}
            d.proc.kill()
            assert d.proc.wait(10) == -signal.SIGKILL
        finally:
            stop_process(d.proc)
        # The dead daemon left the heat pump in the experiment's state, the journal pending.
        assert owner_state(sim.port) == (225, 0)
        with contextlib.closing(sqlite3.connect(db)) as con:
            assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert len(store_query(db, lambda s: s.journal_pending())) == 2
        status = run_impctl("status", "--config", str(config))
        assert status.returncode == 0, status.stderr
        assert "RESTORE PENDING: loop1_setpoint, loop1_mode" in status.stdout
        assert "night:     1 constrained T_set 21 °C, active" in status.stdout

        # Restart: the orphan sweep marks the night interrupted and restores at once.
        d2 = _daemon(config, db, tmp_path / "daemon2.log")
        try:
            wait_until(lambda: owner_state(sim.port) == OWNER, GUARD_S, "the restore",
                       proc=d2.proc)
            night = store_query(db, lambda s: s.night(1))
            assert night.state == "interrupted" and night.valid is False
            assert night.reasons == ("interrupted: impctl stopped during the night",)
            assert store_query(db, lambda s: s.journal_pending()) == []
            after = {s.ts for s in store_query(db, lambda st: st.samples(1))}
            assert before <= after  # every sample committed before the kill survived
            assert store_query(db, lambda s: s.integrity_check()) == "ok"
            events = [m for _, _, m in store_query(db, lambda s: s.events(20))]
            assert "night 1 was interrupted; restoring" in events
        finally:
            assert stop_process(d2.proc) == 0


def test_trigger_now_then_status_nights_export_restore(tmp_path):
    from impctl.imp import read_nights

    # One poll per 600 s: 333 ms of wall time at 1800×, which 12 reads from the simulator
    # subprocess fit even on a loaded machine (120 s at 3600× left 33 ms: coverage fell to
    # 42 %); a 3.5 h window (a normal night's shortest valid one) keeps it to 8 s of wall time.
    with rig(tmp_path, night={"preheat_h": 0.5, "sample_interval_s": 600,
                              "window": "22:00-01:30"},
             epoch=MORNING, speed=VALID_NIGHT_SPEED) as (sim, config, db):
        d = _daemon(config, db, tmp_path / "daemon.log")
        try:
            # --force: the daemon's start may take the simulated clock past 05:00 already.
            queued = run_cli("trigger", "--kind", "normal", "--setpoint", "22", "--now",
                             "--force", "--config", str(config))
            assert queued.returncode == 0, queued.stderr
            assert queued.stdout.startswith("queued request 1: normal night at 22 °C (now)")
            # The running daemon takes it up: the heat pump goes to 22 °C.
            wait_until(lambda: owner_state(sim.port)[0] == 220, GUARD_S, "the triggered night",
                       proc=d.proc)
            live = run_impctl("status", "--config", str(config))
            assert live.returncode == 0, live.stderr
            assert "night:     1 normal T_set 22 °C, active" in live.stdout
            # issue 15: the generation and where it comes from (set in this config)
            assert "generation: extended (configured)" in live.stdout
            wait_until(lambda: store_query(db, lambda s: s.night(1).valid) is not None, GUARD_S,
                       "the night to finish and be assessed", proc=d.proc)
            assert owner_state(sim.port) == OWNER
            night = store_query(db, lambda s: s.night(1))
            assert (night.state, night.valid, night.source) == ("done", True, "trigger"), \
                night.reasons
            assert night.reasons == ("window ended",)
            n_samples = store_query(db, lambda s: s.sample_count(1))
            in_window = [x.ts for x in store_query(db, lambda s: s.samples(1))
                         if night.window_start <= x.ts <= night.window_end]
            preheat = [x.ts for x in store_query(db, lambda s: s.samples(1))
                       if x.ts < night.window_start]
            assert 0 < len(in_window) < n_samples  # the preheat is sampled too
            assert len(preheat) + len(in_window) <= n_samples  # not after the window

            # impctl status / nights / export / restore on the result.
            while True:  # a status taken within one simulated (UTC) day
                day = sim.clock.now().date()
                st = run_impctl("status", "--json", "--config", str(config))
                if sim.clock.now().date() == day:
                    break
            assert st.returncode == 0, st.stderr
            status = json.loads(st.stdout)
            assert status["current_night"] is None and status["pending_restore"] == []
            assert status["pending_requests"] == 0
            assert status["heatpump"]["generation"]["doubt"] is None
            assert status["heatpump"]["quirks"] == {}
            # Writes are counted per day of the heat pump's (simulated) clock: the set and
            # the restore of 2187 on the night's day, none on a later day.
            assert night.started.date() == night.ended.date()
            used = 2 if day == night.ended.date() else 0
            assert status["writes_today"] == {"2187": {"used": used, "limit": 12},
                                              "2042": {"used": 0, "limit": 12}}
            nights = run_impctl("nights", "--config", str(config))
            assert nights.returncode == 0, nights.stderr
            row = nights.stdout.splitlines()[1].split()
            assert row[:3] == ["1", "normal", "22.0"] and row[6:9] == ["done", "yes",
                                                                        str(n_samples)]
            out = tmp_path / "nights.csv"
            exp = run_impctl("export", "--format", "csv", "--out", str(out), "--config",
                          str(config))
            assert exp.returncode == 0, exp.stderr
            wrote = len(preheat) + len(in_window)
            assert exp.stdout.strip() == f"wrote {wrote} samples to {out}"
            # The measured-data format of `impctl fit`: the window's samples, from its start;
            # before them the pre-heat, read as a piece of the night the season model takes.
            [pre, read] = read_nights(out)
            assert (pre.night_id, pre.kind, pre.phase) == ("1", "normal", "preheat")
            assert pre.start == preheat[0] and len(pre.time_s) == len(preheat)
            assert read.kind == "normal" and len(read.time_s) == len(in_window)
            assert read.phase == ""
            assert read.start == in_window[0] and read.time_s[0] == 0.0
            nothing = run_cli("restore", "--config", str(config))
            assert nothing.returncode == 0 and nothing.stdout.strip() == "nothing to restore"

            # `impctl restore` after the daemon died mid-night puts the owner's state back.
            # Simulated daytime by now: a --now night then needs --force.
            run_cli("trigger", "--kind", "constrained", "--now", "--force", "--config",
                    str(config))
            wait_until(lambda: owner_state(sim.port) == (225, 0), GUARD_S,
                       "the constrained night to switch off", proc=d.proc)
            d.proc.kill()
            d.proc.wait(10)
            restored = run_cli("restore", "--config", str(config))
            assert restored.returncode == 0, restored.stderr
            assert restored.stdout.strip() == "restored and verified"
            assert owner_state(sim.port) == OWNER
            assert store_query(db, lambda s: s.journal_pending()) == []
        finally:
            stop_process(d.proc)
        # The manual nights ran beside the 1 s trigger poll, not inside it: no scheduler
        # warning per second of night in the journal.
        assert "maximum number of running instances" not in d.output()
