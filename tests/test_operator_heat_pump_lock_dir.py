"""The heat-pump lock directory against other local users: real unprivileged processes
(forked children that ``setuid`` to ``nobody`` or to the service user ``systemd-sysusers``
made), real ``impctl daemon`` / ``impctl trigger --foreground`` subprocesses as root, the
real ``systemd-tmpfiles`` line, a tmpfs whose ``run/lock`` is 1777 like ``/run/lock``.

* another user who makes ``impctl/`` first (after a reboot, before any impctl ran) and
  plants a symbolic link, a held lock or a fake holder note there, or who puts a symbolic
  link in its place, gets both commands refused with one line naming the directory, its
  owner and mode, and the fix; the link's target (root's 0600 file) keeps its content and
  mode, and no fake holder is ever named;
* the same checks apply to a person running impctl with ``IMPCTL_LOCK_DIR``; without the
  tmpfiles line only root's impctl makes the machine's ``/run/lock/impctl``;
* in the directory tmpfiles makes (``root:impctl`` 3770), even a member of the group cannot
  make root follow a link, open a pipe or write through a hard link;
* another user can neither take a lock (held or free), nor fake a holder note, nor remove
  the lock, nor squat a heat pump's lock name, in the tmpfiles directory and in the one
  root's impctl makes itself; the service user and root share one lock and name each other;
* a lock file removed and re-made between a daemon's ``open`` and its ``flock`` does not let
  two daemons start on one heat pump.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import stat
from pathlib import Path

import pytest
from daemon_fixtures import daemon_mapping, free_port, run_cli, write_config
from lock_fixtures import (
    FAKE_PID,
    NOBODY,
    as_user,
    deployed_lock_dir,
    holding_as_user,
    run_lock_dir,
    scratch_root,
)
from sim_fixtures import clock

from impctl.daemon.locks import heat_pump as hplock
from impctl.daemon.locks.heat_pump import HeatPumpLock, lock_path
from impctl.daemon.locks.store import DaemonRunning
from impctl.errors import InputError
from impctl.modbus.config import LinkConfig

SECRET = b"root's own settings\n"


@pytest.fixture
def base():
    with scratch_root() as path:
        yield path


@pytest.fixture
def secret(base: Path) -> Path:
    """A root-owned 0600 file an attacker would like root to overwrite."""
    path = base / "secret"
    path.write_bytes(SECRET)
    os.chmod(path, 0o600)
    return path


def _untouched(path: Path) -> bool:
    return path.read_bytes() == SECRET and stat.S_IMODE(path.stat().st_mode) == 0o600


def _config(tmp_path: Path) -> tuple[Path, LinkConfig]:
    """A configuration for a heat pump at a loopback port where nothing listens: every
    refusal here comes before the first Modbus request."""
    port = free_port()
    config = write_config(tmp_path / "impctl.toml",
                          daemon_mapping(tmp_path / "state", port, clock()))
    return config, LinkConfig(host="127.0.0.1", port=port)


def _plant_own_dir(folder: Path, lock: Path, secret: Path) -> None:
    folder.mkdir()
    os.chmod(folder, 0o755)
    os.symlink(secret, lock)


def _plant_held_lock(folder: Path, lock: Path) -> int:
    """nobody's directory with a lock file it holds and a fake holder note in it."""
    folder.mkdir()
    os.chmod(folder, 0o755)
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    os.write(fd, json.dumps({"pid": FAKE_PID, "state_dir": "/fake",
                             "started": "2099-01-01T00:00:00+00:00"}).encode())
    fcntl.flock(fd, fcntl.LOCK_EX)
    note = lock.with_name(f"{lock.name}.{NOBODY}")
    note.write_text(json.dumps({"pid": FAKE_PID, "state_dir": "/fake",
                                "started": "2099-01-01T00:00:00+00:00"}))
    return fd


@pytest.mark.parametrize("planted", ["own directory with a link", "held lock and fake note",
                                     "link to root's directory"])
def test_a_lock_directory_another_user_made_is_refused(tmp_path, base, secret, monkeypatch,
                                                       planted):
    folder = run_lock_dir(base) / "impctl"
    monkeypatch.setenv("IMPCTL_LOCK_DIR", str(folder))
    config, link = _config(tmp_path)
    lock = lock_path(link, folder)
    private = base / "private"  # root's own directory, 0700
    private.mkdir(mode=0o700)
    if planted == "own directory with a link":
        as_user(lambda: _plant_own_dir(folder, lock, secret))
        expect = "owned by nobody (uid 65534)"
    elif planted == "link to root's directory":
        as_user(lambda: os.symlink(private, folder))
        expect = "a symbolic link, owned by nobody (uid 65534)"
    else:
        expect = "owned by nobody (uid 65534)"
    with holding_as_user(lambda: _plant_held_lock(folder, lock)) \
            if planted == "held lock and fake note" else contextlib.nullcontext():
        for command in (["daemon"], ["trigger", "--kind", "normal", "--now", "--force",
                                     "--foreground"]):
            proc = run_cli(*command, "--config", str(config), timeout_s=30)
            assert proc.returncode == 2, proc.stderr
            [line] = proc.stderr.splitlines()
            prefix = f"impctl: {folder}: refusing the heat-pump lock directory: "
            assert line.startswith(prefix), line
            assert expect in line and "systemd-tmpfiles --create impctl.conf" in line, line
            assert str(FAKE_PID) not in line and "/fake" not in line, line
    assert _untouched(secret)
    assert list(private.iterdir()) == []


