"""The daemon's stop, in its order: what drives the heat pump ends first, then the owner's
settings go back, then what only reports or computes, and the store closes last."""

from __future__ import annotations

import asyncio
import logging
from typing import Any, Protocol

from apscheduler.schedulers.asyncio import AsyncIOScheduler

from ..controller import restore_all
from .running import RunningDaemon

_LOG = logging.getLogger("impctl.daemon")

#: The budget [s of the event loop's monotonic time] of the stop's work on the heat pump: inside
#: the unit's ``TimeoutStopSec=90s`` (deploy/impctl.service) with room left for a last Modbus
#: try running over it, the MQTT "offline" (:data:`~impctl.mqtt.bridge.STOP_TIMEOUT_S`) and
#: closing the link and the store. Past the unit's timeout systemd kills the process, and its
#: ``ExecStopPost`` (``impctl restore``) puts back whatever is still pending.
STOP_BUDGET_S = 70.0
#: Of the budget, what the night's own abort and restore leave for the rest: the owner
#: recording's last row and the stop's own restore of a journal the night left pending [s].
AFTER_NIGHT_S = 20.0
#: Longest wait for the owner recording's last row and snapshot [s].
RECORDER_S = 30.0
#: Shortest try the stop's own restore gets, whatever is left of the budget [s].
RESTORE_MIN_S = 5.0


class Stopping(RunningDaemon, Protocol):
    """What the stop ends of the daemon (:class:`~impctl.daemon.service.Daemon`), besides
    what its hooks see (typing only)."""

    #: the heating curve's watch (:class:`~impctl.daemon.curve.watch.CurveWatch`) or None
    curve: Any
    scheduler: AsyncIOScheduler | None
    _polls: list[asyncio.Task]
    _recorder_task: asyncio.Task | None
    _accelerated_task: asyncio.Task | None
    _fit_task: asyncio.Task | None


async def shut_down(daemon: Stopping) -> None:
    """Stop ``daemon``'s tasks, restore the pending journal, close the link and the store,
    all within :data:`STOP_BUDGET_S`."""
    d = daemon
    loop = asyncio.get_running_loop()
    deadline = loop.time() + STOP_BUDGET_S
    if d.curve is not None:  # before the restore below, which gives the curve back
        d.curve.task.cancel()
        await asyncio.gather(d.curve.task, return_exceptions=True)
    if d._night_task is not None and not d._night_task.done():
        # The controller sees the stop event, aborts and restores; wait for it.
        try:
            await asyncio.wait_for(asyncio.shield(d._night_task),
                                   timeout=max(0.0, deadline - AFTER_NIGHT_S - loop.time()))
        except (TimeoutError, asyncio.CancelledError, Exception) as exc:  # noqa: BLE001
            _LOG.error("night did not finish cleanly on stop: %r", exc)
    for task in d._polls:
        task.cancel()
    if d._recorder_task is not None:  # its last row stored, its snapshot done
        try:
            await asyncio.wait_for(asyncio.shield(d._recorder_task), timeout=max(0.0, min(
                RECORDER_S, deadline - RESTORE_MIN_S - loop.time())))
        except (TimeoutError, asyncio.CancelledError, Exception) as exc:  # noqa: BLE001
            _LOG.error("owner recording did not stop cleanly: %r", exc)
            d._recorder_task.cancel()
    if d.store is not None and d.store.journal_pending() and d._connected.is_set():
        # the rest of the budget, in the daemon clock's seconds (restore_all counts on it)
        left_s = max(RESTORE_MIN_S, deadline - loop.time())
        await restore_all(d.client, d.store, clock=d.clock,
                          timeout_s=d.clock.sim_seconds(left_s), retry_s=1.0)
    if d.scheduler is not None and d.scheduler.running:
        d.scheduler.shutdown(wait=False)
    if d._accelerated_task is not None:  # after the night above has finished
        d._accelerated_task.cancel()
        await asyncio.gather(d._accelerated_task, return_exceptions=True)
    if d._fit_task is not None:  # kill the fit subprocess and reap it
        d._fit_task.cancel()
        await asyncio.gather(d._fit_task, return_exceptions=True)
    if d.mqtt is not None:  # MQTT hook: "offline" after the restore, before closing
        await d.mqtt.stop()
    if d.client is not None:
        d.client.close()
    if d.store is not None:
        d.store.close()
    _LOG.info("impctl daemon stopped")
