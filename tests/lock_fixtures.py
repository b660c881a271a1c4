"""Real unprivileged users for the heat-pump lock tests (the tests run as root).

* :func:`as_user` runs a function in a forked child that has dropped to another user
  (``setgroups``/``setgid``/``setuid``; the kernel checks every access), and returns what it
  returned or raises what it raised;
* :func:`holding_as_user` does the same but keeps the child (and what it opened and locked)
  alive for the ``with`` block;
* :func:`deployed_lock_dir` makes ``/run/lock/impctl`` under a scratch root with the real
  ``systemd-sysusers`` and ``systemd-tmpfiles`` from ``deploy/impctl.sysusers`` and
  ``deploy/impctl.tmpfiles``;
* :func:`scratch_root` is a world-searchable scratch directory on a tmpfs (``/dev/shm``, like
  ``/run/lock``), since pytest's own ``tmp_path`` is private to root.

A child may only use modules its parent imported already: after ``setuid`` it cannot read
the interpreter's library under ``/root``.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
NOBODY = 65534
#: What the other user plants as a fake holder note (never to be named as the holder).
FAKE_PID = 4242


def _drop(uid: int, gid: int, groups: tuple[int, ...]) -> None:
    os.setgroups(list(groups))
    os.setgid(gid)
    os.setuid(uid)


def _child(fn: Callable[[], Any], uid: int, gid: int, groups: tuple[int, ...], out: int) -> None:
    """The forked child's whole life: drop, run, report, never return into pytest."""
    try:
        try:
            _drop(uid, gid, groups)
            result: tuple[str, Any] = ("ok", fn())
        except BaseException as exc:  # noqa: BLE001 - reported to the parent as it is
            result = ("error", exc)
        try:
            data = pickle.dumps(result)
        except Exception:  # noqa: BLE001
            data = pickle.dumps(("error", RuntimeError(repr(result))))
        os.write(out, len(data).to_bytes(8, "big") + data)
    finally:
        os._exit(0)


def _receive(fd: int) -> Any:
    chunks = b""
    while len(chunks) < 8 or len(chunks) < 8 + int.from_bytes(chunks[:8], "big"):
        more = os.read(fd, 65536)
        if not more:
            raise RuntimeError("the child ended without reporting")
        chunks += more
    kind, value = pickle.loads(chunks[8:])
    if kind == "error":
        raise value
    return value


def as_user(fn: Callable[[], Any], uid: int = NOBODY, gid: int = NOBODY,
            groups: tuple[int, ...] = ()) -> Any:
    """``fn()`` run by a real unprivileged process with these ids."""
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read)
        _child(fn, uid, gid, groups, write)
    os.close(write)
    try:
        return _receive(read)
    finally:
        os.close(read)
        os.waitpid(pid, 0)


@contextlib.contextmanager
def holding_as_user(fn: Callable[[], Any], uid: int = NOBODY, gid: int = NOBODY,
                    groups: tuple[int, ...] = ()) -> Iterator[SimpleNamespace]:
    """``fn()`` run by a real unprivileged process that stays alive, holding whatever ``fn``
    opened and locked, until the block ends; yields its ``pid`` and ``result``."""
    read, write = os.pipe()
    hold_r, hold_w = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read)
        os.close(hold_w)

        def hold() -> Any:
            kept = fn()
            os.write(write, b"R")  # ready: fn's result follows once released
            os.read(hold_r, 1)  # until the parent closes its end
            return repr(kept)

        _child(hold, uid, gid, groups, write)
    os.close(write)
    os.close(hold_r)
    try:
        first = os.read(read, 1)
        if first != b"R":  # fn failed: its error is what the child reports
            rest = first + b"".join(iter(lambda: os.read(read, 65536), b""))
            kind, value = pickle.loads(rest[8:])
            raise value if kind == "error" else RuntimeError(value)
        yield SimpleNamespace(pid=pid)
    finally:
        os.close(hold_w)
        with contextlib.suppress(Exception):
            _receive(read)
        os.close(read)
        os.waitpid(pid, 0)


@contextlib.contextmanager
def scratch_root() -> Iterator[Path]:
    """A world-searchable scratch directory on a tmpfs, removed afterwards."""
    base = Path(tempfile.mkdtemp(prefix="impctl-lockdir-",
                                 dir="/dev/shm" if os.path.isdir("/dev/shm") else None))
    os.chmod(base, 0o755)
    try:
        yield base
    finally:
        shutil.rmtree(base, ignore_errors=True)


def run_lock_dir(base: Path) -> Path:
    """``<base>/run/lock``: root's, mode 1777, like ``/run/lock`` after a reboot."""
    run_lock = base / "run" / "lock"
    run_lock.mkdir(parents=True)
    os.chmod(base / "run", 0o755)
    os.chmod(run_lock, 0o1777)
    return run_lock


def deployed_lock_dir(base: Path) -> SimpleNamespace:
    """``<base>/run/lock/impctl`` made by the real ``systemd-sysusers`` and
    ``systemd-tmpfiles --create`` from this checkout's deploy files, with ``<base>`` as the
    root; ``uid``/``gid`` are the service user's and group's, as sysusers allocated them."""
    assert shutil.which("systemd-tmpfiles") and shutil.which("systemd-sysusers")
    (base / "etc").mkdir(exist_ok=True)
    run_lock = base / "run" / "lock"
    if not run_lock.exists():
        run_lock_dir(base)
    for tool, conf in (("systemd-sysusers", "impctl.sysusers"),
                       ("systemd-tmpfiles", "impctl.tmpfiles")):
        args = [tool, f"--root={base}", str(ROOT / "deploy" / conf)]
        if tool == "systemd-tmpfiles":
            args.insert(1, "--create")
        proc = subprocess.run(args, capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr
    [user] = [line.split(":") for line in (base / "etc" / "passwd").read_text().splitlines()
              if line.startswith("impctl:")]
    return SimpleNamespace(path=run_lock / "impctl", user="impctl", uid=int(user[2]),
                           gid=int(user[3]))