def test_the_same_checks_apply_to_a_person_with_impctl_lock_dir(base):
    """nobody running impctl with IMPCTL_LOCK_DIR at another user's directory, or at a
    directory anyone can write, is refused the same way."""
    link = LinkConfig(host="127.0.0.1", port=502)
    others, everyones, mine = base / "others", base / "everyones", base / "mine"
    for folder, owner, mode in ((others, 1234, 0o755), (everyones, NOBODY, 0o777),
                                (mine, NOBODY, 0o700)):
        folder.mkdir()
        os.chown(folder, owner, owner)
        os.chmod(folder, mode)

    def take(folder: Path) -> str:
        try:
            HeatPumpLock(link, "/home/nobody/impctl", directory=folder).acquire().release()
        except InputError as exc:
            return str(exc)
        return "taken"

    line = as_user(lambda: take(others))
    assert line.startswith(f"{others}: refusing the heat-pump lock directory: owned by uid "
                           "1234, group gid 1234, mode 0755; it must belong to root or "
                           "nobody (uid 65534) and not be writable by others"), line
    line = as_user(lambda: take(everyones))
    assert "owned by nobody (uid 65534), group nogroup, mode 0777" in line, line
    assert list(others.iterdir()) == [] and list(everyones.iterdir()) == []
    assert as_user(lambda: take(mine)) == "taken"


@pytest.mark.parametrize("planted", ["symbolic link", "named pipe", "hard link"])
def test_root_never_follows_what_a_group_member_put_in_the_lock_directory(
        base, secret, planted, monkeypatch):
    deployed = deployed_lock_dir(base)
    monkeypatch.setenv("IMPCTL_LOCK_DIR", str(deployed.path))
    link = LinkConfig(host="127.0.0.1", port=502)
    lock = lock_path(link, deployed.path)
    own = deployed.path / "own.txt"

    def plant() -> None:
        if planted == "symbolic link":
            os.symlink(secret, lock)
        elif planted == "named pipe":
            os.mkfifo(lock, 0o660)
        else:
            own.write_bytes(SECRET)
            os.chmod(own, 0o600)
            os.link(own, lock)

    as_user(plant, deployed.uid, deployed.gid, (deployed.gid,))
    with pytest.raises(InputError) as refused:
        HeatPumpLock(link, "/var/lib/impctl").acquire()
    [line] = str(refused.value).splitlines()
    kind = {"symbolic link": "a symbolic link in its place", "named pipe":
            "a named pipe in its place", "hard link": "a file with 2 links"}[planted]
    assert line.startswith(f"{lock}: refusing the heat-pump lock: {kind}"), line
    assert _untouched(secret)
    if planted == "hard link":
        assert own.read_bytes() == SECRET


def _attempts(folder: Path, lock: Path) -> dict[str, str]:
    """What another user tries against a lock directory: the outcome of each attempt."""
    out = {}
    mine = folder.parent / f"nobody-{os.getpid()}.lock"  # in the 1777 parent
    mine.write_text("{}")
    other = folder / "tcp_192.168.1.60_502_unit_20-00000000.lock"
    note = lock.with_name(f"{lock.name}.{NOBODY}")
    fake = json.dumps({"pid": FAKE_PID, "state_dir": "/fake",
                       "started": "2099-01-01T00:00:00+00:00"})
    for what, attempt in (
            ("take the lock", lambda: fcntl.flock(os.open(lock, os.O_RDONLY),
                                                  fcntl.LOCK_EX | fcntl.LOCK_NB)),
            ("fake a holder note", lambda: note.write_text(fake)),
            ("write the lock", lambda: lock.write_text(fake)),
            ("remove the lock", lambda: lock.unlink()),
            ("replace the lock", lambda: os.rename(mine, lock)),
            ("squat another heat pump", lambda: other.mkdir())):
        try:
            attempt()
            out[what] = "done"
        except PermissionError:
            out[what] = "denied"
        except OSError as exc:
            out[what] = exc.strerror
    return out


