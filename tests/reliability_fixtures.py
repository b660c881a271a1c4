"""Helpers of the reliability suite (``tests/test_reliability_*.py``, ``bench/crash.py``,
``bench/soak.py``): a Modbus TCP proxy with switchable faults, an in-process daemon rig, log
capture, and what the kernel says about a process (file descriptors, memory, sockets).

Nothing is mocked. The proxy is a real asyncio TCP server between impctl and the simulator;
the daemon is the real :class:`~impctl.daemon.service.Daemon`; the simulator is the real
``impctl_sim`` Modbus server; the store is a real SQLite file.

The proxy's faults (``ModbusProxy.mode``)
-----------------------------------------
``pass``          forward both ways, byte for byte
``down``          the gateway is gone: every connection is accepted and closed at once (the
                  attempts are counted, so a busy loop shows), open ones are cut
``drop-read``     an FC 03 request is forwarded, its answer is cut in half and the connection
                  closed — the connection dies in the middle of the read
``drop-write``    an FC 06 request is forwarded (the write lands) and the connection closed
                  before the answer — the answer of a write is lost
``lose-write``    an FC 06 request is swallowed and the connection closed — the write is lost
``busy-write``    an FC 06 request is answered with Modbus exception 6 (busy) by the proxy,
                  the device never sees it; reads pass
``stall``         the gateway freezes for ``stall_s`` wall-clock seconds from the switch: no
                  answer leaves it meanwhile, then everything held back is delivered late (the
                  client has long timed out; late answers must not be taken for new ones)
``garbage``       random bytes before every answer (a noisy RS-485 gateway)
``slow-write``    every FC 06 request is held ``write_delay_s`` wall-clock seconds before it is
                  forwarded — even when its sender has died meanwhile (a slow gateway: the
                  write lands after the master is gone)
``down-after-write``  the next FC 06 request is forwarded (the write lands), then the mode
                  becomes ``down``: the link drops before the write's answer and read-back
"""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import logging
import os
import random
import re
import struct
import time
from collections import Counter
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any
from zoneinfo import ZoneInfo

from daemon_fixtures import HEAVY_HOUSE, OWNER_SETPOINT_C, daemon_mapping
from impctl_sim import KronotermSimulator, SimConfig, constant_weather
from sim_fixtures import wait_for

from impctl.clock import VirtualClock
from impctl.clock import loop as vtime
from impctl.config import config_from_mapping
from impctl.daemon.service import Daemon
from impctl.model import HouseParameters

TZ = ZoneInfo("Europe/Ljubljana")
#: 03:00 local: manual nights are far from the scheduled 22:00 one and from the UTC day's end.
MORNING = datetime(2026, 1, 12, 3, 0, tzinfo=TZ)
#: Test-sized link timings (``[heatpump]``, wall clock): a failed try costs a fraction of a
#: second.
QUICK_LINK = {"timeout_s": 0.2, "attempts": 2, "retry_delay_s": 0.02,
              "connect_backoff_s": [0.05, 0.2]}
MODES = ("pass", "down", "drop-read", "drop-write", "lose-write", "busy-write", "stall",
         "garbage", "slow-write", "down-after-write")
#: Which rig (``daemon_rig(name=…)``) the running code belongs to: every task the daemon
#: creates inherits it, so several rigs can share one event loop and keep their logs apart.
RIG: contextvars.ContextVar[str | None] = contextvars.ContextVar("RIG", default=None)


# -- the proxy -------------------------------------------------------------------------------------
@dataclass
class ProxyStats:
    """What crossed the proxy."""

    accepted: int = 0                                   # client connections accepted
    refused: int = 0                                    # … closed at once ("down")
    requests: Counter = field(default_factory=Counter)  # function code → client requests
    cut: Counter = field(default_factory=Counter)       # mode → connections it cut
    garbage_bytes: int = 0
    #: Every request in order: (function code, PDU address, count or written word).
    trace: list[tuple[int, int, int]] = field(default_factory=list)


