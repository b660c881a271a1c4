"""The owner changes the heat pump while impctl is down in the middle of a night.

The daemon dies (SIGKILL, a power cut) with the heating off; the owner, cold, raises the room
setpoint on the controller before anything restarts. The restart — the daemon's start, or
``impctl restore`` as systemd's ``ExecStopPost=`` runs it, also from ``owner-values.json``
when the store is lost — must keep the owner's new setpoint and put back only what the owner
did not touch, as a night's own restore does.

Real parts: ``impctl daemon`` and ``impctl-sim`` as subprocesses, the tests' Modbus proxy
between them on loopback TCP, a real SIGKILL, a real SQLite file; the owner writes over a
Modbus connection of their own, and the heat pump is read straight from the simulator with a
plain pymodbus client.

What is promised:

* a register holding neither what impctl last wrote and read back nor the owner's journaled
  value is the owner's: kept, its journal entry closed as theirs, one warning line and an
  event; the other registers come back to the owner's values;
* with no change by the owner, everything comes back;
* a write impctl could not read back before it died claims nothing: the owner's value goes
  back into that register whatever it holds; so does a journal kept by an impctl from before
  it kept what it holds (a store of schema 6, an ``owner-values.json`` of version 1), which
  still opens and restores.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import json
import sqlite3
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from daemon_fixtures import (
    OWNER_MODE,
    OWNER_SETPOINT_RAW,
    SimProcess,
    cut_store,
    daemon_mapping,
    modbus_write,
    owner_state,
    restored_by_cli,
    run_cli,
    sim_process,
    start_daemon,
    stop_process,
    wait_until,
    write_config,
)
from reliability_fixtures import MORNING, ProxyThread, db_facts
from sim_fixtures import budget, client, run, simulator

from impctl.controller import restore_all
from impctl.store import SCHEMA_VERSION, Store
from impctl.store.restore.owner_file import OwnerValuesJournal, _canonical
from impctl.store.schema import MIGRATIONS

SPEED = 600.0
GUARD_S = 120.0
PREHEAT = 225          # T_max 22.5 °C: impctl's preheat setpoint, read back before the kill
OWNERS_NEW = 235       # 23.5 °C: what the owner sets while impctl is down
KEPT = "the owner's value kept"


@dataclass
class Killed:
    """A daemon killed mid-night: the simulator, the proxy the daemon talked through, its
    configuration and state directory."""

    sim: SimProcess
    proxy: ProxyThread
    config: Path
    state: Path

    def set_proxy(self, mode: str) -> None:
        """Switch the proxy's fault; returns once it is in force."""
        async def switch() -> None:
            self.proxy.proxy.set(mode)
        asyncio.run_coroutine_threadsafe(switch(), self.proxy.loop).result(10)


@contextlib.contextmanager
def killed_mid_night(tmp_path: Path, *, in_doubt: bool = False) -> Iterator[Killed]:
    """A constrained night, SIGKILLed once the heating is off. ``in_doubt``: the switch-off
    lands on the heat pump but the link drops before impctl can read it back, and the daemon
    dies so."""
    state = tmp_path / "state"
    with sim_process(tmp_path, MORNING, SPEED) as sim, contextlib.ExitStack() as stack:
        proxy = ProxyThread(sim.port)
        stack.callback(proxy.close)
        # A preheat of 6 s of wall time: time to switch the proxy before the switch-off.
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            state, proxy.port, sim.clock,
            night={"window": "22:00-23:30", "preheat_h": 1.0, "sample_interval_s": 60}))
        db = state / "impctl.db"
        killed = Killed(sim, proxy, config, state)
        daemon = start_daemon(config, db, tmp_path / "daemon.log")
        try:
            wait_until(lambda: "next night job at" in daemon.output(), GUARD_S,
                       "the daemon to be up", proc=daemon.proc)
            with Store(db) as store:
                store.add_request("constrained", 21.0, "now", forced=True)
            if in_doubt:
                # The preheat setpoint has passed the proxy (impctl reads it back next); the
                # next write, the switch-off, lands and the link drops before its answer.
                wait_until(lambda: owner_state(sim.port) == (PREHEAT, OWNER_MODE), GUARD_S,
                           "the preheat", interval_s=0.01, proc=daemon.proc)
                killed.set_proxy("down-after-write")
                wait_until(lambda: owner_state(sim.port) == (PREHEAT, 0)
                           and proxy.proxy.mode == "down", GUARD_S,
                           "the switch-off to land and the link to drop", proc=daemon.proc)
                assert proxy.proxy.stats.cut["down-after-write"] == 1
            else:
                wait_until(lambda: owner_state(sim.port) == (PREHEAT, 0) and len(
                    db_facts(db)["samples"]) >= 3, GUARD_S, "the heating to be off",
                    proc=daemon.proc)
            daemon.proc.kill()
            daemon.proc.wait(10)
        finally:
            stop_process(daemon.proc)
        assert owner_state(sim.port) == (PREHEAT, 0)
        killed.set_proxy("pass")
        yield killed


def restart(killed: Killed, how: str, log: Path) -> str:
    """Bring impctl back ``how``: ``daemon`` (its start restores), ``restore`` (the CLI) or
    ``restore-no-store`` (the CLI, the store cut to its header: from owner-values.json).
    Returns what it said (the daemon's log, the CLI's stdout and stderr)."""
    db = killed.state / "impctl.db"
    if how == "daemon":
        daemon = start_daemon(killed.config, db, log)
        try:
            wait_until(lambda: "next night job at" in daemon.output() and not db_facts(db)[
                "pending"], GUARD_S, "the restart to restore", proc=daemon.proc)
        finally:
            assert stop_process(daemon.proc) == 0
        return daemon.output()
    if how == "restore-no-store":
        cut_store(db, 100)
    done = restored_by_cli(killed.config)
    return done.stdout + done.stderr


