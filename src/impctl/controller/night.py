"""The IMP night state machine: prepare → act → sample → end → restore → assess.

Safety rules this module keeps:

* the owner's loop-1 setpoint and mode are journaled in the store BEFORE the first write;
* every write goes through the safe client (whitelist, clamp, compare, read-back, budget);
  until its read-back confirms it, impctl claims no value in that register (the write may
  have landed before the link dropped), so the restore puts the owner's value back
  whatever it finds there; what it does claim is kept beside the journal too (:mod:`.held`);
* whatever ends the night — its window, T_min, an abort, an exception (also an unexpected
  one: a bug, a store that cannot write), cancellation (SIGTERM) — the journal is restored and
  verified by read-back; if the process dies instead, the journal stays pending and the next
  start (orphan sweep) or ``impctl restore`` restores it, keeping what the owner set since;
* the night is never run blind: no good read (link lost) or no indoor temperature for longer
  than ``link_lost_limit_s`` aborts it;
* the owner comes first: a loop-1 setpoint or mode that differs at a sample from what impctl
  last wrote (the owner, a thermostat app or ``impctl restore`` changed it), or the heating
  system switched off, ends the night at once (not valid); the changed register keeps the
  owner's new value (its journal entry is closed, not restored) and the others are restored;
* one log line per incident (link lost, readings missing), when it starts, and one when it
  ends; each incident is also noted in the night's reasons;
* a store that cannot record (a full disk) ends the night; the restore never needs it: a
  store that cannot even be read restores from the copy of the owner's values beside it;
* the switch-off comes only while the night's journal is still pending and the registers
  hold what impctl left there (``impctl restore`` may have put the owner's values back
  since the last sample);
* a progress line that cannot be shown (a foreground night's terminal went away) never
  stops the night or its restore;
* waits last one sample interval at most, a wall-clock step ends the night, the window holds
  on the monotonic clock too (:mod:`.timing`); samples are never stored out of order.
"""

from __future__ import annotations

import asyncio
import logging
import sqlite3
from collections.abc import Callable
from datetime import datetime, timedelta

from ..clock import VirtualClock
from ..errors import sqlite_problem
from ..heatpump import HeatPumpClient, HeatPumpError, ModbusLinkError, Snapshot
from ..store import Night, Store
from .assess import record_end
from .held import Held
from .incidents import Incidents
from .limits import NightAbort, SampleLimits
from .owner import (
    fmt_register,
    journal_owner,
    keep_owner_changes,
    owner_changes,
    taken_back,
)
from .plan import NightPolicy, NightRefused, NightRequest, preheat_short
from .poll import readings_problem, sample_from_snapshot, status_line, unfit
from .restore import journal_to_restore, restore_all
from .timing import NightTime, describe_step

_LOG = logging.getLogger(__name__)
_SETPOINT, _MODE = 2187, 2042


