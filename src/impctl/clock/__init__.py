"""A virtual clock shared by the simulator and the daemon, across processes.

Simulated time is defined from three numbers only::

    sim_time = epoch + (wall_now − wall_epoch) × factor

``epoch`` is the simulated instant at the wall-clock instant ``wall_epoch`` (POSIX seconds) and
``factor`` the speed-up. Two processes built from the same three numbers (e.g. from
:meth:`VirtualClock.spec`) compute the same simulated time, to the precision of their system
clocks. With ``factor = 1`` and ``epoch = wall_epoch`` it is the real time.

On the wall clock an accelerated clock is load-sensitive: simulated time runs on while a
process waits for the CPU, so a busy machine (or a slow gateway) makes a simulated night miss
samples. That mode is for a dry run on a field gateway (``[clock] speed``). A simulation that
must not depend on the machine uses :meth:`VirtualClock.on_loop` on a
:class:`~impctl.clock.loop.VirtualTimeLoop`, whose time advances only when everyone waits.

The wall clock can step (NTP correcting a clock that ran ahead, a wrong ``date -s``, a
resume from suspend); :meth:`VirtualClock.monotonic_s` cannot. The night controller bounds its
waits and its window on the monotonic count and compares the two to detect a step.

This module imports nothing from the simulator or the model so the daemon can use it.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from datetime import UTC, datetime

from ..errors import InputError


class VirtualClock:
    """Real or accelerated time.

    Parameters
    ----------
    epoch : datetime, optional
        Simulated time at ``wall_epoch`` (time zone-aware). Default: the wall time at
        ``wall_epoch`` (so ``factor = 1`` gives real time).
    factor : float, default 1
        Simulated seconds per wall-clock second (> 0).
    wall_epoch_s : float, optional
        Wall-clock anchor [POSIX s]. Default: now.
    wall : callable, optional
        Source of wall time [POSIX s]; ``time.time`` by default (tests may inject one).
    monotonic : callable, optional
        A source of seconds that never steps, ticking with ``wall`` [s, any origin]:
        ``time.monotonic`` for ``time.time``; an injected ``wall`` is its own by default
        (a test that steps its wall passes the unstepped source here).
    """

    def __init__(
        self,
        epoch: datetime | None = None,
        factor: float = 1.0,
        wall_epoch_s: float | None = None,
        *,
        wall: Callable[[], float] = time.time,
        monotonic: Callable[[], float] | None = None,
    ) -> None:
        if not factor > 0:
            raise InputError(f"clock factor must be > 0, got {factor}", place="clock")
        if epoch is not None and epoch.tzinfo is None:
            raise InputError("clock epoch must carry a time zone", place="clock")
        self._wall = wall
        self._monotonic = monotonic or (time.monotonic if wall is time.time else wall)
        self.on_loop_time = False  # True: wall is an event loop's time (see on_loop)
        self.factor = float(factor)
        self.wall_epoch_s = float(wall() if wall_epoch_s is None else wall_epoch_s)
        self.epoch_s = self.wall_epoch_s if epoch is None else epoch.timestamp()

    @classmethod
    def real(cls) -> VirtualClock:
        """The real wall clock (factor 1, simulated time = wall time)."""
        return cls(None, 1.0, 0.0)

    @classmethod
    def on_loop(cls, epoch: datetime, factor: float = 1.0,
                loop: asyncio.AbstractEventLoop | None = None) -> VirtualClock:
        """Simulated time on an event loop's clock (default: the running loop's)::

            sim_time = epoch + (loop.time() − loop.time() now) × factor

        On a :class:`~impctl.clock.loop.VirtualTimeLoop` it advances only when every task of the
        loop waits, so the simulation does not depend on the machine's load; ``factor`` then
        scales the loop's own pauses (timeouts, retry delays, poll intervals) into simulated
        time. Such a clock lives in its process: it has no :meth:`spec`.
        """
        loop = loop or asyncio.get_running_loop()
        clock = cls(epoch, factor, loop.time(), wall=loop.time)
        clock.on_loop_time = True
        return clock

    @property
    def epoch(self) -> datetime:
        """Simulated time at the wall anchor (UTC)."""
        return datetime.fromtimestamp(self.epoch_s, UTC)

    def now_s(self) -> float:
        """Simulated time now [POSIX s]."""
        return self.epoch_s + (self._wall() - self.wall_epoch_s) * self.factor

    def now(self) -> datetime:
        """Simulated time now (UTC, time zone-aware)."""
        return datetime.fromtimestamp(self.now_s(), UTC)

    def monotonic_s(self) -> float:
        """Simulated seconds on a source that never steps [s, arbitrary origin]: only its
        differences mean anything. A wall-clock step moves :meth:`now_s`, not this."""
        return self._monotonic() * self.factor

    def wall_seconds(self, sim_s: float) -> float:
        """Wall-clock seconds that ``sim_s`` simulated seconds take."""
        return sim_s / self.factor

    def sim_seconds(self, wall_s: float) -> float:
        """Simulated seconds that pass in ``wall_s`` wall-clock seconds."""
        return wall_s * self.factor

    def spec(self) -> str:
        """A one-line description another process can pass to :meth:`from_spec`.

        Raises
        ------
        ValueError
            For a clock on an event loop's time (:meth:`on_loop`): no other process shares it.
        """
        if self.on_loop_time:
            raise ValueError("a clock on an event loop's time cannot be shared with a process")
        return (f"epoch={self.epoch.isoformat()},factor={self.factor!r},"
                f"wall_epoch={self.wall_epoch_s!r}")

    @classmethod
    def from_spec(cls, spec: str, *, wall: Callable[[], float] = time.time,
                  monotonic: Callable[[], float] | None = None) -> VirtualClock:
        """Rebuild a clock from :meth:`spec` output (``epoch=…,factor=…,wall_epoch=…``).

        Raises
        ------
        InputError
            On a malformed spec.
        """
        parts: dict[str, str] = {}
        for item in spec.split(","):
            key, sep, value = item.partition("=")
            if not sep:
                raise InputError(f"clock spec item {item!r} is not key=value", place="clock")
            parts[key.strip()] = value.strip()
        unknown = set(parts) - {"epoch", "factor", "wall_epoch"}
        if unknown or "epoch" not in parts:
            raise InputError(f"clock spec needs epoch, factor, wall_epoch: {spec!r}",
                             place="clock")
        try:
            epoch = datetime.fromisoformat(parts["epoch"])
            factor = float(parts.get("factor", "1"))
            wall_epoch = float(parts["wall_epoch"]) if "wall_epoch" in parts else None
        except ValueError as exc:
            raise InputError(f"bad clock spec {spec!r}: {exc}", place="clock") from None
        return cls(epoch, factor, wall_epoch, wall=wall, monotonic=monotonic)

    def __repr__(self) -> str:
        if self.on_loop_time:
            return (f"VirtualClock(epoch={self.epoch.isoformat()},factor={self.factor!r},"
                    f"on the event loop's time)")
        return f"VirtualClock({self.spec()})"
