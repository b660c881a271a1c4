"""The daemon's side of the owner recording (``[record]``): when the house may be recorded, the
loop that records it, and the daily retention.

The house is recorded whenever the heat pump answers and no IMP night runs — not its pre-heat,
not its restore, not the restore of owner's values still pending. Each snapshot is taken under
the heat-pump lock (the one a night, a restore and the MQTT idle read hold), and a night that
begins ends the current row. Nothing here writes to the heat pump: the recorder only reads
(:class:`~impctl.controller.recording.recorder.OwnerRecorder`).

Whether it records, and why not, is noted in the daemon's lock file for ``impctl status``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from datetime import UTC, datetime

from ...clock import VirtualClock
from ...config import Config
from ...controller.recording.recorder import OwnerRecorder
from ...heatpump import HeatPumpClient
from ...store import Store
from ..running import RunningDaemon

_LOG = logging.getLogger("impctl.record")
#: How often records older than ``record.keep_days`` are deleted [s of the daemon's clock].
RETENTION_EVERY_S = 86400.0


def make_recorder(daemon: RunningDaemon) -> OwnerRecorder:
    """The recorder the configuration asks for (``[record]``, the night's min_coverage and
    window, the house's own sensors when ``[inputs]`` is configured)."""
    inputs = daemon.house_inputs
    return _recorder(daemon.cfg, daemon.client, daemon.store, daemon.clock,
                     None if inputs is None else (lambda snap: inputs.row(None, snap)))


def _recorder(cfg: Config, client: HeatPumpClient | None, store: Store, clock: VirtualClock,
              inputs_row=None) -> OwnerRecorder:
    return OwnerRecorder(
        client, store, clock, tz=cfg.timezone, window_minutes=cfg.window_minutes,
        interval_s=cfg.record.interval_s,
        sample_interval_s=cfg.record.snapshot_interval_s(cfg.night),
        min_coverage=cfg.night.min_coverage, inputs_row=inputs_row)


def close_for_good(cfg: Config, store: Store, clock: VirtualClock) -> int:
    """Close every record still recording, its day over or not, labelled from the rows it
    has (a day cut short says "data missing"): the recording has ended for good — the
    demo's end. A daemon that stops leaves the current day open for its next start."""
    recorder = _recorder(cfg, None, store, clock)
    records = store.owner_records(states=["recording"])
    for record in records:
        recorder.close(record.id)
    return len(records)


def busy(daemon: RunningDaemon) -> str | None:
    """Why the house is not recorded now (None: it may be)."""
    if not daemon._connected.is_set():
        return "the heat pump is not connected"
    if daemon.night_running():
        return "an IMP night runs"
    if daemon._restorable():  # not the heating curve's while the owner has it set
        return "the owner's settings are being restored"
    return None


class _State:
    """What the lock file says of the recording, written on change only."""

    def __init__(self, daemon: RunningDaemon):
        self.daemon = daemon
        self.key: tuple | None = None

    def set(self, state: str, why: str | None = None) -> None:
        if self.key == (state, why):
            return
        self.key = (state, why)
        lock = self.daemon._lock
        if lock is None:
            return
        try:
            lock.note("record", {"state": state, "why": why,
                                 "since": datetime.now(UTC).isoformat()})
        except OSError as exc:  # status loses a line; recording goes on
            _LOG.warning("could not note the recording state: %s", exc)


async def record_house(daemon: RunningDaemon, recorder: OwnerRecorder) -> None:
    """Record the house until the daemon stops (then the current row is stored)."""
    cfg = daemon.cfg
    state = _State(daemon)
    _safely(recorder.close_due)  # records an earlier run left open past their day
    recorder.purge(cfg.record.keep_days)
    purged_at = daemon.clock.monotonic_s()
    usable = recorder.closed_usable
    failed: str | None = None
    try:
        while not daemon.stop.is_set():
            try:
                why = busy(daemon)
                if why is not None:
                    if state.key is None or state.key[0] != "paused":
                        recorder.end_row()  # a night begins: its span is not the owner's
                    state.set("paused", why)
                    await _wait(daemon, recorder.sample_interval_s)
                    continue
                when = recorder.next_poll()
                await recorder.sleep_until(when, daemon.stop)
                if daemon.stop.is_set() or not recorder.time.reached(when):
                    continue  # stopping, or a bounded wait woke before its instant
                async with daemon._heat_pump_lock:
                    if busy(daemon) is not None:
                        continue
                    await recorder.poll()
                if recorder.closed_usable != usable:  # a new owner night: the morning refit
                    usable = recorder.closed_usable
                    daemon.want_season()
                state.set("recording")
                if daemon.clock.monotonic_s() - purged_at >= RETENTION_EVERY_S:
                    recorder.purge(cfg.record.keep_days)
                    purged_at = daemon.clock.monotonic_s()
                failed = None
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # noqa: BLE001 - recording never stops the daemon
                if failed != repr(exc):
                    _LOG.exception("owner recording failed; retrying")
                    failed = repr(exc)
                state.set("failed", str(exc))
                await _wait(daemon, recorder.sample_interval_s)
    finally:
        _safely(recorder.end_row)
        state.set("stopped")


def _safely(fn) -> None:
    try:
        fn()
    except Exception:  # noqa: BLE001 - logged; recording goes on without it
        _LOG.exception("owner recording: %s failed", getattr(fn, "__name__", fn))


async def _wait(daemon: RunningDaemon, sim_s: float) -> None:
    """Wait ``sim_s`` simulated seconds of the daemon's clock on the loop, or until the stop."""
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(daemon.stop.wait(), timeout=daemon.clock.wall_seconds(sim_s))
