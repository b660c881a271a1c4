"""A Dask cluster as on a real one: ``dask scheduler`` and ``dask worker`` started as separate
programs on loopback (random free port), stopped — the whole process groups — when done."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

DASK = str(Path(sys.executable).with_name("dask"))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def dask_cluster(log_dir: Path, nworkers: int, env: dict[str, str] | None = None
                 ) -> Iterator[tuple[str, list[subprocess.Popen]]]:
    """(scheduler address, [scheduler process, worker process]) of a scheduler and one
    ``dask worker --nworkers N --nthreads 1`` program, ready: all N workers registered."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, **(env or {})}
    log_dir.mkdir(parents=True, exist_ok=True)
    logs = [open(log_dir / "scheduler.log", "w"), open(log_dir / "worker.log", "w")]  # noqa: SIM115
    procs: list[subprocess.Popen] = []
    try:
        procs.append(subprocess.Popen(
            [DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
            stdout=subprocess.DEVNULL, stderr=logs[0], env=env, start_new_session=True))
        procs.append(subprocess.Popen(
            [DASK, "worker", address, "--nworkers", str(nworkers), "--nthreads", "1",
             "--no-dashboard", "--host", "127.0.0.1"],
            stdout=subprocess.DEVNULL, stderr=logs[1], env=env, start_new_session=True))
        _wait_for_workers(address, nworkers, procs)
        yield address, procs
    finally:
        for p in reversed(procs):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGTERM)
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
        for f in logs:
            f.close()


def _wait_for_workers(address: str, n: int, procs: list[subprocess.Popen]) -> None:
    from distributed import Client

    deadline = time.monotonic() + 120
    while True:
        if any(p.poll() is not None for p in procs):
            raise RuntimeError(f"a Dask program exited early: {[p.args[1] for p in procs]}")
        try:
            with Client(address, timeout="5s") as client:
                client.wait_for_workers(n, timeout=120)
            return
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(1)
