"""The state directory's file system fills up in the middle of a constrained night.

Real parts only: ``state_dir`` is a real 2 MB tmpfs (mounted by the test: the suite runs as
root), filled by writing a file until the kernel answers ENOSPC; the daemon is ``impctl
daemon`` in a subprocess, the heat pump an ``impctl-sim`` subprocess on loopback TCP, the
restore ``impctl restore`` as systemd's ``ExecStopPost=`` runs it. Waits poll observable state
(the simulator's registers, what a read-only connection sees in the store) under generous
guards; nothing is timed.

What is promised: a restore never depends on recording anything. The sample that cannot be
committed ends the night with one clear line, the owner's settings go back and are verified by
read-back although neither the write budget nor the journal can record it, SIGTERM and
``impctl restore`` with the disk still full exit 0 without a traceback, and once space returns
both SQLite files pass ``integrity_check`` and the next start closes the journal (the night is
not valid, whatever part of its end could still be recorded).
"""

from __future__ import annotations

import contextlib
import errno
import json
import sqlite3
import subprocess
from collections.abc import Iterator
from pathlib import Path

from daemon_fixtures import (
    OWNER_MODE,
    OWNER_SETPOINT_RAW,
    daemon_mapping,
    owner_state,
    run_cli,
    sim_process,
    start_daemon,
    stop_process,
    wait_until,
    write_config,
)
from reliability_fixtures import MORNING, db_facts

#: 600×: one 60 s poll every 0.1 s of wall time; the night switches off 0.6 s after it starts.
SPEED = 600.0
#: Guard [s of wall time] of each wait: generous, not a deadline the daemon must meet.
GUARD_S = 120.0
OWNER = (OWNER_SETPOINT_RAW, OWNER_MODE)


@contextlib.contextmanager
def small_tmpfs(path: Path, size: str = "2m") -> Iterator[Path]:
    """A real tmpfs of ``size`` mounted on ``path`` (unmounted at the end)."""
    path.mkdir(parents=True, exist_ok=True)
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size},mode=0750", "tmpfs", str(path)],
                   check=True)
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=False)


def fill(directory: Path) -> Path:
    """Write zeros to ``directory/fill`` until the file system says ENOSPC (like ``dd``)."""
    target = directory / "fill"
    chunk = bytes(4096)
    with target.open("wb", buffering=0) as out:
        try:
            while True:
                out.write(chunk)
        except OSError as exc:
            assert exc.errno == errno.ENOSPC, exc
    return target


def _integrity(path: Path) -> str:
    with contextlib.closing(sqlite3.connect(f"file:{path}?mode=ro", uri=True)) as con:
        return con.execute("PRAGMA integrity_check").fetchone()[0]


def test_state_dir_fills_mid_night_restore_needs_no_space(tmp_path):
    state = tmp_path / "state"
    with small_tmpfs(state), sim_process(tmp_path, MORNING, SPEED) as sim:
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            state, sim.port, sim.clock,
            night={"window": "22:00-23:30", "preheat_h": 0.1, "sample_interval_s": 60}))
        db = state / "impctl.db"
        daemon = start_daemon(config, db, tmp_path / "daemon.log")
        try:
            wait_until(lambda: "next night job at" in daemon.output(), GUARD_S,
                       "the daemon to be up", proc=daemon.proc)
            from impctl.store import Store

            with Store(db) as store:
                store.add_request("constrained", 21.0, "now", forced=True)

            def heating_off_and_sampled() -> bool:
                facts = db_facts(db)
                return owner_state(sim.port) == (225, 0) and sum(
                    1 for night, *_ in facts["samples"] if night == 1) >= 3
            wait_until(heating_off_and_sampled, GUARD_S, "the heating to be off",
                       proc=daemon.proc)
            filler = fill(state)
            # The next sample cannot be committed: the night ends and the heat pump is
            # restored, although neither the budget nor the journal can record it.
            wait_until(lambda: owner_state(sim.port) == OWNER, GUARD_S,
                       "the owner's settings back on the heat pump", proc=daemon.proc)
            assert db_facts(db)["pending"], "the journal could not have recorded the restore"
            wait_until(lambda: "night 1 aborted" in daemon.output(), GUARD_S,
                       "the night's end line", proc=daemon.proc)
            log = daemon.output()
            assert "night aborted: the store cannot record: disk full" in log, log[-3000:]
            # SIGTERM with the disk still full: a clean exit, no traceback.
            assert stop_process(daemon.proc) == 0
        finally:
            stop_process(daemon.proc)
        log = daemon.output()
        assert "Traceback" not in log, log[-4000:]
        assert "impctl daemon stopped" in log
        assert owner_state(sim.port) == OWNER

        # ExecStopPost= with the disk still full: one line, exit 0, nothing to write.
        restore = run_cli("restore", "--config", str(config))
        assert restore.returncode == 0, (restore.stdout, restore.stderr)
        assert "Traceback" not in restore.stderr, restore.stderr
        lines = restore.stdout.splitlines()
        assert len(lines) == 1, lines
        assert lines[0].startswith("restored and verified"), lines
        assert "cannot record" in lines[0], lines
        assert owner_state(sim.port) == OWNER

        # Space returns: both SQLite files are sound, and the next start closes the journal
        # and marks the night interrupted.
        filler.unlink()
        assert _integrity(db) == "ok"
        assert _integrity(state / "writes.db") == "ok"
        again = start_daemon(config, db, tmp_path / "daemon2.log")
        try:
            wait_until(lambda: not db_facts(db)["pending"], GUARD_S,
                       "the journal to be closed", proc=again.proc)
            facts = db_facts(db)
            assert facts["integrity"] == "ok"
            # Not valid either way: recorded as aborted when a small write still found room
            # (SQLite reuses the WAL space of the failed commit), else swept as interrupted.
            state_, valid, reasons = facts["nights"][1]
            assert valid == 0, facts["nights"]
            assert state_ == "interrupted" or (
                state_ == "aborted" and "the store cannot record: disk full" in reasons), \
                facts["nights"]
            assert owner_state(sim.port) == OWNER
        finally:
            assert stop_process(again.proc) == 0
        assert "Traceback" not in again.output()
        # The copy of the journal outside the store lists nothing pending any more.
        assert json.loads((state / "owner-values.json").read_text())["entries"] == []
