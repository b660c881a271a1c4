"""Security: the daemon listens on nothing, its store is not world-accessible, the simulator
stays on loopback unless told otherwise.

* ``impctl daemon`` (a real subprocess, started with the umask of an ordinary shell, 022) has
  no listening TCP or UDP port and no listening AF_UNIX socket — idle and in the middle of a
  night (from ``/proc/PID/fd`` and ``/proc/PID/net/*``). Manual nights go through the store
  (``impctl trigger`` adds a row the daemon polls), so there is no trigger socket to protect.
* The store it creates — ``impctl.db`` and SQLite's ``-wal`` and ``-shm`` — is 0640 or
  stricter, also when ``impctl trigger`` creates it first (the unit's ``UMask=0027`` is a second
  line of defence, not the only one).
* The simulator refuses any non-loopback address without ``allow_remote`` (TCP and RTU over
  TCP, IPv4 and IPv6); ``impctl-sim --host 192.0.2.10`` exiting 2 is already proven by
  ``test_simulator_server``.
* ``systemd-analyze security --offline=true`` exposure ≤ 2.5 for ``deploy/impctl.service`` is
  proven by ``test_deploy.test_unit_security_exposure_at_most_2_5`` (not repeated here).
"""

from __future__ import annotations

import os
import stat
import subprocess

import pytest
from daemon_fixtures import (
    IMPCTL,
    ROOT,
    daemon_mapping,
    owner_state,
    sim_process,
    stop_process,
    wait_until,
    write_config,
)
from impctl_sim import KronotermSimulator, SimConfig
from reliability_fixtures import MORNING, listening_sockets, socket_inodes
from sim_fixtures import clock, run

from impctl.errors import InputError
from impctl.store import Store


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def _shell_umask():
    os.umask(0o022)


def test_daemon_listens_on_nothing_and_its_store_is_not_world_accessible(tmp_path):
    with sim_process(tmp_path, MORNING, 3600.0) as sim:
        state = tmp_path / "state"
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            state, sim.port, sim.clock, night={"window": "22:00-23:00", "preheat_h": 0.5}))
        # `impctl trigger` before the daemon ever ran creates the store: 0640 under umask 022.
        queued = subprocess.run([*IMPCTL, "trigger", "--kind", "constrained", "--now", "--force",
                                 "--config", str(config)], capture_output=True, text=True,
                                cwd=ROOT, preexec_fn=_shell_umask, timeout=60)
        assert queued.returncode == 0, queued.stderr
        log = tmp_path / "daemon.log"
        with log.open("w") as out:
            daemon = subprocess.Popen([*IMPCTL, "daemon", "--config", str(config)], stdout=out,
                                      stderr=subprocess.STDOUT, cwd=ROOT,
                                      preexec_fn=_shell_umask)
        try:
            wait_until(lambda: "next night job at" in log.read_text(), 30, "the daemon",
                       proc=daemon)
            idle = listening_sockets(daemon.pid)
            wait_until(lambda: owner_state(sim.port)[1] == 0, 30, "the night to switch off",
                       proc=daemon)
            in_night = listening_sockets(daemon.pid)
            sockets = socket_inodes(daemon.pid)
        finally:
            assert stop_process(daemon) == 0
        assert idle == [] and in_night == [], (idle, in_night)
        assert sockets  # it does hold sockets: its Modbus client connection
        for name in ("impctl.db", "impctl.db-wal", "impctl.db-shm"):
            path = state / name
            if path.exists():
                assert _mode(path) & 0o007 == 0, (name, oct(_mode(path)))
        assert _mode(state / "impctl.db") == 0o640
        with Store(state / "impctl.db") as store:
            assert store.nights()[0].source == "trigger"  # the trigger went through the store


def test_unit_sets_a_restrictive_umask():
    """The second line of defence for files the daemon creates besides the store (the write
    budget, the fit's work files)."""
    assert "\nUMask=0027\n" in (ROOT / "deploy" / "impctl.service").read_text()


@pytest.mark.parametrize("host", ["0.0.0.0", "::", "192.0.2.10", "gateway.example"])
def test_simulator_refuses_non_loopback_without_the_flag(host):
    async def body():
        sim = KronotermSimulator(SimConfig(clock=clock()))
        with pytest.raises(InputError, match="refusing to listen"):
            await sim.start(host, 0)
        with pytest.raises(InputError, match="refusing to listen"):
            await sim.start(rtu=f"socket://{'[::]' if host == '::' else host}:0")
        await sim.stop()
    run(body())


def test_simulator_binds_loopback_and_wider_only_when_allowed():
    async def body():
        for host, allow in (("127.0.0.1", False), ("::1", False), ("localhost", False),
                            ("0.0.0.0", True)):
            sim = KronotermSimulator(SimConfig(clock=clock()))
            try:
                port = await sim.start(host, 0, allow_remote=allow)
                assert port > 0
            finally:
                await sim.stop()
    run(body())
