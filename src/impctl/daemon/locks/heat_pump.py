"""One process drives a heat pump per machine: a lock keyed by the heat pump's address.

The store's ``daemon.lock`` (:mod:`.store`) keeps two daemons off one state directory; this
lock keeps two daemons with different state directories off one heat pump. Its file lives in
a directory every impctl on the machine shares: ``$IMPCTL_LOCK_DIR``, else
``/run/lock/impctl`` (``/run/lock`` is the FHS place for locks; a tmpfs, so nothing survives
a reboot). ``deploy/impctl.tmpfiles`` creates it at boot as ``root:impctl`` mode 3770: the
service user (group ``impctl``) and root share it, nobody else can enter it, and the sticky
bit keeps one member from removing another's lock. Without that line only root's impctl makes
it (root's own, 0755), since a directory another user made would be theirs to fake.

Nothing in that directory is taken on trust. It is opened without following a symbolic link
and refused (one line naming its owner and mode) unless it belongs to root or to the running
user and others cannot write it; its owner's group may, as the owner chose to share it. A lock
file is created with ``O_EXCL`` or, when it exists, opened only if it is a regular file with
one link whose owner could write the directory; impctl never changes the mode of a file it did
not create. After ``flock`` the file must still be the one the path names (a lock file removed
or replaced in between would let two daemons hold two files), else it starts over. The file is
named after the address (TCP ``host:port`` + unit, or the serial device's real path + unit)
and holds the holder's PID and state directory, written by the holder alone; ``flock`` makes
the kernel drop the lock when the process dies, also on SIGKILL.
"""

from __future__ import annotations

import contextlib
import errno
import grp
import hashlib
import ipaddress
import json
import os
import pwd
import re
import stat
from datetime import UTC, datetime
from pathlib import Path

from ...errors import InputError
from ...modbus.config import LinkConfig
from .store import DaemonRunning, FlockHolder, flock_within

LOCK_DIR_ENV = "IMPCTL_LOCK_DIR"
DEFAULT_LOCK_DIR = "/run/lock/impctl"
#: How to make the default directory right (the line every refusal ends with).
_FIX = ("as root remove it and run systemd-tmpfiles --create impctl.conf "
        "(deploy/impctl.tmpfiles), or set IMPCTL_LOCK_DIR to a directory of your own")
#: Open/replace races tolerated before giving up (each needs a writer of the directory).
_ATTEMPTS = 5


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


def _user(uid: int) -> str:
    with contextlib.suppress(KeyError):
        return f"{pwd.getpwuid(uid).pw_name} (uid {uid})"
    return f"uid {uid}"


def _group(gid: int) -> str:
    with contextlib.suppress(KeyError):
        return grp.getgrgid(gid).gr_name
    return f"gid {gid}"