@pytest.mark.parametrize("made_by", ["tmpfiles", "root's impctl"])
def test_another_user_cannot_take_fake_or_remove_the_lock(base, made_by, monkeypatch):
    if made_by == "tmpfiles":
        folder = deployed_lock_dir(base).path
    else:  # no tmpfiles.d: the first impctl to run, as root, makes the directory
        folder = run_lock_dir(base) / "impctl"
    monkeypatch.setenv("IMPCTL_LOCK_DIR", str(folder))
    link = LinkConfig(host="127.0.0.1", port=502)
    lock = lock_path(link, folder)
    denied = dict.fromkeys(["take the lock", "fake a holder note", "write the lock",
                            "remove the lock", "replace the lock", "squat another heat pump"],
                           "denied")
    with HeatPumpLock(link, "/var/lib/impctl"):
        assert as_user(lambda: _attempts(folder, lock)) == denied
        with pytest.raises(DaemonRunning) as second:
            HeatPumpLock(link, "/srv/second").acquire()
        line = str(second.value)
        assert f"PID {os.getpid()}, state_dir /var/lib/impctl" in line, line
        assert str(FAKE_PID) not in line
    # Free again: still nothing another user can take or fake.
    assert as_user(lambda: _attempts(folder, lock)) == denied
    with HeatPumpLock(link, "/srv/second"):
        pass


def test_the_service_user_and_root_share_one_lock(base, monkeypatch):
    deployed = deployed_lock_dir(base)
    monkeypatch.setenv("IMPCTL_LOCK_DIR", str(deployed.path))
    link = LinkConfig(host="127.0.0.1", port=502)
    service = (deployed.uid, deployed.gid, (deployed.gid,))

    def hold() -> HeatPumpLock:
        return HeatPumpLock(link, "/var/lib/impctl").acquire()

    def try_take() -> str:
        try:
            HeatPumpLock(link, "/var/lib/impctl").acquire().release()
        except DaemonRunning as exc:
            return str(exc)
        return "taken"

    with holding_as_user(hold, *service) as daemon:
        with pytest.raises(DaemonRunning) as refused:
            HeatPumpLock(link, "/root/impctl", role="trigger --foreground").acquire()
        assert f"daemon (PID {daemon.pid}, state_dir /var/lib/impctl)" in str(refused.value)
    with HeatPumpLock(link, "/root/impctl", role="trigger --foreground"):
        line = as_user(try_take, *service)
        assert (f"another impctl trigger --foreground (PID {os.getpid()}, state_dir "
                "/root/impctl)") in line, line
    assert as_user(try_take, *service) == "taken"
    # A lock file root makes is the group's to use too.
    other = LinkConfig(host="127.0.0.1", port=503)
    with HeatPumpLock(other, "/root/impctl"):
        pass
    made = os.stat(lock_path(other, deployed.path))
    assert (made.st_uid, made.st_gid, stat.S_IMODE(made.st_mode)) == (0, deployed.gid, 0o660)
    assert as_user(lambda: HeatPumpLock(other, "/var/lib/impctl").acquire().path.name,
                   *service) == lock_path(other, deployed.path).name
    assert json.loads(lock_path(other, deployed.path).read_text())["state_dir"] == \
        "/var/lib/impctl"


def test_a_lock_file_replaced_before_flock_lets_only_one_daemon_start(base, monkeypatch):
    """Between a daemon's open and its flock, root removes the lock file and a second daemon
    makes a new one and takes it: the first must not take the removed file's lock."""
    folder = base / "locks"
    folder.mkdir(mode=0o700)
    link = LinkConfig(host="127.0.0.1", port=502)
    real_flock_within = hplock.flock_within
    second: list[HeatPumpLock] = []

    def flock_after_a_swap(fd: int, wait_s: float) -> bool:
        if not second:  # the first daemon, between its open and its flock
            lock_path(link, folder).unlink()
            second.append(HeatPumpLock(link, "/srv/second", directory=folder))
            second[0].acquire()
        return real_flock_within(fd, wait_s)

    monkeypatch.setattr(hplock, "flock_within", flock_after_a_swap)
    try:
        with pytest.raises(DaemonRunning) as refused:
            HeatPumpLock(link, "/srv/first", directory=folder).acquire(wait_s=0.2)
        assert "state_dir /srv/second" in str(refused.value)
    finally:
        for held in second:
            held.release()


def test_only_root_makes_the_machines_lock_directory(base, monkeypatch):
    """After a reboot without the tmpfiles line, a user's impctl does not make the machine's
    lock directory (it would be theirs to fake); root's makes it, root's own, 0755."""
    folder = run_lock_dir(base) / "impctl"
    monkeypatch.setattr(hplock, "DEFAULT_LOCK_DIR", str(folder))  # /run/lock/impctl here
    monkeypatch.delenv("IMPCTL_LOCK_DIR")
    link = LinkConfig(host="127.0.0.1", port=502)

    def take() -> str:
        try:
            HeatPumpLock(link, "/home/nobody/impctl").acquire().release()
        except InputError as exc:
            return str(exc)
        return "taken"

    assert as_user(take) == (f"{folder}: missing: root creates the heat-pump lock directory at "
                             "boot from deploy/impctl.tmpfiles (as root: systemd-tmpfiles "
                             "--create impctl.conf), or set IMPCTL_LOCK_DIR to a directory of "
                             "your own")
    assert not os.path.lexists(folder)
    with HeatPumpLock(link, "/var/lib/impctl"):
        st = os.stat(folder)
        assert (st.st_uid, stat.S_IMODE(st.st_mode)) == (0, 0o755)