def outcomes(state: Path) -> dict[str, str | None]:
    """Each register's journal outcome, the latest entry's (what another process sees)."""
    with contextlib.closing(sqlite3.connect(f"file:{state / 'impctl.db'}?mode=ro",
                                            uri=True)) as con:
        return {r: o for r, o in con.execute("SELECT register, outcome FROM journal ORDER BY id")}


def events(state: Path) -> list[str]:
    with contextlib.closing(sqlite3.connect(f"file:{state / 'impctl.db'}?mode=ro",
                                            uri=True)) as con:
        return [m for (m,) in con.execute("SELECT message FROM events ORDER BY id")]


@pytest.mark.parametrize("how", ["daemon", "restore", "restore-no-store"])
def test_the_owners_setpoint_set_while_impctl_was_down_is_kept(tmp_path, how):
    with killed_mid_night(tmp_path) as killed:
        modbus_write(killed.sim.port, 2187, OWNERS_NEW)   # the owner, while impctl is down
        said = restart(killed, how, tmp_path / "restart.log")
        assert owner_state(killed.sim.port) == (OWNERS_NEW, OWNER_MODE), (
            f"the owner's 23.5 °C set while impctl was down was written over: {said}")
        assert said.count(KEPT) == 1, said   # one warning line
        if how != "daemon":   # and the command's own line names what it left as it was
            assert "loop1_setpoint left as the owner set it" in said.splitlines()[0], said
        if how != "restore-no-store":
            assert outcomes(killed.state) == {
                "loop1_setpoint": f"owner changed it to raw {OWNERS_NEW}",
                "loop1_mode": "restored"}
            assert sum(KEPT in m for m in events(killed.state)) == 1, events(killed.state)
        again = run_cli("restore", "--config", str(killed.config))
        assert again.returncode == 0 and again.stdout.startswith("nothing to restore"), again
        assert owner_state(killed.sim.port) == (OWNERS_NEW, OWNER_MODE)


@pytest.mark.parametrize("how", ["daemon", "restore"])
def test_without_a_change_by_the_owner_everything_comes_back(tmp_path, how):
    with killed_mid_night(tmp_path) as killed:
        said = restart(killed, how, tmp_path / "restart.log")
        assert owner_state(killed.sim.port) == (OWNER_SETPOINT_RAW, OWNER_MODE), said
        assert KEPT not in said, said
        assert outcomes(killed.state) == {"loop1_setpoint": "restored",
                                          "loop1_mode": "restored"}


def test_a_switch_off_not_read_back_before_the_kill_claims_nothing(tmp_path):
    """The switch-off landed unseen, then the daemon died; the owner raises the setpoint and
    also puts loop 1 on their schedule (2) while impctl is down. The setpoint impctl had read
    back is told apart from the owner's: kept. Loop 1 held a value impctl never read back,
    so nothing is known of who set it: the owner's journaled mode (1) goes back."""
    with killed_mid_night(tmp_path, in_doubt=True) as killed:
        modbus_write(killed.sim.port, 2187, OWNERS_NEW)
        modbus_write(killed.sim.port, 2042, 2)
        said = restart(killed, "daemon", tmp_path / "restart.log")
        assert owner_state(killed.sim.port) == (OWNERS_NEW, OWNER_MODE), said
        assert said.count(KEPT) == 1, said
        assert outcomes(killed.state) == {
            "loop1_setpoint": f"owner changed it to raw {OWNERS_NEW}",
            "loop1_mode": "restored"}


def test_a_journal_from_before_the_held_values_restores_whatever_it_finds(tmp_path):
    recorded = "2026-01-12T21:00:00+00:00"
    (tmp_path / "store").mkdir()
    path = tmp_path / "store" / "impctl.db"     # its own copy goes beside it
    db = sqlite3.connect(path, isolation_level=None)
    for migration in MIGRATIONS[:6]:
        for statement in migration.split(";"):
            if statement.strip():
                db.execute(statement)
    db.execute("INSERT INTO journal (night_id, register, address, raw_value, recorded)"
               " VALUES (NULL, 'loop1_mode', 2041, 1, ?)", (recorded,))
    db.execute("PRAGMA user_version = 6")
    db.close()
    content = {"format": "impctl owner values", "version": 1, "updated": recorded,
               "entries": [{"id": 1, "night_id": None, "register": "loop1_mode",
                            "address": 2041, "raw_value": 1, "recorded": recorded}]}
    copy = tmp_path / "owner-values.json"
    copy.write_text(json.dumps({**content,
                                "sha256": hashlib.sha256(_canonical(content)).hexdigest()}))

    async def body():
        async with simulator() as sim, client(sim, budget=budget(tmp_path)) as hp:
            with Store(path) as store:
                assert store.schema_version == SCHEMA_VERSION
                [entry] = store.journal_pending()
                assert (entry.raw_value, entry.confirmed_raw) == (1, None)
                await hp.set_loop1_mode(0)     # an older impctl's switch-off
                assert await restore_all(hp, store, clock=sim.clock, timeout_s=10.0) == []
                assert store.integrity_check() == "ok"
            assert await sim.read_words(2042) == [OWNER_MODE]
            journal = OwnerValuesJournal(copy)
            assert journal.journal_pending()[0].confirmed_raw is None
            await hp.set_loop1_mode(2)         # neither: still not known to be the owner's
            assert await restore_all(hp, journal, clock=sim.clock, timeout_s=10.0) == []
            assert await sim.read_words(2042) == [OWNER_MODE]
    run(body())