def _kind(st: os.stat_result) -> str:
    mode = st.st_mode
    for test, name in ((stat.S_ISLNK, "a symbolic link"), (stat.S_ISDIR, "a directory"),
                       (stat.S_ISFIFO, "a named pipe"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device")):
        if test(mode):
            return name
    return "a regular file"


def _describe(st: os.stat_result) -> str:
    """``owned by nobody (uid 65534), group nogroup, mode 0755``."""
    return (f"owned by {_user(st.st_uid)}, group {_group(st.st_gid)}, "
            f"mode {stat.S_IMODE(st.st_mode):04o}")


def open_lock_dir(folder: Path) -> tuple[int, os.stat_result]:
    """(descriptor, stat) of the lock directory, created if missing; refuses a directory that
    another user could write or a symbolic link in its place.

    Trusted: owned by root or by the running user, not writable by others. Group write is the
    owner's choice to share it (``root:impctl`` 3770 from tmpfiles.d) and is accepted.
    """
    if str(folder) == DEFAULT_LOCK_DIR and os.geteuid() != 0 \
            and not os.path.lexists(folder):
        # Made by another user, the machine's lock directory would be theirs to fake.
        raise InputError("missing: root creates the heat-pump lock directory at boot from "
                         "deploy/impctl.tmpfiles (as root: systemd-tmpfiles --create "
                         "impctl.conf), or set IMPCTL_LOCK_DIR to a directory of your own",
                         folder)
    try:
        os.mkdir(folder, 0o755)
    except FileExistsError:
        pass
    except OSError as exc:
        raise InputError(f"cannot create the heat-pump lock directory: {exc.strerror}; "
                         "as root run systemd-tmpfiles --create impctl.conf "
                         "(deploy/impctl.tmpfiles), or set IMPCTL_LOCK_DIR to a directory of "
                         "your own; under systemd the unit needs "
                         "ReadWritePaths=-/run/lock/impctl", folder) from None
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError as exc:
        try:
            found = os.lstat(folder)
            seen = f"{_kind(found)}, {_describe(found)}"
        except OSError:
            seen = "not readable"
        if exc.errno in (errno.ELOOP, errno.ENOTDIR):
            raise InputError(f"refusing the heat-pump lock directory: {seen}, not a "
                             f"directory; {_FIX}", folder) from None
        raise InputError(f"cannot open the heat-pump lock directory: {exc.strerror} ({seen}); "
                         "run as root or as a member of its group, or set IMPCTL_LOCK_DIR to "
                         "a directory of your own", folder) from None
    st = os.fstat(fd)
    if st.st_uid not in (0, os.geteuid()) or st.st_mode & stat.S_IWOTH:
        os.close(fd)
        who = "root" if os.geteuid() == 0 else f"root or {_user(os.geteuid())}"
        raise InputError(f"refusing the heat-pump lock directory: {_describe(st)}; it must "
                         f"belong to {who} and not be writable by others, or another user "
                         f"could take, fake or remove the lock; {_FIX}", folder) from None
    return fd, st


def _may_write_dir(st: os.stat_result, folder: os.stat_result) -> bool:
    """Could the owner of ``st`` have created it in ``folder`` (root, the running user, the
    directory's owner, or a member of the group the owner shares it with)?"""
    if st.st_uid in (0, os.geteuid(), folder.st_uid):
        return True
    return bool(folder.st_mode & stat.S_IWGRP) and st.st_gid == folder.st_gid


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

    def _refuse(self, what: str) -> InputError:
        return InputError(f"refusing the heat-pump lock: {what}; the lock must be a regular "
                          "file with one link that impctl created; remove it as root",
                          self.path)

    def _open(self, dirfd: int, folder: os.stat_result) -> int | None:
        """The lock file, opened for writing and created if missing; None when it changed
        under us (try again)."""
        name = self.path.name
        try:
            fd = os.open(name, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                         | os.O_CLOEXEC, 0o600, dir_fd=dirfd)
        except FileExistsError:
            pass
        except OSError as exc:
            raise InputError(f"cannot create the heat-pump lock: {exc.strerror} (the "
                             f"directory is {_describe(folder)}); {_FIX}", self.path) from None
        else:
            if folder.st_mode & stat.S_IWGRP:  # ours: for the group the directory is shared with
                with contextlib.suppress(OSError):
                    os.fchown(fd, -1, folder.st_gid)
                with contextlib.suppress(OSError):
                    os.fchmod(fd, 0o660)
            return fd
        try:  # look before opening: never open a link, a pipe or a device here
            seen = os.stat(name, dir_fd=dirfd, follow_symlinks=False)
        except FileNotFoundError:
            return None
        if not stat.S_ISREG(seen.st_mode):
            raise self._refuse(f"{_kind(seen)} in its place, {_describe(seen)}")
        if seen.st_nlink != 1:
            raise self._refuse(f"a file with {seen.st_nlink} links (a hard link to another "
                               f"file), {_describe(seen)}")
        if not _may_write_dir(seen, folder):
            raise self._refuse(f"a file {_describe(seen)}, who cannot write the lock directory")
        try:
            fd = os.open(name, os.O_RDWR | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_NOCTTY
                         | os.O_CLOEXEC, dir_fd=dirfd)
        except FileNotFoundError:
            return None
        except PermissionError as denied:  # the holder must be able to name itself in it
            raise InputError(f"cannot open the heat-pump lock: {denied.strerror} (it is "
                             f"{_describe(seen)}); run as root or as a member of the lock "
                             "directory's group, or as root remove it while no impctl runs",
                             self.path) from None
        except OSError as exc:  # replaced by a link in between: ELOOP
            raise self._refuse(exc.strerror) from None
        now = os.fstat(fd)
        if (now.st_dev, now.st_ino) != (seen.st_dev, seen.st_ino):
            os.close(fd)
            return None
        return fd

    def _still_named(self, dirfd: int, fd: int) -> bool:
        """Is ``fd`` still the file the lock's name points to (not removed or replaced)?"""
        try:
            named = os.stat(self.path.name, dir_fd=dirfd, follow_symlinks=False)
        except FileNotFoundError:
            return False
        held = os.fstat(fd)
        return (named.st_dev, named.st_ino) == (held.st_dev, held.st_ino)

    def acquire(self, wait_s: float = 1.0) -> HeatPumpLock:
        """Take the lock, or raise :class:`~.lock.DaemonRunning` naming the holder's PID and
        state directory (as the holder wrote them in the lock file)."""
        dirfd, folder = open_lock_dir(self.path.parent)
        try:
            for _ in range(_ATTEMPTS):
                fd = self._open(dirfd, folder)
                if fd is None:
                    continue
                if not flock_within(fd, wait_s):
                    held = _holder(fd)
                    os.close(fd)
                    raise self._running(held)
                if self._still_named(dirfd, fd):
                    break
                os.close(fd)  # locked a file no longer under the lock's name: start over
            else:
                raise InputError("the heat-pump lock file keeps being removed or replaced; "
                                 "find what does it", self.path)
        finally:
            os.close(dirfd)
        content = json.dumps({"pid": os.getpid(), "role": self.role,
                              "state_dir": self.state_dir, "heat_pump": self.address,
                              "started": datetime.now(UTC).isoformat()}).encode()
        with contextlib.suppress(OSError):  # the lock holds all the same
            os.ftruncate(fd, 0)
            os.pwrite(fd, content, 0)
        self._fd = fd
        return self

    def _running(self, held: dict) -> DaemonRunning:
        who = (f"PID {held['pid']}, state_dir {held.get('state_dir', '?')}"
               if held else "another process")
        return DaemonRunning(
            f"another impctl {held.get('role') or 'daemon'} ({who}) already drives the heat "
            f"pump at {self.address}; one daemon per heat pump: stop it first, or point this "
            "configuration at another heat pump", self.path)


def _holder(fd: int) -> dict:
    """What the holder wrote in the lock file open at ``fd`` ({} when nothing readable)."""
    with contextlib.suppress(OSError, ValueError):
        data = json.loads(os.pread(fd, 4096, 0) or b"{}")
        if isinstance(data, dict) and "pid" in data:
            return data
    return {}
