"""Warnings that a flood cannot multiply: the first few of a kind in full, the rest counted.

Anyone who can publish on the broker can send thousands of commands a second; one warning line
each would fill the journal (and a gateway's SD card) and hide everything else. So the first
:data:`IN_FULL` ignored commands of a kind (their topic and why they were ignored) within
:data:`WINDOW_S` are logged in full (a person's few wrong presses each get their line); the
ones after them are only counted, and when the window closes one line says how many there were
and why the last one was ignored. The next command of the kind after that opens a new window.
The keys are bounded (a command name, or "unknown", and a reason kind), so a flood over many
topics cannot multiply the lines either.

The windows run on the daemon's clock (real time on a gateway; an accelerated dry run's
simulated time).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Hashable
from dataclasses import dataclass

#: Length of a counting window [s, the daemon's clock].
WINDOW_S = 60.0
#: Ignored commands of one kind logged in full per window; the rest are counted.
IN_FULL = 5


@dataclass
class _Window:
    opened_s: float
    subject: str
    first_reason: str = ""   # of the first one counted
    last_reason: str = ""
    logged: int = 0          # lines logged in full
    count: int = 0           # counted since


class CountedWarnings:
    """One warning per key and window, then a counted summary.

    Parameters
    ----------
    log : the logger the lines go to
    now_s : the clock [s] (the daemon's ``VirtualClock.now_s``)
    wall_s : simulated seconds → seconds of the running event loop until the window closes
        (the clock's ``wall_seconds``; identity for real time)
    window_s : length of a window [s, on ``now_s``]
    in_full : lines logged in full per key and window
    """

    def __init__(self, log: logging.Logger, now_s: Callable[[], float],
                 wall_s: Callable[[float], float] = lambda s: s,
                 window_s: float = WINDOW_S, in_full: int = IN_FULL) -> None:
        self.log, self.now_s, self.wall_s, self.window_s = log, now_s, wall_s, window_s
        self.in_full = in_full
        self._open: dict[Hashable, _Window] = {}
        self._timers: dict[Hashable, asyncio.TimerHandle] = {}

    def warn(self, key: Hashable, subject: str, reason: str, line: str) -> None:
        """An ignored command: ``line`` is logged while ``key`` has had fewer than ``in_full``
        lines in its window; otherwise it is counted under ``subject`` (the topic) and
        ``reason`` (why)."""
        now = self.now_s()
        window = self._open.get(key)
        if window is not None and now - window.opened_s >= self.window_s:
            self.close(key)   # its timer has not run yet (a busy loop): close it here
            window = None
        if window is None:
            window = self._open[key] = _Window(now, subject)
            self._schedule(key)
        if window.logged < self.in_full:
            self.log.warning("%s", line)
            window.logged += 1
            return
        if window.count == 0:
            window.first_reason = reason
        window.count += 1
        window.last_reason = reason

    def _schedule(self, key: Hashable) -> None:
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:  # no loop (a plain call): closed by the next warn or flush
            return
        self._timers[key] = loop.call_later(max(0.0, self.wall_s(self.window_s)),
                                            self.close, key)

    def close(self, key: Hashable) -> None:
        """End ``key``'s window: one line with the count of what it suppressed, if any."""
        timer = self._timers.pop(key, None)
        if timer is not None:
            timer.cancel()
        window = self._open.pop(key, None)
        if window is None or window.count == 0:
            return
        n = window.count
        why = window.last_reason if window.last_reason == window.first_reason else (
            f"the last: {window.last_reason}")
        self.log.warning("MQTT: %s more command%s on %s ignored within %s s of the first: %s",
                         f"{n:,}", "" if n == 1 else "s", window.subject,
                         f"{self.window_s:g}", why)

    def flush(self) -> None:
        """Close every window (the bridge stops): no count is lost."""
        for key in list(self._open):
            self.close(key)
