"""Helpers for the heat-pump and simulator tests: a real simulator on loopback, a real client.

Everything runs over real loopback sockets; nothing here mocks Modbus. Tests are plain sync
functions that call :func:`run` (no pytest-asyncio).
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
from collections.abc import AsyncIterator, Awaitable, Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TypeVar

from impctl_sim import KronotermSimulator, SimConfig

from impctl.clock import VirtualClock
from impctl.heatpump import (
    HeatPumpClient,
    HeatPumpConfig,
    LinkConfig,
    WriteBudget,
    WritePolicy,
)

T = TypeVar("T")

#: Simulated start of every test: a January evening.
EPOCH = datetime(2026, 1, 12, 20, 0, tzinfo=UTC)


def run(coro: Awaitable[T], timeout_s: float = 30.0) -> T:
    """Run one test coroutine, failing (not hanging) after ``timeout_s``."""
    return asyncio.run(asyncio.wait_for(coro, timeout_s))


def clock(factor: float = 600.0, wall: Callable[[], float] | None = None) -> VirtualClock:
    """A clock starting at :data:`EPOCH` now, ``factor`` times faster than real time."""
    if wall is None:
        return VirtualClock(EPOCH, factor)
    return VirtualClock(EPOCH, factor, wall=wall)


def link_config(port: int, **overrides: Any) -> LinkConfig:
    """A TCP link with test-sized timeouts (fast failures, few retries)."""
    base: dict[str, Any] = dict(host="127.0.0.1", port=port, timeout_s=0.5, retries=0,
                                attempts=2, retry_delay_s=0.02, connect_backoff_s=(0.05, 0.2),
                                drain_s=0.02)
    base.update(overrides)
    return LinkConfig(**base)


def hp_config(port: int, *, writes: WritePolicy | None = None, **kwargs: Any) -> HeatPumpConfig:
    """Client configuration for a simulator on ``port``; link overrides go in ``link=``."""
    link = kwargs.pop("link", None) or link_config(port)
    return HeatPumpConfig(link=link, writes=writes or WritePolicy(verify_delay_s=0.01),
                          **kwargs)


@contextlib.asynccontextmanager
async def simulator(config: SimConfig | None = None, **start: Any
                    ) -> AsyncIterator[KronotermSimulator]:
    """A started simulator on 127.0.0.1 (free port unless ``port=`` is given)."""
    config = config or SimConfig(clock=clock())
    sim = KronotermSimulator(config)
    await sim.start(**start)
    try:
        yield sim
    finally:
        await sim.stop()


@contextlib.asynccontextmanager
async def client(sim: KronotermSimulator, *, budget: WriteBudget | None = None,
                 **kwargs: Any) -> AsyncIterator[HeatPumpClient]:
    """A connected client on the simulator's port, sharing the simulator's clock."""
    hp = HeatPumpClient(hp_config(sim.port, **kwargs), clock=sim.clock, budget=budget)
    await hp.connect(max_wait_s=5.0)
    try:
        yield hp
    finally:
        hp.close()


def budget(tmp_path: Path, daily: int = 12) -> WriteBudget:
    """A fresh write budget in the test's temporary directory."""
    return WriteBudget(tmp_path / "writes.sqlite", daily)


def free_port() -> int:
    """A loopback port that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def raw_exchange(port: int, adu: bytes, *, read_s: float = 0.5) -> bytes:
    """Send one raw ADU over a fresh TCP connection and return whatever comes back in time."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(adu)
        await writer.drain()
        data = b""
        with contextlib.suppress(TimeoutError):
            while len(data) < 7 or len(data) < 6 + struct.unpack(">H", data[4:6])[0]:
                chunk = await asyncio.wait_for(reader.read(512), read_s)
                if not chunk:
                    break
                data += chunk
        return data
    finally:
        writer.close()


def umodbus_call(port: int, adu: bytes, timeout_s: float = 2.0) -> Any:
    """Send a uModbus-built TCP request ADU with uModbus' own client code; return its parse."""
    from umodbus.client import tcp

    with socket.create_connection(("127.0.0.1", port), timeout=timeout_s) as sock:
        return tcp.send_message(adu, sock)


async def in_thread(fn: Callable[..., T], *args: Any) -> T:
    """Run blocking (e.g. uModbus socket) code without blocking the simulator's loop."""
    return await asyncio.to_thread(fn, *args)


async def wait_for(predicate: Callable[[], bool], timeout_s: float = 10.0) -> None:
    """Wait until ``predicate()`` holds (simulated time passing), failing after ``timeout_s``."""
    async with asyncio.timeout(timeout_s):
        while not predicate():
            await asyncio.sleep(0.01)