class NightController:
    """Runs IMP nights against one heat pump and records them in the store.

    Parameters
    ----------
    client : HeatPumpClient, connected
    store : Store
    clock : VirtualClock (real time, or the simulator's accelerated clock)
    policy : NightPolicy
    on_status : callable(str), optional
        Receives one-line progress for systemd STATUS= and the CLI.
    stop : asyncio.Event, optional
        Set it to abort the running night (then restore) — the daemon's SIGTERM path.
    """

    def __init__(self, client: HeatPumpClient, store: Store, clock: VirtualClock,
                 policy: NightPolicy, *, on_status: Callable[[str], None] | None = None,
                 stop: asyncio.Event | None = None):
        self.client, self.store, self.clock, self.policy = client, store, clock, policy
        self.on_status = on_status or (lambda text: None)
        #: Called with (night id, snapshot) after each stored sample (the house's own sensors
        #: are stored beside it); must not raise.
        self.on_sample: Callable[[int, Snapshot], None] | None = None
        self.stop = stop or asyncio.Event()
        self.last_snapshot: Snapshot | None = None
        self.last_good_read: datetime | None = None
        self.last_t_air: datetime | None = None  # time of the last sample with T_air
        self._incidents = Incidents(store)
        self._limits = SampleLimits(policy)
        self._held = Held()  # register → the value impctl last wrote there and read back
        self._entries: dict[int, int] = {}  # register → this night's journal entry
        self._abort_reason: str | None = None  # a household's stop request (abort())
        self._aborted = asyncio.Event()
        self._running = False
        #: Registers a night's restore leaves as they are (their journal entries stay
        #: pending): the heating-curve points while the owner has impctl's curve set.
        self.keep_registers: frozenset[str] = frozenset()
        self._time = NightTime(clock, policy.sample_interval_s)
        self._last_stored: datetime | None = None  # the newest sample's time this night

    @property
    def running(self) -> bool:
        """A night is in :meth:`run`, from its preparation to the end of its restore."""
        return self._running

    def abort(self, reason: str) -> bool:
        """End the running night now and restore, leaving the process running (the
        household's stop button). Returns False when no night is running."""
        if not self._running:
            return False
        self._abort_reason = reason
        self._aborted.set()
        return True

    def _say(self, text: str) -> None:
        """One line of progress to ``on_status``; a reader that went away (the terminal of a
        foreground night closed: EIO, a broken pipe) never stops the night or its restore."""
        try:
            self.on_status(text)
        except Exception as exc:  # noqa: BLE001 - the heat pump matters more than the line
            _LOG.warning("progress line not shown (%s): %s", exc, text)

    def _clock_check(self) -> None:
        """End the night (raises ``NightAbort``) when the wall clock stepped since the last look."""
        step = self._time.step_s()
        if step is not None:
            raise NightAbort(f"system clock stepped by {describe_step(step)}")

    async def _sleep_until(self, when: datetime) -> None:
        """Sleep until ``when``, one sample interval at most, or a stop or an abort."""
        await self._time.sleep_until(when, self.stop, self._aborted)

    # -- the night ---------------------------------------------------------------------------
    async def run(self, req: NightRequest) -> Night:
        """Run one night to its end; returns the stored, assessed night.

        The heat pump is restored before this returns, whatever happened (unless the process
        dies, in which case the journal drives the restore at the next start).
        """
        try:
            night_id = self.store.create_night(
                req.kind, req.setpoint_c, req.window_start, req.window_end,
                t_min_c=req.t_min_c, t_max_c=req.t_max_c, source=req.source)
            if req.campaign_seq is not None:
                self.store.link_campaign(req.campaign_seq, night_id)
        except sqlite3.Error as exc:  # nothing written to the heat pump: nothing to restore
            why = f"the store cannot record: {sqlite_problem(exc)}"
            _LOG.error("night not started: %s", why)
            raise NightRefused(why) from None
        log = _LOG.getChild(f"night{night_id}")
        state, reasons = "done", []
        wrote = False
        self._incidents = Incidents(self.store)
        self._held, self._entries = Held(), {}
        self._abort_reason, self._running = None, True
        self._aborted.clear()
        self._time = NightTime(self.clock, self.policy.sample_interval_s)
        self._limits = SampleLimits(self.policy)
        self._last_stored = None
        try:
            self.store.set_night_state(night_id, "preparing")
            first = await self._prepare(night_id, req, log)
            self.store.set_night_state(night_id, "active", started=self.clock.now())
            wrote = True
            end_reason = await self._act_and_sample(night_id, req, first, log)
            reasons.append(end_reason)
        except NightRefused as exc:
            state, reasons = "refused", [str(exc)]
            log.warning("night refused: %s", exc)
        except NightAbort as exc:
            state, reasons = "aborted", [exc.reason]
            log.warning("night aborted: %s", exc.reason)
        except asyncio.CancelledError:
            state, reasons = "aborted", ["stopped (cancelled)"]
            log.warning("night cancelled: restoring the heat pump")
            self._running = False
            await self._finish(night_id, req, state, reasons, wrote, log)
            raise
        except HeatPumpError as exc:
            state, reasons = "aborted", [f"heat pump: {exc}"]
            log.error("night aborted by a heat-pump error: %s", exc)
        except sqlite3.Error as exc:  # a full disk, a read-only or damaged store
            state, reasons = "aborted", [f"the store cannot record: {sqlite_problem(exc)}"]
            log.error("night aborted: %s; restoring the heat pump", reasons[0])
        except Exception as exc:  # a bug or a failing store must not leave the heating off
            state, reasons = "aborted", [f"internal error: {exc!r}"]
            log.exception("night aborted by an unexpected error; restoring the heat pump")
        self._running = False
        return await self._finish(night_id, req, state, reasons, wrote, log)

    async def _finish(self, night_id: int, req: NightRequest, state: str, reasons: list[str],
                      wrote: bool, log: logging.Logger) -> Night:
        """Restore, then record and assess the night; the restore comes first and never
        depends on the store recording anything."""
        self._incidents.close(self.clock.now())
        try:
            self.store.set_night_state(night_id, "restoring" if wrote else state)
        except Exception as exc:  # noqa: BLE001 - the restore below matters more
            log.error("cannot record the night's state (%s); restoring the heat pump anyway",
                      sqlite_problem(exc), exc_info=not isinstance(exc, sqlite3.Error))
        journal = journal_to_restore(self.store, log)
        if journal is not None and [e for e in journal.journal_pending()
                                    if e.register not in self.keep_registers]:
            self._say(f"night {night_id}: restoring the heat pump")
            # Shielded: a second cancellation must not interrupt putting the heating back.
            # A value that is neither what impctl last left there nor the journaled one was
            # set by the owner after the last sample, and stays.
            left = await asyncio.shield(restore_all(
                self.client, journal, clock=self.clock,
                timeout_s=self.policy.restore_timeout_s,
                retry_s=max(0.05, self.clock.wall_seconds(self.policy.sample_interval_s)),
                keep=self.keep_registers, held=self._held.by_name()))
            if left:
                reasons.append("restore incomplete: " + ", ".join(e.register for e in left))
        reasons += self._incidents.notes
        night, unrecorded = record_end(self.store, self.policy, night_id, req, state, reasons,
                                       self.clock.now())
        log.info("night %d %s, %s: %s%s", night_id, night.state,
                 "valid" if night.valid else "not valid", "; ".join(night.reasons),
                 "" if unrecorded is None else f" (not recorded: {unrecorded}; the next start "
                 "marks it interrupted)")
        self._say(f"night {night_id} {night.state} "
                  f"({'valid' if night.valid else 'not valid'})")
        return night

    async def _snapshot(self, night_id: int | None, log: logging.Logger) -> Snapshot | None:
        """One poll; stores it as a sample; None when the link failed (the incident is
        logged once, when it starts). A wall-clock step since the last poll ends the night
        before anything is stored (raises ``NightAbort``)."""
        self._clock_check()
        polled = self.clock.now()
        try:
            snap = await self.client.snapshot()
        except ModbusLinkError as exc:
            if self.last_good_read is None or self.last_snapshot is not None:
                self._incidents.link_lost(exc, polled, log)
            self.last_snapshot = None
            return None
        now = self.clock.now()
        if self.last_snapshot is None and self.last_good_read is not None:
            self._incidents.link_back(now, log)
        self.last_snapshot = snap
        self.last_good_read = now
        if snap.t_air_c.value is not None:
            self.last_t_air = now
        self._incidents.readings(readings_problem(snap), now, log)
        if night_id is not None:
            if self._last_stored is not None and snap.timestamp <= self._last_stored:
                # A wall-clock step within the tolerance: a sample is never stored out of
                # order (nor over an earlier one); the next one is.
                log.info("sample at %s not stored: not after the previous one (%s)",
                         snap.timestamp.isoformat(), self._last_stored.isoformat())
                return snap
            self.store.add_sample(sample_from_snapshot(night_id, snap))
            self._last_stored = snap.timestamp
            if self.on_sample is not None:
                self.on_sample(night_id, snap)
        return snap

    async def _prepare(self, night_id: int, req: NightRequest, log) -> Snapshot:
        """Check the heat pump and weather (re-checking until the start grace runs out),
        then journal the owner's state before any write."""
        act_at = req.window_start - timedelta(hours=self.policy.preheat_h)
        give_up = max(act_at, self.clock.now()) + timedelta(seconds=self.policy.start_grace_s)
        while not (self._time.reached(act_at) or self.stop.is_set()
                   or self._abort_reason is not None):
            await self._sleep_until(act_at)
        try:
            self.client.require_heat_power()
        except HeatPumpError as exc:
            raise NightRefused(str(exc)) from None
        while True:
            if self._abort_reason is not None:
                raise NightAbort(self._abort_reason)
            if self.stop.is_set():
                raise NightRefused("stopped before the night started")
            problem = None
            snap = await self._snapshot(None, log)
            if snap is None:
                problem = "heat pump not reachable"
            else:
                problem = unfit(snap, self.policy)
            if problem is None:
                break
            if self.clock.now() >= give_up:
                raise NightRefused(problem)
            self._say(f"night {night_id}: waiting ({problem})")
            await self._sleep_until(self.clock.now() + timedelta(
                seconds=self.policy.sample_interval_s))
        self._entries, values = await journal_owner(
            self.client, self.store, night_id, self.clock.now().date())
        self._held = Held(self.store, self._entries, values)
        log.info("journaled owner's state: setpoint %s, loop-1 mode %s",
                 fmt_register(_SETPOINT, snap.loop1_setpoint_c.value),
                 fmt_register(_MODE, snap.loop1_mode.value))
        return snap

    async def _act_and_sample(self, night_id: int, req: NightRequest, first: Snapshot,
                              log) -> str:
        """Write the night's settings and sample until the end; returns why it ended."""
        policy = self.policy
        if self._abort_reason is not None:   # asked while the night prepared: no write
            raise NightAbort(self._abort_reason)
        if self.stop.is_set():
            raise NightAbort("stop requested (signal)")
        if self._time.reached(req.window_end):   # a late start (a resume from suspend)
            raise NightAbort("the night's window had ended before its first write")
        preheat_target = req.t_max_c if req.kind == "constrained" else req.setpoint_c
        result = await self._held.write(
            _SETPOINT, lambda: self.client.set_loop1_setpoint(preheat_target))
        if result.clamped:
            log.warning("setpoint %.1f °C clamped to %.1f °C by the configured limits",
                        result.requested, result.target)
        if first.loop1_mode.value == 2:
            # A schedule could drop to ECO mid-night; hold loop 1 in plain "on" instead.
            await self._held.write(_MODE, lambda: self.client.set_loop1_mode(1))
        self._limits.set_floor(req, first.loop1_setpoint_c.value)
        switched_off = False
        deadline = req.window_end + timedelta(seconds=policy.deadline_grace_s)
        interval = timedelta(seconds=policy.sample_interval_s)
        self._time.anchor()  # from here the window is held on the monotonic clock as well
        next_at = self.clock.now()
        while True:
            if self._abort_reason is not None:
                raise NightAbort(self._abort_reason)
            if self.stop.is_set():
                raise NightAbort("stop requested (signal)")
            self._clock_check()  # before the deadline: a step forward is named as such
            now = self.clock.now()
            if self._time.reached(deadline):
                raise NightAbort("hard deadline passed")
            if (req.kind == "constrained" and not switched_off
                    and self._time.reached(req.window_start)
                    and not self._time.reached(req.window_end)):
                too_cold = preheat_short(self.last_snapshot, req, policy)
                if too_cold:  # switching off would only take the room under T_min
                    return too_cold
                await self._still_ours(log)
                await self._switch_off(log)
                switched_off = True
                self._limits.trend = []
            snap = await self._snapshot(night_id, log)
            self._owner_check(snap, log)
            reason = self._check(snap, req, switched_off, now)
            if reason is not None:
                return reason
            self._say(status_line(night_id, req, snap))
            next_at = max(next_at + interval, self.clock.now())
            if next_at >= req.window_end or self._time.reached(req.window_end):
                await self._sleep_until(req.window_end)
                final = await self._snapshot(night_id, log)
                if final is not None:
                    self._owner_check(final, log)
                    self._check(final, req, switched_off, self.clock.now())
                return "window ended"
            await self._sleep_until(next_at)

    def _owner_check(self, snap: Snapshot | None, log) -> None:
        """End the night when the owner changed what impctl holds (raises ``NightAbort``).

        The changed registers' journal entries are closed, so the restore that follows puts
        back only what the owner did not touch, and never overwrites their new choice.
        """
        self._owner_changed(owner_changes(snap, self._held))

    async def _still_ours(self, log) -> None:
        """Before the switch-off (:func:`.owner.taken_back`): raises ``NightAbort``, nothing
        written, when the owner's values were put back since the last sample."""
        why = await taken_back(self.client, self.store, self._entries, self._held, log)
        if why is not None:
            raise NightAbort(why)

    def _owner_changed(self, changes) -> None:
        why = keep_owner_changes(self.store, changes)
        if why is not None:
            raise NightAbort(why)

    async def _switch_off(self, log) -> None:
        if self.policy.constrained_action == "loop_off":
            await self._held.write(_MODE, lambda: self.client.set_loop1_mode(0))
            log.info("heating switched off (loop-1 mode 0)")
        else:
            await self._held.write(_SETPOINT, lambda: self.client.set_loop1_setpoint(
                self.policy.setpoint_floor_c))
            log.info("heating set back to the floor %.1f °C", self.policy.setpoint_floor_c)

    def _check(self, snap: Snapshot | None, req: NightRequest, switched_off: bool,
               now: datetime) -> str | None:
        """Abort (raises) or end (returns the reason) conditions after a poll."""
        return self._limits.judge(snap, req, switched_off, now, self.last_good_read,
                                  self.last_t_air)
