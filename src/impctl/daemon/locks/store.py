"""One process drives the heat pump per store: a lock file with the holder's PID and heartbeat.

``<state_dir>/daemon.lock`` is held with ``flock(LOCK_EX)`` by ``impctl daemon`` (and by
``impctl trigger --foreground``) for as long as it runs; the kernel drops the lock when the
process dies, also on SIGKILL, so a stale file never blocks a restart. The file holds the
holder's PID and role as JSON; its modification time is the heartbeat, touched by the daemon's
health loop only while its event loop runs and its store answers. ``impctl status`` and
``impctl trigger`` read both without taking the lock for more than an instant.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Self

from ...errors import InputError

LOCK_NAME = "daemon.lock"
#: Wall seconds between heartbeats of a healthy daemon.
HEARTBEAT_S = 10.0
#: A heartbeat older than this [wall s] means the holder is alive but stuck.
STALE_S = 60.0


class DaemonRunning(InputError):
    """Another process already drives the heat pump of this store."""


@dataclass(frozen=True)
class DaemonInfo:
    """What the lock file says about the process driving the heat pump.

    Attributes
    ----------
    running : a process holds the lock now
    pid : its PID (or the last holder's when not running); None when never started
    role : "daemon" or "trigger --foreground"
    heartbeat_age_s : wall seconds since the last heartbeat (None without a lock file)
    notes : what the holder published with :meth:`DaemonLock.note` (e.g. its MQTT link)
    """

    running: bool
    pid: int | None = None
    role: str | None = None
    heartbeat_age_s: float | None = None
    notes: dict = field(default_factory=dict)

    @property
    def stale(self) -> bool:
        """Running, but the heartbeat is older than :data:`STALE_S` (hung event loop)."""
        return self.running and (self.heartbeat_age_s or 0.0) > STALE_S

    def describe(self) -> str:
        """One line for people, e.g. ``running (PID 812, heartbeat 4 s ago)``."""
        age = "" if self.heartbeat_age_s is None else f"{_age(self.heartbeat_age_s)} ago"
        if self.running:
            who = "" if self.role in (None, "daemon") else f"{self.role}, "
            if self.stale:
                return (f"NOT RESPONDING: PID {self.pid} holds the lock but its last heartbeat "
                        f"was {age}")
            return f"running ({who}PID {self.pid}, heartbeat {age})"
        if self.pid is None:
            return "NOT RUNNING (never started on this store)"
        return (f"NOT RUNNING: nothing watches the heat pump (last PID {self.pid}, "
                f"last heartbeat {age})")


def _age(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def _read(path: Path) -> tuple[int | None, str | None, dict]:
    try:
        data = json.loads(path.read_text() or "{}")
        notes = data.get("notes")
        return (int(data["pid"]), str(data.get("role", "daemon")),
                notes if isinstance(notes, dict) else {})
    except (OSError, ValueError, KeyError, TypeError):
        return None, None, {}


def probe(state_dir: str | Path) -> DaemonInfo:
    """Is a daemon (or foreground night) driving the heat pump of this state directory?"""
    path = Path(state_dir) / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return DaemonInfo(False)
    except OSError:  # not readable by this user: fall back to the PID alone
        return DaemonInfo(False)
    try:
        pid, role, notes = _read(path)
        age = max(0.0, time.time() - os.fstat(fd).st_mtime)
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return DaemonInfo(True, pid, role, age, notes)
        fcntl.flock(fd, fcntl.LOCK_UN)
        return DaemonInfo(False, pid, role, age, notes)
    finally:
        os.close(fd)


def flock_within(fd: int, wait_s: float) -> bool:
    """Take an exclusive ``flock`` on ``fd``, retrying for ``wait_s`` [s] (``impctl status``
    may hold a shared lock for an instant); False when another process keeps it."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.05)


class FlockHolder:
    """A file held open under a kernel ``flock`` (released by the kernel even on ``kill -9``);
    a context manager. Subclasses open and lock it in ``acquire`` and keep its descriptor in
    ``_fd``."""

    _fd: int | None = None

    def acquire(self) -> Self:
        raise NotImplementedError

    def release(self) -> None:
        """Drop the lock (the file stays, with what its holder wrote in it)."""
        if self._fd is not None:
            with contextlib.suppress(OSError):
                fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> Self:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


class DaemonLock(FlockHolder):
    """The exclusive lock of one store's heat pump, held for the life of the process.

    Parameters
    ----------
    state_dir : the configuration's state directory (must exist)
    role : what holds it, shown by ``impctl status``
    """

    def __init__(self, state_dir: str | Path, role: str = "daemon"):
        self.path = Path(state_dir) / LOCK_NAME
        self.role = role
        self._fd: int | None = None
        self._content: dict = {}

    def acquire(self, wait_s: float = 1.0) -> DaemonLock:
        """Take the lock, or raise :class:`DaemonRunning` naming the holder's PID.

        Retries for ``wait_s``: ``impctl status`` may hold a shared lock for an instant.
        """
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o640)
        except OSError as exc:
            raise InputError(f"cannot create the lock file: {exc.strerror}", self.path) from None
        if not flock_within(fd, wait_s):
            os.close(fd)
            pid, role, _ = _read(self.path)
            who = f"PID {pid}" if pid is not None else "another process"
            raise DaemonRunning(
                f"another impctl {role or 'daemon'} ({who}) already drives the heat pump of "
                f"this store; stop it first (systemctl stop impctl)",
                self.path.parent) from None
        self._content = {"pid": os.getpid(), "role": self.role,
                         "started": datetime.now(UTC).isoformat(), "notes": {}}
        self._fd = fd
        self._write()
        return self

    def _write(self) -> None:
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, json.dumps(self._content).encode(), 0)

    def note(self, key: str, value: dict | None) -> None:
        """Publish ``value`` under ``key`` for ``impctl status`` (JSON-able); the file is
        rewritten only when a note changed, not at every heartbeat (flash storage)."""
        if self._fd is None or self._content["notes"].get(key) == value:
            return
        self._content["notes"][key] = value
        self._write()

    def heartbeat(self) -> None:
        """Touch the lock file: the holder is alive and healthy."""
        if self._fd is not None:
            os.utime(self._fd)

