"""The time a night runs on: waits bounded by one sample interval, a wall-clock step detected.

The night's instants (window, deadline, sample times) are wall-clock instants, but the wall
clock can step: NTP correcting a clock that ran ahead, a wrong ``date -s``, a resume from
suspend. asyncio sleeps on the monotonic clock, so a wait computed on a wall clock that then
steps back 3 h sleeps 3 h — with the heating off and nobody looking. Hence:

* no wait is longer than one sample interval (the caller looks again after it);
* at every poll the wall clock's advance since the last poll is compared with the monotonic
  clock's; a difference beyond :data:`STEP_TOLERANCE_S` (or two sample intervals, if longer)
  is a step, and the night ends on it;
* once the night acts, its window and deadline are also measured on the monotonic clock from
  that moment, so no step, however small or repeated, extends the time the heating is off.
"""

from __future__ import annotations

import asyncio
from datetime import datetime

from ..clock import VirtualClock

#: Smallest wall-clock step (either way) that ends a night [simulated s]; the tolerance is
#: two sample intervals when that is longer. NTP's slew (≤ 500 ppm) stays far below it.
STEP_TOLERANCE_S = 120.0
#: An instant closer than this counts as come [simulated s]: a wait computed from floats can
#: fall short by a rounding error, and a timer that short would not advance the loop's time.
#: Whatever picks the next instant to wait for must skip exactly the instants this counts as
#: come, no more: an instant it skipped although not yet come is missed at every turn when each
#: wait, capped at one interval, lands the same few milliseconds short of the next one.
REACHED_S = 1e-3


def describe_step(step_s: float) -> str:
    """A step as people say it: "−3.0 h", "+5 min"."""
    sign = "−" if step_s < 0 else "+"
    if abs(step_s) >= 3600:
        return f"{sign}{abs(step_s) / 3600:.1f} h"
    return f"{sign}{abs(step_s) / 60:.0f} min"


class NightTime:
    """Waits and clock checks of one night.

    Parameters
    ----------
    clock : VirtualClock
        Wall time (:meth:`~VirtualClock.now_s`) and its step-free count
        (:meth:`~VirtualClock.monotonic_s`).
    interval_s : the sample interval [simulated s]: the longest wait.
    """

    def __init__(self, clock: VirtualClock, interval_s: float) -> None:
        self.clock = clock
        self.interval_s = float(interval_s)
        #: A wall-clock step larger than this ends the night [simulated s].
        self.tolerance_s = max(STEP_TOLERANCE_S, 2.0 * self.interval_s)
        self._last: tuple[float, float] | None = None  # (wall s, monotonic s) at the last check
        self._anchor: tuple[float, float] | None = None  # (wall s, monotonic s) when it acted

    def step_s(self) -> float | None:
        """The wall clock's step since the last call [simulated s, + forward], when beyond
        the tolerance; else None. The first call only takes the reference."""
        now = (self.clock.now_s(), self.clock.monotonic_s())
        last, self._last = self._last, now
        if last is None:
            return None
        step = (now[0] - last[0]) - (now[1] - last[1])
        return step if abs(step) > self.tolerance_s else None

    def anchor(self) -> None:
        """From now on, measure the night's instants on the monotonic clock as well."""
        self._anchor = (self.clock.now_s(), self.clock.monotonic_s())

    def left_s(self, when: datetime) -> float:
        """Simulated seconds until ``when``: the smaller of the wall clock's and (once
        anchored) the monotonic clock's count, so neither clock's step prolongs a wait."""
        wall = when.timestamp() - self.clock.now_s()
        if self._anchor is None:
            return wall
        wall0, mono0 = self._anchor
        mono = (when.timestamp() - wall0) - (self.clock.monotonic_s() - mono0)
        return min(wall, mono)

    def reached(self, when: datetime) -> bool:
        """Whether ``when`` has come on either clock."""
        return self.left_s(when) <= REACHED_S

    async def sleep_until(self, when: datetime, *wake: asyncio.Event) -> None:
        """Sleep until ``when``, at most one sample interval, or until an event in ``wake``
        is set; the caller checks the clock (and the events) again after it."""
        left = min(self.left_s(when), self.interval_s)
        delay = self.clock.wall_seconds(left) if left > REACHED_S else 0.0
        if 0 < delay <= 1.0 and wake:  # short: an abort is seen at the next check anyway
            try:
                await asyncio.wait_for(wake[0].wait(), timeout=delay)
            except TimeoutError:
                pass
        elif delay > 0:  # long (real-time nights): wake on any of the events
            waits = [asyncio.ensure_future(e.wait()) for e in wake]
            try:
                if waits:
                    await asyncio.wait(waits, timeout=delay,
                                       return_when=asyncio.FIRST_COMPLETED)
                else:
                    await asyncio.sleep(delay)
            finally:
                for w in waits:
                    w.cancel()
        # Python 3.11's wait_for (here and inside pymodbus) can swallow a cancellation that
        # arrives as its inner future completes (CPython gh-86296); the request is still
        # counted on the task, so honour it here, where every loop of the night passes.
        task = asyncio.current_task()
        if task is not None and task.cancelling():
            raise asyncio.CancelledError("night cancelled")