class ModbusProxy:
    """A TCP proxy on 127.0.0.1 in front of a Modbus TCP server, with switchable faults.

    Parameters
    ----------
    upstream_port : the server's loopback port
    seed : seed of the garbage bytes
    """

    def __init__(self, upstream_port: int, *, seed: int = 0) -> None:
        self.upstream_port = upstream_port
        self.mode = "pass"
        self.stall_s = 5.0
        self.write_delay_s = 0.2
        self.held_writes = 0  # FC 06 requests being held ("slow-write")
        self.stats = ProxyStats()
        self.port = 0
        self._rng = random.Random(seed)
        self._stall_until = 0.0
        self._server: asyncio.base_events.Server | None = None
        self._conns: set[tuple[asyncio.StreamWriter, asyncio.StreamWriter]] = set()
        self._tasks: set[asyncio.Task] = set()

    async def start(self) -> int:
        """Listen on a free loopback port; return it."""
        self._server = await asyncio.start_server(self._accept, "127.0.0.1", 0)
        self.port = self._server.sockets[0].getsockname()[1]
        return self.port

    async def stop(self) -> None:
        """Close the listener and every connection."""
        if self._server is not None:
            self._server.close()
            self.cut_all()
            for task in list(self._tasks):
                task.cancel()
            await asyncio.gather(*self._tasks, return_exceptions=True)
            await self._server.wait_closed()
            self._server = None

    def set(self, mode: str, **options: Any) -> None:
        """Switch the fault (``stall_s=`` for ``stall``); ``down`` also cuts open connections."""
        if mode not in MODES:
            raise ValueError(f"unknown proxy mode {mode!r}")
        for key, value in options.items():
            setattr(self, key, value)
        self.mode = mode
        if mode == "down":
            self.cut_all()
        if mode == "stall":
            self._stall_until = asyncio.get_running_loop().time() + self.stall_s

    def cut_all(self) -> None:
        """Close every open connection (both sides)."""
        for client_w, server_w in list(self._conns):
            client_w.close()
            server_w.close()

    async def _accept(self, client_r: asyncio.StreamReader,
                      client_w: asyncio.StreamWriter) -> None:
        self._tasks.add(asyncio.current_task())
        try:
            if self.mode == "down":
                self.stats.refused += 1
                client_w.close()
                return
            self.stats.accepted += 1
            try:
                server_r, server_w = await asyncio.open_connection("127.0.0.1",
                                                                   self.upstream_port)
            except OSError:
                client_w.close()
                return
            pair = (client_w, server_w)
            self._conns.add(pair)
            state = {"cut_answer": False, "drop_answer": False}
            up = asyncio.create_task(self._upstream(client_r, client_w, server_w, state))
            down = asyncio.create_task(self._downstream(server_r, client_w, server_w, state))
            try:
                await asyncio.wait({up, down}, return_when=asyncio.FIRST_COMPLETED)
            except asyncio.CancelledError:  # the proxy stops
                pass
            finally:
                for task in (up, down):
                    task.cancel()
                await asyncio.gather(up, down, return_exceptions=True)
                client_w.close()
                server_w.close()
                self._conns.discard(pair)
        finally:
            self._tasks.discard(asyncio.current_task())

    async def _upstream(self, client_r, client_w, server_w, state) -> None:
        """Client → server, one MBAP frame at a time (the client never sends stray bytes)."""
        while True:
            header = await client_r.readexactly(7)
            length = struct.unpack(">H", header[4:6])[0]
            body = await client_r.readexactly(max(length - 1, 0))
            fc = body[0] if body else 0
            self.stats.requests[fc] += 1
            if len(body) >= 5:
                self.stats.trace.append((fc, *struct.unpack(">HH", body[1:5])))
            mode = self.mode
            if mode == "down":
                return
            if mode == "lose-write" and fc == 6:
                self.stats.cut[mode] += 1
                return
            if mode == "busy-write" and fc == 6:  # MBAP length 3: unit, FC | 0x80, code
                client_w.write(header[:4] + struct.pack(">H", 3) + header[6:7] + bytes([0x86, 6]))
                await client_w.drain()
                continue
            if mode == "drop-write" and fc == 6:
                state["drop_answer"] = True
            if mode == "slow-write" and fc == 6:
                self.held_writes += 1
                try:
                    await asyncio.sleep(self.write_delay_s)
                finally:
                    self.held_writes -= 1
            server_w.write(header + body)
            await server_w.drain()
            if mode == "drop-write" and fc == 6:
                await asyncio.sleep(0.02)  # let the server take the write, then hang up
                self.stats.cut[mode] += 1
                return
            if mode == "drop-read" and fc == 3:
                state["cut_answer"] = True
            if mode == "down-after-write" and fc == 6:
                # the heat pump takes the write, then the gateway's link drops (until set back)
                await asyncio.sleep(0.02)
                self.stats.cut[mode] += 1
                self.set("down")
                return

    async def _downstream(self, server_r, client_w, server_w, state) -> None:
        """Server → client, in chunks as they come (a greeting may precede any answer)."""
        while True:
            chunk = await server_r.read(4096)
            if not chunk:
                return
            mode = self.mode
            if mode == "down":
                return
            if mode == "stall":
                held = self._stall_until - asyncio.get_running_loop().time()
                if held > 0:
                    await asyncio.sleep(held)
            if state["drop_answer"]:
                return
            if state["cut_answer"]:
                client_w.write(chunk[: max(1, len(chunk) // 2)])
                await client_w.drain()
                self.stats.cut["drop-read"] += 1
                return
            if mode == "garbage":
                junk = bytes(self._rng.randrange(256) for _ in range(self._rng.randint(1, 12)))
                self.stats.garbage_bytes += len(junk)
                chunk = junk + chunk
            if client_w.is_closing():
                return
            client_w.write(chunk)
            await client_w.drain()


class ProxyThread:
    """A :class:`ModbusProxy` on its own event loop in a background thread (for tests whose
    daemon and simulator are subprocesses)."""

    def __init__(self, upstream_port: int, mode: str = "pass", **options: Any) -> None:
        import threading

        self.loop = asyncio.new_event_loop()
        self.proxy = ModbusProxy(upstream_port)
        self._thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self._thread.start()
        self.port = self._call(self.proxy.start())
        self.loop.call_soon_threadsafe(lambda: self.proxy.set(mode, **options))

    def _call(self, coro):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(10)

    def close(self) -> None:
        self._call(self.proxy.stop())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(10)
        self.loop.close()


# -- log capture -----------------------------------------------------------------------------------
class LogLines(logging.Handler):
    """Collects the records of the ``impctl`` loggers (at INFO and above) with the time on
    the virtual clock; with ``rig``, only those emitted by that rig's tasks."""

    def __init__(self, clock: VirtualClock | None = None, rig: str | None = None) -> None:
        super().__init__(logging.INFO)
        self.clock = clock
        self.rig = rig
        self.records: list[tuple[datetime | None, logging.LogRecord]] = []

    def emit(self, record: logging.LogRecord) -> None:
        if self.rig is None or RIG.get() == self.rig:
            self.records.append((self.clock.now() if self.clock else None, record))

    def mark(self) -> int:
        """An index to count lines from."""
        return len(self.records)

    def lines(self, since: int = 0, level: int = logging.WARNING,
              exclude: tuple[str, ...] = ()) -> list[str]:
        """Messages at ``level`` or above since ``since``, minus those matching ``exclude``
        (regular expressions)."""
        out = []
        for _, rec in self.records[since:]:
            msg = rec.getMessage()
            if rec.levelno >= level and not any(re.search(p, msg) for p in exclude):
                out.append(f"{rec.levelname} {rec.name}: {msg}")
        return out


_LEVEL_BEFORE: list[tuple[int, int]] = []  # impctl's and pymodbus' levels before capturing


@contextlib.contextmanager
def captured_logs(clock: VirtualClock | None = None, rig: str | None = None
                  ) -> Iterator[LogLines]:
    """Capture the ``impctl`` loggers at INFO (what the journal shows with log_level info)."""
    handler = LogLines(clock, rig)
    logger, pymodbus = logging.getLogger("impctl"), logging.getLogger("pymodbus")
    if not any(isinstance(h, LogLines) for h in logger.handlers):
        _LEVEL_BEFORE.append((logger.level, pymodbus.level))
    logger.setLevel(logging.INFO)
    pymodbus.setLevel(logging.CRITICAL)  # as `impctl daemon` does
    logger.addHandler(handler)
    try:
        yield handler
    finally:
        logger.removeHandler(handler)
        if not any(isinstance(h, LogLines) for h in logger.handlers):  # the last one out
            level, pymodbus_level = _LEVEL_BEFORE.pop()
            logger.setLevel(level)
            pymodbus.setLevel(pymodbus_level)


#: The audit lines of the write path: one per write, not per poll, so they are no incident spam.
WRITE_AUDIT = (r" and verified \(\d+/\d+ today\)$", r"^restored \S+ \(register \d+\) to raw",
               r"^journaled owner's state", r"^heating switched off", r"^owner's settings restored",
               r"^night \d+ (done|aborted|refused)", r"^manual trigger \d+")


# -- the in-process daemon rig ---------------------------------------------------------------------
@dataclass
class DaemonRig:
    """A simulator, a proxy in front of it and a daemon talking through the proxy."""

    sim: KronotermSimulator
    proxy: ModbusProxy
    daemon: Daemon
    task: asyncio.Task
    clock: VirtualClock
    logs: LogLines
    context: contextvars.Context  # the daemon's tasks' (RIG = its name)

    @property
    def store(self):
        return self.daemon.store

    def night(self, night_id: int | None = None):
        nights = self.store.nights()
        if night_id is None:
            return nights[-1] if nights else None
        return self.store.night(night_id)

    def owner_state(self) -> tuple[float, int]:
        """What the simulated heat pump itself runs on: (loop-1 setpoint °C, loop-1 mode)."""
        return self.sim.plant.setpoint_c, self.sim.plant.loop_mode

    async def trigger(self, kind: str, setpoint_c: float = 21.0) -> int:
        """Queue a manual night (as ``impctl trigger --now --force``); return its night id once it
        exists."""
        before = len(self.store.nights())
        self.store.add_request(kind, setpoint_c, "now", forced=True)
        # Taken at once, as the daemon's 1 s trigger-poll job would (APScheduler times its
        # jobs on the wall clock, not on the loop's, possibly virtual, time), in the rig's
        # context so that the night's log lines are this rig's.
        await asyncio.create_task(self.daemon._poll_requests(), context=self.context)
        await wait_for(lambda: len(self.store.nights()) > before, 20)
        return self.store.nights()[-1].id

    async def until(self, predicate: Callable[[], Any], timeout_s: float = 20.0) -> None:
        """Wait for ``predicate`` while checking that the daemon stays up."""
        def check() -> bool:
            if self.task.done():
                raise AssertionError(f"the daemon stopped: {self.task!r}")
            return bool(predicate())
        await wait_for(check, timeout_s)

    async def sim_minutes(self, minutes: float, timeout_s: float = 30.0) -> None:
        """Let ``minutes`` of simulated time pass."""
        end = self.clock.now() + timedelta(minutes=minutes)
        await self.until(lambda: self.clock.now() >= end, timeout_s)

    def switched_off(self, night_id: int) -> bool:
        """Loop 1 is off on the heat pump and a committed sample shows it."""
        return self.sim.plant.loop_mode == 0 and any(
            s.loop_mode == 0 for s in self.store.samples(night_id))

    def finished(self, night_id: int) -> bool:
        """The night is assessed and nothing is left to restore."""
        night = self.store.night(night_id)
        return night.valid is not None and not self.store.journal_pending()


def loop_wall() -> Callable[[], float]:
    """POSIX seconds that advance with the running loop's clock: the wall time on a standard
    loop; on a :class:`~impctl.clock.loop.VirtualTimeLoop` the simulated clock then follows the
    loop's virtual time, so however slow the machine, computation takes no simulated time."""
    loop = asyncio.get_running_loop()
    offset = time.time() - loop.time()
    return lambda: loop.time() + offset


@contextlib.asynccontextmanager
async def daemon_rig(tmp_path: Path, *, speed: float, house: HouseParameters = HEAVY_HOUSE,
                     t_out_c: float = 0.0, epoch: datetime = MORNING,
                     heatpump: dict | None = None, night: dict | None = None,
                     sim_faults: str | None = None, name: str = "rig",
                     record: dict | None = None, campaign: dict | None = None,
                     daemon_clock: Callable[[VirtualClock], VirtualClock] | None = None
                     ) -> AsyncIterator[DaemonRig]:
    """Simulator → proxy → in-process daemon, one event loop, one accelerated clock (on the
    loop's time: run it with :func:`run_virtual` to make it independent of the machine's load).

    The night window of a manual (``--now``) night lasts ``night['window']``; the default
    here is one hour after a 6-minute preheat. Several rigs may run in one event loop; give
    each its own ``name`` (its logs are kept apart by the :data:`RIG` context variable).
    ``record`` is merged into ``[record]``; ``daemon_clock(house_clock)`` gives the daemon a
    clock of its own (a wall clock that steps), the simulated house keeping the unstepped one.
    """
    from impctl_sim import parse_faults

    clock = VirtualClock(epoch, speed, wall=loop_wall())
    cfg = SimConfig(clock=clock, house=house, weather=constant_weather(t_out_c),
                    setpoint_c=OWNER_SETPOINT_C,
                    faults=parse_faults(sim_faults) if sim_faults else parse_faults("none"))
    sim = KronotermSimulator(cfg)
    await sim.start()
    proxy = ModbusProxy(sim.port)
    await proxy.start()
    with captured_logs(clock, name) as logs:
        mapping = daemon_mapping(
            tmp_path / "state", proxy.port, clock, heatpump=heatpump or {},
            night={"window": "22:00-23:00", "preheat_h": 0.1, "sample_interval_s": 60,
                   **(night or {})}, **({"record": record} if record else {}),
            **({"campaign": campaign} if campaign else {}))
        daemon = Daemon(config_from_mapping(mapping),
                        clock=clock if daemon_clock is None else daemon_clock(clock))
        context = contextvars.copy_context()
        context.run(RIG.set, name)
        task = asyncio.create_task(daemon.run(), name=f"impctl daemon {name}",
                                   context=context)
        try:
            await wait_for(lambda: daemon.scheduler is not None or task.done(), 20)
            assert not task.done(), task
            yield DaemonRig(sim, proxy, daemon, task, clock, logs, context)
        finally:
            daemon.stop.set()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(task, 30)
            await proxy.stop()
            await sim.stop()


# -- what the kernel says about a process ----------------------------------------------------------
def open_fds(pid: int | str = "self") -> int:
    """Number of open file descriptors of ``pid``."""
    return len(os.listdir(f"/proc/{pid}/fd"))


def rss_kb(pid: int | str = "self") -> int:
    """Resident set size of ``pid`` [kB] (``VmRSS``)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError(f"no VmRSS for {pid}")


def cpu_s(pid: int | str = "self") -> float:
    """User + system CPU time of ``pid`` [s]."""
    fields_ = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields_[11]) + int(fields_[12])) / os.sysconf("SC_CLK_TCK")


def socket_inodes(pid: int | str) -> set[int]:
    """Inodes of the sockets ``pid`` holds open."""
    out = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        with contextlib.suppress(OSError):
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
            if target.startswith("socket:["):
                out.add(int(target[8:-1]))
    return out


def listening_sockets(pid: int | str) -> list[str]:
    """The listening (TCP LISTEN, bound UDP, accepting AF_UNIX) sockets among ``pid``'s open
    file descriptors, read from ``/proc/PID/net/*`` (the process's network namespace)."""
    inodes = socket_inodes(pid)
    found = []
    for proto in ("tcp", "tcp6", "udp", "udp6"):
        path = Path(f"/proc/{pid}/net/{proto}")
        if not path.exists():
            continue
        for line in path.read_text().splitlines()[1:]:
            parts = line.split()
            local, state, inode = parts[1], parts[3], int(parts[9])
            if inode not in inodes:
                continue
            # TCP state 0A = LISTEN; a UDP socket bound to a port receives from anyone.
            if (proto.startswith("tcp") and state == "0A") or (
                    proto.startswith("udp") and not local.endswith(":0000")):
                found.append(f"{proto} {local}")
    unix = Path(f"/proc/{pid}/net/unix")
    for line in unix.read_text().splitlines()[1:]:
        parts = line.split()
        flags, inode = int(parts[3], 16), int(parts[6])
        if inode in inodes and flags & 0x10000:  # __SO_ACCEPTCON: a listening AF_UNIX socket
            found.append(f"unix {parts[7] if len(parts) > 7 else '(unnamed)'}")
    return found


# -- crash anywhere: SIGKILL the daemon subprocess, restart, check --------------------------------
#: Night states of a night that was running (the orphan sweep marks them interrupted).
RUNNING = ("planned", "preparing", "active", "restoring")


@dataclass
class KillPoint:
    """One SIGKILL of ``impctl daemon`` and what the restart found."""

    n: int
    kind: str             # night kind, or "recovery" (killed while recovering from the last)
    after_s: float        # wall seconds after the night was created (after the restart)
    phase: str            # what the store and the heat pump showed at the kill
    heat_pump: tuple[int, int]  # (2187 raw, 2042) at the kill
    pending: int          # journal entries pending at the kill
    samples: int          # samples committed at the kill (all nights)
    recovered_s: float = 0.0  # wall seconds from the restart to the owner's state verified


def _ro(db: Path):
    import sqlite3

    return contextlib.closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=10))


def db_facts(db: Path) -> dict[str, Any]:
    """What a read-only connection sees: integrity, nights, pending journal, sample keys."""

    empty = {"integrity": "ok", "nights": {}, "pending": [], "journal": [], "samples": set()}
    if not db.exists():
        return empty
    with _ro(db) as con:
        if con.execute("PRAGMA user_version").fetchone()[0] == 0:  # not migrated yet
            return {**empty, "integrity": con.execute("PRAGMA integrity_check").fetchone()[0]}
        return {
            "integrity": con.execute("PRAGMA integrity_check").fetchone()[0],
            "nights": {r[0]: (r[1], r[2], r[3]) for r in con.execute(
                "SELECT id, state, valid, reasons FROM nights")},
            "pending": con.execute("SELECT register, raw_value FROM journal"
                                   " WHERE restored IS NULL ORDER BY id").fetchall(),
            "journal": con.execute("SELECT register, raw_value FROM journal").fetchall(),
            "samples": {tuple(r) for r in con.execute(
                "SELECT night_id, ts, t_air_c FROM samples")},
        }


def _phase(facts: dict, heat_pump: tuple[int, int], owner: tuple[int, int]) -> str:
    running = [(i, s) for i, (s, _, _) in facts["nights"].items() if s in RUNNING]
    if not running:
        return "idle" if heat_pump == owner else "recovering: night swept, restore pending"
    state = running[-1][1]
    if state == "restoring":
        return "restoring at the night's end"
    if heat_pump[1] == 0:
        return "heating off (constrained)"
    if heat_pump != owner:
        return "setpoint written (preheat / normal night)"
    return "journaled, nothing written yet" if facts["pending"] else "preparing"


def crash_run(tmp_path: Path, points: int, seed: int, *, speed: float = 7200.0,
              recovery_share: float = 0.2, slow_writes_s: float = 0.0,
              log: Callable[[str], None] | None = None) -> list[KillPoint]:
    """SIGKILL ``impctl daemon`` at ``points`` random instants and restart it each time.

    One ``impctl-sim`` subprocess and one state directory for the whole run. Each point either
    queues a constrained or normal night (``impctl trigger --now`` through the store) and
    kills the daemon at a uniformly random instant of it — from the preheat to the restore at
    its end — or, with probability ``recovery_share``, kills the freshly restarted daemon
    while it is still recovering from the previous kill. With ``slow_writes_s`` the daemon
    talks through a :class:`ModbusProxy` that holds every write that long (``slow-write``), so
    many kills catch a write in flight — one that lands after the daemon is dead. After every
    kill, and again after every restart, it asserts:

    * SQLite ``integrity_check`` is ok (store and write-budget files);
    * if the heat pump is not in the owner's state, the journal holds the owner's values;
    * after the restart: the owner's setpoint and mode are back on the heat pump (read with
      an independent pymodbus client) and the journal confirms them (restored = read back);
    * every sample committed before the kill (seen by another connection before it, and the
      file's content after it) is still there;
    * every night that was running is ``interrupted`` and not valid;
    * every journal entry ever written holds the owner's values, never impctl's own.
    """
    from daemon_fixtures import (
        OWNER_MODE,
        OWNER_SETPOINT_RAW,
        daemon_mapping,
        owner_state,
        sim_process,
        start_daemon,
        stop_process,
        wait_until,
        write_config,
    )

    say = log or (lambda text: None)
    owner = (OWNER_SETPOINT_RAW, OWNER_MODE)
    rng = random.Random(seed)
    kills: list[KillPoint] = []
    # Preheat 15 min + a 2 h window: 1.1 s of wall time at 7200×.
    night_wall_s = (0.25 + 2.0) * 3600 / speed
    with contextlib.ExitStack() as stack:
        sim = stack.enter_context(sim_process(tmp_path, MORNING, speed))
        proxy = None
        if slow_writes_s:
            proxy = ProxyThread(sim.port, "slow-write", write_delay_s=slow_writes_s)
            stack.callback(proxy.close)
        state = tmp_path / "state"
        db, budget_db = state / "impctl.db", state / "writes.db"
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            state, proxy.port if proxy else sim.port, sim.clock,
            night={"window": "22:00-00:00", "preheat_h": 0.25, "sample_interval_s": 120}))
        starts = 0

        def start():
            nonlocal starts
            starts += 1
            return start_daemon(config, db, tmp_path / f"daemon{starts}.log"), time.monotonic()

        def recovered(proc, since: float, was_running: set[int]) -> float:
            def done():
                if owner_state(sim.port) != owner:
                    return False
                facts = db_facts(db)
                return not facts["pending"] and all(
                    facts["nights"][i][0] == "interrupted" for i in was_running)
            wait_until(done, CRASH_GUARD_S, "the restart to restore the owner's settings",
                       proc=proc)
            return time.monotonic() - since

        daemon, started = start()
        last_facts = db_facts(db)
        was_running: set[int] = set()
        for n in range(points):
            recovery = n > 0 and rng.random() < recovery_share
            if recovery:
                kind, t0 = "recovery", started
                time.sleep(rng.uniform(0.0, 0.5))
            else:
                if kills:
                    kills[-1].recovered_s = recovered(daemon.proc, started, was_running)
                _check_after_restart(db_facts(db), last_facts, was_running, owner)
                kind = rng.choice(("constrained", "normal"))
                nights_before = len(db_facts(db)["nights"])
                from impctl.store import Store

                with Store(db) as store:
                    store.add_request(kind, 21.0 if kind == "constrained" else 22.0, "now",
                                      forced=True)
                wait_until(lambda b=nights_before: len(db_facts(db)["nights"]) > b, CRASH_GUARD_S,
                           "the daemon to take the night", interval_s=0.01, proc=daemon.proc)
                t0 = time.monotonic()
                # Half uniform over the whole night, a quarter around its start (journal,
                # preheat write, switch-off) and a quarter around its end (last samples,
                # restore), where the short phases are.
                where = rng.random()
                if where < 0.5:
                    delay = rng.uniform(0.0, night_wall_s + 0.2)
                elif where < 0.75:
                    delay = rng.uniform(0.0, 0.25)
                else:
                    delay = rng.uniform(night_wall_s - 0.15, night_wall_s + 0.2)
                time.sleep(delay)
            seen = db_facts(db)["samples"]  # committed, as another reader sees them
            in_flight = proxy is not None and proxy.proxy.held_writes > 0
            daemon.proc.kill()
            daemon.proc.wait(10)
            after_s = time.monotonic() - t0
            if in_flight:  # let the held write land on the heat pump: the master is dead
                time.sleep(slow_writes_s + 0.05)
            facts = db_facts(db)
            heat_pump = owner_state(sim.port)
            assert facts["integrity"] == "ok", (n, facts["integrity"])
            assert _integrity(budget_db) == "ok", n
            assert seen <= facts["samples"], (n, "a sample seen before the kill is gone")
            # A register not at the owner's value has a pending journal entry holding it.
            pending = dict(facts["pending"])
            for register, now_raw, owner_raw in zip(("loop1_setpoint", "loop1_mode"), heat_pump,
                                                    owner, strict=True):
                if now_raw != owner_raw:
                    assert pending.get(register) == owner_raw, (n, heat_pump, facts["pending"])
            was_running = {i for i, (s, _, _) in facts["nights"].items() if s in RUNNING}
            phase = _phase(facts, heat_pump, owner)
            if in_flight:
                phase = f"write in flight, landed after the kill ({phase})"
            kills.append(KillPoint(n, kind, after_s, phase, heat_pump, len(facts["pending"]),
                                   len(facts["samples"])))
            say(f"kill {n:3d} {kind:<11} after {after_s:5.2f} s: {kills[-1].phase}")
            last_facts = facts
            daemon, started = start()
        kills[-1].recovered_s = recovered(daemon.proc, started, was_running)
        _check_after_restart(db_facts(db), last_facts, was_running, owner)
        wait_until(lambda: "next night job at" in daemon.output(), CRASH_GUARD_S,
                   "the daemon to be up", proc=daemon.proc)
        assert stop_process(daemon.proc) == 0  # and a clean SIGTERM still exits 0
    return kills


#: Guard [s of wall time] of the crash run's waits on a restarted daemon (imports, restore):
#: generous, so a loaded machine slows the run down instead of failing it.
CRASH_GUARD_S = 120.0


def _integrity(path: Path) -> str:
    if not path.exists():
        return "ok"
    with _ro(path) as con:
        return con.execute("PRAGMA integrity_check").fetchone()[0]


def _check_after_restart(facts: dict, at_kill: dict, was_running: set[int],
                         owner: tuple[int, int]) -> None:
    assert facts["integrity"] == "ok", facts["integrity"]
    assert at_kill["samples"] <= facts["samples"], "samples committed before the kill are gone"
    for night_id in was_running:
        state, valid, reasons = facts["nights"][night_id]
        assert (state, valid) == ("interrupted", 0), (night_id, state, valid)
        assert "interrupted: impctl stopped during the night" in reasons
    owners = {"loop1_setpoint": owner[0], "loop1_mode": owner[1]}
    assert all(owners[reg] == raw for reg, raw in facts["journal"]), facts["journal"]


# -- virtual time: an event loop whose clock jumps to the next timer when nothing else is due ------
def run_virtual(coro, timeout_s: float = 86400.0):
    """Run ``coro`` on a fresh :class:`~impctl.clock.loop.VirtualTimeLoop` (``timeout_s`` in virtual
    seconds: a guard). Executor jobs and subprocesses (the daemon's fits) hold its clock."""
    return vtime.run(asyncio.wait_for(coro, timeout_s))


# -- soak: many scheduled nights at high speed -----------------------------------------------------
@dataclass
class SoakNight:
    """One scheduled night of a soak run and the daemon's state after it."""

    night_id: int
    kind: str
    state: str
    valid: bool
    window_start: datetime      # local
    late_min: float             # started − scheduled preheat start [simulated min]
    reasons: tuple[str, ...]
    samples: int
    rss_kb: int
    fds: int
    cpu_s: float


def soak_run(tmp_path: Path, nights: int, *, speed: float, sample_interval_s: float = 300.0,
             log: Callable[[str], None] | None = None, guard_s: float = 900.0
             ) -> list[SoakNight]:
    """The daemon (:class:`~impctl.daemon.service.Daemon`, with ``impctl daemon``'s logging)
    runs a campaign of ``nights`` scheduled nights, one per simulated day (22:00–05:00 local,
    preheat from 20:00), against the simulator (heavy house, 0 °C, ideal plant), both in one
    process on a virtual-time loop (``tests/virtual_daemon.py``): simulated time passes only
    when both wait, so no night is late or short however loaded the machine. After each night
    (assessed, nothing pending) the process records its RSS, open file descriptors and CPU
    time from /proc. ``guard_s``: real seconds before the run counts as hung."""
    import json
    import subprocess
    import sys

    from daemon_fixtures import daemon_mapping, heatpump_section

    say = log or (lambda text: None)
    # Noon local: the first preheat (20:00) is 8 simulated hours away.
    epoch = datetime(2026, 1, 12, 12, 0, tzinfo=TZ)
    constrained = max(1, nights // 3)
    normal = nights - constrained
    state = tmp_path / "state"
    db = state / "impctl.db"
    mapping = daemon_mapping(
        state, 0, VirtualClock(epoch, speed),
        night={"window": "22:00-05:00", "preheat_h": 2.0, "sample_interval_s": sample_interval_s},
        campaign={"enabled": True, "mode": "fixed", "constrained_nights": constrained,
                  "normal_setpoints_c": [21.0, 22.0],
                  "normal_nights_per_setpoint": (normal + 1) // 2, "fit_when_complete": False})
    mapping["heatpump"] = heatpump_section(0)
    mapping["clock"].pop("wall_epoch_s")  # the process's clock is on its loop's time
    spec = tmp_path / "soak.json"
    spec.write_text(json.dumps({"mapping": mapping, "epoch": epoch.isoformat(),
                                "speed": speed, "nights": nights}))
    rows_path, log_path = tmp_path / "rows.jsonl", tmp_path / "daemon.log"
    with log_path.open("w") as err:
        proc = subprocess.run([sys.executable, str(Path(__file__).parent / "virtual_daemon.py"),
                               str(spec), str(rows_path)], stdout=err, stderr=subprocess.STDOUT,
                              timeout=guard_s)
    assert proc.returncode == 0, log_path.read_text()[-3000:]
    out: list[SoakNight] = []
    from impctl.store import Store

    with Store(db) as store:
        for line in rows_path.read_text().splitlines():
            facts = json.loads(line)
            n = store.night(facts["night_id"])
            act = n.window_start - timedelta(hours=2.0)
            row = SoakNight(n.id, n.kind, n.state, bool(n.valid), n.window_start.astimezone(TZ),
                            ((n.started or n.ended) - act).total_seconds() / 60, n.reasons,
                            store.sample_count(n.id), facts["rss_kb"], facts["fds"],
                            facts["cpu_s"])
            out.append(row)
            say(f"night {row.night_id:3d} {row.kind:<11} {row.state:<8} "
                f"valid={row.valid!s:<5} {row.window_start:%Y-%m-%d %H:%M} "
                f"late {row.late_min:5.1f} min, {row.samples} samples, "
                f"RSS {row.rss_kb / 1024:.1f} MB, {row.fds} fds, CPU {row.cpu_s:.1f} s")
    return out[:nights]
