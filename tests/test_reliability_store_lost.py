"""The store is truncated mid-night (an SD card after a power cut), the heating off.

Real parts: ``impctl daemon`` and ``impctl-sim`` as subprocesses on loopback TCP; the power cut
is a SIGKILL of the daemon with the heating off, then the store file is cut short on disk (its
WAL and index lost with it); ``impctl restore`` runs as a subprocess, as systemd's
``ExecStopPost=`` runs it. The heat pump's registers are read straight from the simulator with
a plain pymodbus client.

What is promised: the owner's journaled values are also kept outside the database
(``owner-values.json``: atomic, checksummed), so ``impctl restore`` puts them back and verifies
them without the store — also when the truncated file still opens (as an empty database, or
without the journal's last entries) — and prints one line; a copy that fails its checksum is
never used, and then the one line says that the heat pump may still be off and which
registers to check.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterator
from pathlib import Path

import pytest
from cli_fixtures import run_impctl
from daemon_fixtures import (
    OWNER_MODE,
    OWNER_SETPOINT_RAW,
    SimProcess,
    cut_store,
    daemon_mapping,
    owner_state,
    restored_by_cli,
    run_cli,
    sim_process,
    start_daemon,
    stop_process,
    wait_until,
    write_config,
)
from reliability_fixtures import MORNING, db_facts

SPEED = 600.0
GUARD_S = 120.0
OWNER = (OWNER_SETPOINT_RAW, OWNER_MODE)


@contextlib.contextmanager
def power_cut_mid_night(tmp_path: Path) -> Iterator[tuple[SimProcess, Path, Path]]:
    """A constrained night with the heating off, then SIGKILL: (sim, config, state_dir)."""
    state = tmp_path / "state"
    with sim_process(tmp_path, MORNING, SPEED) as sim:
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
            wait_until(lambda: owner_state(sim.port) == (225, 0) and len(
                db_facts(db)["samples"]) >= 3, GUARD_S, "the heating to be off",
                proc=daemon.proc)
            daemon.proc.kill()
            daemon.proc.wait(10)
        finally:
            stop_process(daemon.proc)
        assert owner_state(sim.port) == (225, 0)
        yield sim, config, state


@pytest.mark.parametrize("size", [None, 100, 0], ids=["half", "header-cut", "empty"])
def test_impctl_restore_without_the_store(tmp_path, size):
    with power_cut_mid_night(tmp_path) as (sim, config, state):
        copy = json.loads((state / "owner-values.json").read_text())
        assert {e["register"]: e["raw_value"] for e in copy["entries"]} == {
            "loop1_setpoint": OWNER_SETPOINT_RAW, "loop1_mode": OWNER_MODE}
        assert (state / "owner-values.json").stat().st_mode & 0o777 == 0o640
        cut_store(state / "impctl.db", size)
        if size == 100:  # the store does not open: status says what is still to restore
            status = run_impctl("status", "--config", str(config))
            assert status.returncode == 2 and status.stderr.count("\n") == 1, status
            assert "lists loop1_setpoint, loop1_mode to restore (run impctl restore)" in \
                status.stderr, status.stderr
        restored_by_cli(config)
        assert owner_state(sim.port) == OWNER
        assert json.loads((state / "owner-values.json").read_text())["entries"] == []
        again = run_cli("restore", "--config", str(config))  # nothing left to put back
        assert again.returncode == 0 and "Traceback" not in again.stderr, again.stderr
        assert again.stdout.startswith("nothing to restore"), again.stdout
        assert owner_state(sim.port) == OWNER


def test_a_copy_that_fails_its_checksum_is_never_used(tmp_path):
    with power_cut_mid_night(tmp_path) as (sim, config, state):
        path = state / "owner-values.json"
        data = json.loads(path.read_text())
        data["entries"][0]["raw_value"] = 300  # 30.0 °C, not the owner's 21.0 °C
        path.write_text(json.dumps(data))
        cut_store(state / "impctl.db", 100)
        done = run_cli("restore", "--config", str(config))
        assert done.returncode == 1, (done.stdout, done.stderr)
        assert "Traceback" not in done.stderr and done.stdout == "", done
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1, lines
        line = lines[0]
        assert "not a usable impctl database" in line and "checksum" in line, line
        assert "may still be off" in line and "2187" in line and "2042" in line, line
        assert owner_state(sim.port) == (225, 0)  # nothing written from a bad copy


def test_the_copy_follows_the_journal_and_only_lost_entries_are_taken_back(tmp_path):
    """Real SQLite and the real file: the copy lists exactly the pending entries; a copy
    left behind by a crash between the database's commit and the file's rename (its entries
    already closed in the store) is not taken back — it would restore over the owner's later
    choice; an empty store (truncated to 0 bytes) takes the copy's entries back, pending."""
    from impctl.store import Store
    from impctl.store.restore.owner_file import read_owner_values, write_owner_values

    state = tmp_path / "state"
    with Store(state / "impctl.db") as store:
        a = store.journal_record(None, "loop1_setpoint", 2186, 210)
        b = store.journal_record(None, "loop1_mode", 2041, 1)
        entries, _ = read_owner_values(store.owner_file)
        assert [(e.register, e.raw_value) for e in entries] == [
            ("loop1_setpoint", 210), ("loop1_mode", 1)]
        store.journal_mark_owner_changed(b.id, 0)  # the owner's own choice: never restored
        assert [e.register for e in read_owner_values(store.owner_file)[0]] == [
            "loop1_setpoint"]
        stale = [a, b]
        store.journal_mark_restored(a.id)
        assert read_owner_values(store.owner_file)[0] == []
        write_owner_values(store.owner_file, stale)  # as if the last rename never happened
        assert store.recover_journal() == []
        assert store.journal_pending() == []
        assert read_owner_values(store.owner_file)[0] == []  # the stale copy is corrected
        write_owner_values(store.owner_file, stale)
    (state / "impctl.db").write_bytes(b"")  # the store lost everything
    with Store(state / "impctl.db") as store:
        taken = store.recover_journal()
        assert [(e.register, e.raw_value) for e in taken] == [
            ("loop1_setpoint", 210), ("loop1_mode", 1)]
        assert [e.register for e in store.journal_pending()] == ["loop1_setpoint", "loop1_mode"]
        assert store.recover_journal() == []  # taken once
        assert store.integrity_check() == "ok"
