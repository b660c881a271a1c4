"""Simulated time that advances only when everyone waits: an asyncio event loop on virtual time.

:class:`VirtualTimeLoop` is a standard selector event loop whose :meth:`~VirtualTimeLoop.time`
is virtual. Each iteration polls the real sockets without waiting; when nothing is ready and
nothing started from the loop is still working outside it, the loop does not sleep: its time
jumps to the next timer. Computation therefore takes no virtual time and waiting takes no real
time, so a simulator and a controller sharing the loop see the same simulated history however
busy (or slow) the machine is — the approach of trio's autojump clock and of ``looptime``.

Work outside the loop holds the clock (the loop then waits in real time, with its virtual time
standing still) until it has finished and its result is back in the loop:

* jobs started with :meth:`~asyncio.loop.run_in_executor` (also ``asyncio.to_thread``,
  ``getaddrinfo`` and APScheduler's jobs of plain functions), until their future is done;
* subprocesses started with :meth:`~asyncio.loop.subprocess_exec` or ``subprocess_shell``
  (``asyncio.create_subprocess_exec``), until they have exited: a fit in a subprocess takes
  no simulated time (``wait_for_processes=False`` lets the clock run on instead).

A job held so must not itself wait for the loop's time to pass (a thread blocking on a
coroutine that sleeps would wait for ever): it may only wait for I/O the loop serves.

Loopback TCP between two endpoints of the same loop (Modbus client and server) needs no hold:
on Linux the data is in the peer's receive queue when ``send`` returns, so the poll sees it
before any jump. Anything else the loop cannot see — a thread started by hand, another process
talking to this one, a ``time.sleep`` — is not waited for: run such parts on real time.

Why not ``looptime`` (PyPI): it is a pytest plugin whose loop moves its fake time in real-time
steps while executor jobs run (``idle_step``), and it does not wait for subprocesses, so a job
slowed down by a busy CPU would let simulated time pass; here nothing outside the loop may
move the clock.
"""

from __future__ import annotations

import asyncio
import selectors
import time
import weakref
from collections.abc import Awaitable, Callable, Coroutine
from typing import Any, TypeVar

_T = TypeVar("_T")
#: Longest real wait [s] while work outside the loop holds the clock; its completion wakes
#: the loop at once (the loop's self-pipe), this only bounds a missed wake-up.
HOLD_POLL_S = 0.05


class _Selector(selectors.DefaultSelector):
    """The platform selector, with ``select`` deferring to the loop's virtual-time rule."""

    def __init__(self) -> None:
        super().__init__()
        self.decide: Callable[[float | None], list] | None = None

    def select(self, timeout: float | None = None):
        if self.decide is None:
            return super().select(timeout)
        return self.decide(timeout)

    def real_select(self, timeout: float | None) -> list:
        return super().select(timeout)


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """An event loop whose time jumps to the next timer whenever every party waits.

    Parameters
    ----------
    start_s : float, default 1e6
        The loop's time at creation [virtual s]: fixed, so that runs round alike; not 0 (a
        time that reads as false), and small enough for asyncio's 1 ns timer resolution.
    wait_for_processes : bool, default True
        Hold the clock while a subprocess started from the loop runs.

    Attributes
    ----------
    jumps : int
        How often the time jumped to a timer.
    held_s : float
        Real seconds spent waiting for work outside the loop (executor jobs, subprocesses).
    """

    def __init__(self, *, start_s: float = 1e6, wait_for_processes: bool = True) -> None:
        self._vsel = _Selector()
        super().__init__(self._vsel)
        self._now = float(start_s)
        self._jobs: set[asyncio.Future] = set()
        self._processes: weakref.WeakSet = weakref.WeakSet()
        self._starting = 0  # subprocesses being started (no transport yet)
        self.wait_for_processes = wait_for_processes
        self.jumps = 0
        self.held_s = 0.0
        self._vsel.decide = self._select

    def time(self) -> float:
        return self._now

    # -- work outside the loop ---------------------------------------------------------------
    def run_in_executor(self, executor, func, *args):  # noqa: D102 - asyncio's
        future = super().run_in_executor(executor, func, *args)
        self._jobs.add(future)
        return future

    async def subprocess_exec(self, protocol_factory, *args, **kwargs):  # noqa: D102
        return await self._tracked(super().subprocess_exec(protocol_factory, *args, **kwargs))

    async def subprocess_shell(self, protocol_factory, cmd, **kwargs):  # noqa: D102
        return await self._tracked(super().subprocess_shell(protocol_factory, cmd, **kwargs))

    async def _tracked(self, starting: Awaitable[tuple[Any, Any]]) -> tuple[Any, Any]:
        self._starting += 1
        try:
            transport, protocol = await starting
        finally:
            self._starting -= 1
        self._processes.add(transport)
        return transport, protocol

    def outside_work(self) -> bool:
        """Whether work started from the loop runs outside it (the clock is held)."""
        if self._jobs:
            self._jobs = {f for f in self._jobs if not f.done()}
        if self._jobs:
            return True
        if not self.wait_for_processes:
            return False
        return self._starting > 0 or any(
            t.get_returncode() is None for t in list(self._processes))

    # -- the clock ----------------------------------------------------------------------------
    def _select(self, timeout: float | None) -> list:
        ready = self._vsel.real_select(0)
        if ready or (timeout is not None and timeout <= 0):
            return ready
        if self.outside_work():
            t0 = time.monotonic()
            ready = self._vsel.real_select(HOLD_POLL_S)
            self.held_s += time.monotonic() - t0
            return ready
        if timeout is None:  # no timer at all: only the outside world can wake the loop
            return self._vsel.real_select(None)
        # Exactly to the earliest timer (asyncio's _run_once has dropped cancelled ones from
        # the head of its heap); ``timeout`` is that distance, or asyncio's 24 h cap.
        due = self._scheduled[0]._when if self._scheduled else self._now + timeout
        self._now = max(self._now, min(due, self._now + timeout))
        self.jumps += 1
        return ready


def run(main: Coroutine[Any, Any, _T], *, wait_for_processes: bool = True) -> _T:
    """``asyncio.run(main)`` on a fresh :class:`VirtualTimeLoop`."""
    with asyncio.Runner(loop_factory=lambda: VirtualTimeLoop(
            wait_for_processes=wait_for_processes)) as runner:
        return runner.run(main)


def on_virtual_time(loop: asyncio.AbstractEventLoop | None = None) -> bool:
    """Whether ``loop`` (default: the running loop) runs on virtual time."""
    return isinstance(loop or asyncio.get_running_loop(), VirtualTimeLoop)
