"""One process drives a heat pump per machine: a lock keyed by the heat pump's address.

The store's ``daemon.lock`` (:mod:`.lock`) keeps two daemons off one state directory; this
lock keeps two daemons with different state directories off one heat pump. Its file lives in
a directory every impctl on the machine shares: ``$IMPCTL_LOCK_DIR``, else
``/run/lock/impctl`` (``/run/lock`` is the FHS place for locks; a tmpfs, so nothing survives
a reboot). The directory is created mode 1777 like ``/run/lock`` itself, so daemons running as
different users (systemd's ``DynamicUser=``, a person's shell) see each other's locks; the
unit needs ``ReadWritePaths=/run/lock`` under ``ProtectSystem=strict``. The file is named
after the address (TCP ``host:port`` + unit, or the serial device's real path + unit) and
holds the holder's PID and state directory; ``flock`` makes the kernel drop the lock when the
process dies, also on SIGKILL.
"""

from __future__ import annotations

import contextlib
import hashlib
import ipaddress
import json
import os
import re
from datetime import UTC, datetime
from pathlib import Path

from ..errors import InputError
from ..modbus.config import LinkConfig
from .lock import DaemonRunning, FlockHolder, flock_within

LOCK_DIR_ENV = "IMPCTL_LOCK_DIR"
DEFAULT_LOCK_DIR = "/run/lock/impctl"


def lock_dir() -> Path:
    """The machine-wide directory of heat-pump locks."""
    return Path(os.environ.get(LOCK_DIR_ENV) or DEFAULT_LOCK_DIR)


def heat_pump_address(link: LinkConfig) -> str:
    """The heat pump as one string, the same for every spelling of one address:
    ``tcp 192.168.1.50:502 unit 20`` or ``rtu /dev/ttyUSB0 unit 20``."""
    if link.transport == "tcp":
        host = link.host.strip().lower()
        if host == "localhost":
            host = "127.0.0.1"
        with contextlib.suppress(ValueError):
            host = ipaddress.ip_address(host.strip("[]")).compressed
        return f"tcp {host}:{link.port} unit {link.device_id}"
    port = link.serial_port
    if "://" not in port:  # a device path: /dev/serial/by-id/… and /dev/ttyUSB0 are one
        port = os.path.realpath(port)
    return f"rtu {port} unit {link.device_id}"


def lock_path(link: LinkConfig, directory: Path | None = None) -> Path:
    """The lock file of the heat pump at ``link``."""
    address = heat_pump_address(link)
    readable = re.sub(r"[^A-Za-z0-9.]+", "_", address).strip("_")[:80]
    digest = hashlib.sha256(address.encode()).hexdigest()[:8]
    return (directory or lock_dir()) / f"{readable}-{digest}.lock"


def _holder(path: Path) -> dict:
    """What the holder wrote: in the lock file, or (when the file belongs to another user)
    in its ``<lock>.<uid>`` note next to it; the newest counts."""
    found = []
    for candidate in [path, *path.parent.glob(path.name + ".*")]:
        with contextlib.suppress(OSError, ValueError):
            data = json.loads(candidate.read_text() or "{}")
            if isinstance(data, dict) and "pid" in data:
                found.append(data)
    return max(found, key=lambda d: str(d.get("started", "")), default={})


class HeatPumpLock(FlockHolder):
    """The machine-wide lock of one heat pump, held for the life of the process.

    Parameters
    ----------
    link : the heat pump's link from the configuration
    state_dir : the holder's state directory (named to a second daemon)
    role : what holds it ("daemon", "trigger --foreground")
    directory : the lock directory (default :func:`lock_dir`)
    """

    def __init__(self, link: LinkConfig, state_dir: str | Path, role: str = "daemon",
                 directory: Path | None = None):
        self.address = heat_pump_address(link)
        self.path = lock_path(link, directory)
        self.state_dir, self.role = str(state_dir), role
        self._fd: int | None = None
        self._note: Path | None = None

    def _open(self) -> tuple[int, bool]:
        """(fd, writable) of the lock file, creating the directory and file if needed."""
        folder = self.path.parent
        fix = ("set IMPCTL_LOCK_DIR to a directory every impctl on this machine can write, "
               "or under systemd add ReadWritePaths=/run/lock to the unit")
        if not folder.is_dir():
            try:
                folder.mkdir(mode=0o1777, parents=False)
                os.chmod(folder, 0o1777)  # the umask narrowed mkdir's mode
            except FileExistsError:
                pass
            except OSError as exc:
                raise InputError(f"cannot create the heat-pump lock directory: "
                                 f"{exc.strerror}; {fix}", folder) from None
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except PermissionError as denied:  # another user's file: flock works read-only too
            try:
                return os.open(self.path, os.O_RDONLY), False
            except OSError:
                raise InputError(f"cannot open the heat-pump lock: {denied.strerror}; {fix}",
                                 self.path) from None
        except OSError as exc:
            raise InputError(f"cannot open the heat-pump lock: {exc.strerror}; {fix}",
                             self.path) from None
        with contextlib.suppress(OSError):  # readable by a daemon running as another user
            if os.fstat(fd).st_uid == os.getuid():
                os.fchmod(fd, 0o644)
        return fd, True

    def acquire(self, wait_s: float = 1.0) -> HeatPumpLock:
        """Take the lock, or raise :class:`~.lock.DaemonRunning` naming the holder's PID and
        state directory."""
        fd, writable = self._open()
        if not flock_within(fd, wait_s):
            os.close(fd)
            held = _holder(self.path)
            who = (f"PID {held['pid']}, state_dir {held.get('state_dir', '?')}"
                   if held else "another process")
            raise DaemonRunning(
                f"another impctl {(held or {}).get('role') or 'daemon'} ({who}) already drives the "
                f"heat pump at {self.address}; one daemon per heat pump: stop it first, "
                "or point this configuration at another heat pump", self.path) from None
        content = json.dumps({"pid": os.getpid(), "role": self.role,
                              "state_dir": self.state_dir, "heat_pump": self.address,
                              "started": datetime.now(UTC).isoformat()}).encode()
        try:
            if writable:
                os.ftruncate(fd, 0)
                os.pwrite(fd, content, 0)
            else:
                self._note = self.path.with_name(f"{self.path.name}.{os.getuid()}")
                self._note.write_bytes(content)
        except OSError:  # the lock holds all the same; only the holder's name is missing
            pass
        self._fd = fd
        return self

