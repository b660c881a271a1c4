"""The heating curve on the heat pump — only when the owner asked for it — and the comfort
watch that follows it.

The owner asks with ``[curve] apply = true`` or ``impctl curve --apply`` (and takes it back
with ``impctl curve --restore``; the command's word wins over the configuration, :mod:`.intent`).
Then, while no night runs, the daemon:

1. **sets** the kept curve (:mod:`.state`) when it lowers the running one: only on an
   extended controller (a compact one has no curve register) whose adaptive curve (2320) is
   off (the controller would change the points itself); the owner's points 2309/2314 are
   journaled first, then written through the safe path (whitelist, compare, budget,
   read-back) — each point within 20–55 °C or up to the owner's own point where that is
   higher (``[heatpump.writes] loop1_curve_c`` where the installer set limits), checked before
   the write: a curve outside them is refused, never clamped;
2. **checks** that the controller follows (:mod:`.follow`): its own flow target (2128) must
   have moved as the line moved at the outdoor temperature now, within :data:`FOLLOW_TOL_K`,
   both read once the points have stood :data:`~.follow.SETTLE_S` (set once the points found
   have, judged once impctl's have); if not, the owner's points come back and the curve stays
   advice (the points' meaning is the controller document's, not measured);
3. **watches comfort**: a room on average more than ``[curve] short_k`` below its setpoint
   over ``short_h`` (the mean of the looks, so that a room short most of the time but crossing
   the line every few minutes counts) raises both points by ``raise_k`` (said in the log
   and the store's events); a curve raised back to the owner's, or past the bounds, is the
   owner's again, and impctl sets no curve until asked again (it proved too low for this
   house);
4. keeps the owner's word: points the owner changed are kept (their journal entries closed)
   and impctl stops setting the curve until asked again.

The owner's points come back on ``impctl curve --restore``, on ``impctl restore`` and the
unit's ``ExecStopPost``, on every stop of the daemon and at its next start (the orphan sweep;
the watch then sets the curve again). A night's own restore leaves them
(:attr:`impctl.controller.NightController.keep_registers`). Beside each point's journal entry
is what impctl last wrote there and read back (given up before each write, :meth:`CurveWatch.
_write`): a restore after the daemon died keeps a point the owner set while it was down, and
then impctl sets no curve until asked again (:func:`.intent.owner_kept_point`).
"""

from __future__ import annotations

import asyncio
import logging
import sqlite3
from collections import deque
from dataclasses import replace

from ...controller.held import Held
from ...heatpump import HeatPumpError
from ...heatpump.config import CURVE_FLOW_BOUNDS_C, CURVE_OWNER_MAX_C
from ...heatpump.writes import write_rules
from ...kronoterm.registers import Generation
from ...store import JournalEntry
from ..running import RunningDaemon
from .follow import FOLLOW_TOL_K, LOOKED_AT, FollowCheck, Settling
from .intent import CURVE_REGISTERS, KEEP, intent, no_curve
from .state import load_curve

_LOG = logging.getLogger("impctl.daemon")
#: A new kept curve replaces the one set when a point moves by at least this [K].
MOVE_K = 0.5


def wanted(daemon: RunningDaemon) -> bool:
    """Whether the owner wants impctl's curve on the heat pump now."""
    word = intent(daemon.cfg.state_dir)
    return daemon.cfg.curve.apply if word is None else word


def curve_entries(store) -> list[JournalEntry]:
    """The pending journal entries of the curve points."""
    return [e for e in store.journal_pending() if e.register in KEEP]


class CurveWatch:
    """Sets the curve, checks it, watches comfort (module docstring)."""

    def __init__(self, daemon: RunningDaemon):
        self.daemon = daemon
        self.held: tuple[float, float] | None = None   # points impctl wrote [°C]
        self.owner: tuple[float, float] | None = None  # the owner's points [°C]
        self._owner_raw: dict[int, int] = {}             # … as journaled (raw words)
        self._verify: FollowCheck | None = None          # the follow check waiting
        self._written_s: float | None = None             # impctl's last write read back
        self._settle = Settling()                        # the points found, unchanged since
        # the room's looks since the watch began this window: (simulated s, K below setpoint)
        self._looks: deque[tuple[float, float]] = deque()
        self._since: float | None = None                # simulated s this window began
        self.raised_k = 0.0
        self._refused: str | None = None                # why not now (said once)
        self.task: asyncio.Task | None = None

    # -- the daemon's hooks ------------------------------------------------------------------
    async def run(self) -> None:
        """Look every sampling interval while the daemon runs."""
        d = self.daemon
        while not d.stop.is_set():
            await asyncio.sleep(max(0.2, d.clock.wall_seconds(d.cfg.night.sample_interval_s)))
            try:
                await self.check()
            except HeatPumpError as exc:  # the link: the next look tries again
                _LOG.info("heating curve: heat pump not answering (%s); next look later", exc)
            except (OSError, sqlite3.Error) as exc:
                # The owner's points cannot be journaled (a full disk): nothing was written
                # (the journal comes first); said once, tried again at the next look.
                self._refuse(f"the owner's points cannot be kept ({exc})")

    async def check(self) -> None:
        """One look: never during a night, a restore or while the heat pump is away."""
        d = self.daemon
        night = d._night_task
        if (d.stop.is_set() or not d._connected.is_set() or d._heat_pump_lock.locked()
                or (night is not None and not night.done())):
            return
        async with d._heat_pump_lock:
            if not wanted(d):
                if curve_entries(d.store):
                    await self._give_back("the owner asked for their curve back")
                self.held = None
                return
            curve = load_curve(d.cfg.state_dir)
            if self.held is None:
                await self._set(curve)
            elif not curve_entries(d.store):
                await self._journal_closed()
            else:
                await self._follow(curve)

    async def _journal_closed(self) -> None:
        """impctl holds its curve, but the owner's points are no longer journaled: closed from
        outside (``impctl restore`` in another process) while impctl's points were being
        written, so they landed after the owner's went back. The owner asked for their
        settings: their points are put back from what this watch journaled, verified, and no
        curve is set until asked again."""
        d = self.daemon
        self._intent_off("the owner's settings were put back from outside")
        self._settle.forget()
        for ma, raw in self._owner_raw.items():
            await d.client.restore_raw(ma, raw)
        self.held, self._verify = None, None
        self._keep(False)
        self._say("warning", "the owner's settings were put back from outside (impctl restore) "
                             "while the heating curve was being set: their points are back, "
                             "impctl sets no curve until asked again (impctl curve --apply)")

    # -- setting -------------------------------------------------------------------------------
    def _refuse(self, why: str) -> None:
        if why != self._refused:
            self._say("warning", f"heating curve not set: {why}; it stays advice")
            self._refused = why

    async def _set(self, curve: dict | None) -> None:
        d = self.daemon
        client = d.client
        if curve is None or not curve.get("lowers"):
            if curve_entries(d.store):  # set before this run: the owner's, until it lowers
                await self._give_back("the kept curve no longer lowers the running one")
            return
        points = tuple(float(v) for v in curve["recommended"]["flow_c"])
        if client.generation is not Generation.EXTENDED:
            return self._refuse("a compact controller (TT3000) has no heating-curve "
                                "registers: set the curve in its menu")
        adaptive = await client.read(2320)
        if adaptive.value is None or adaptive.value != 0:
            return self._refuse("the controller's adaptive curve (2320) is on or unknown: "
                                "it changes the points itself")
        before = {ma: await client.read(ma) for ma in LOOKED_AT}
        if any(before[ma].raw is None for ma in CURVE_REGISTERS):
            return self._refuse("the curve points cannot be read")
        found = tuple(int(before[ma].raw) for ma in CURVE_REGISTERS)
        if not self._settle.settled(found, d.clock.monotonic_s()):
            return None   # 2128 may still say what points written just before asked for
        # the points before impctl ever wrote: journaled (kept across restarts), else now
        pending = {e.address + 1: e.raw_value for e in curve_entries(d.store)}
        owner_raw = {ma: pending.get(ma, int(before[ma].raw)) for ma in CURVE_REGISTERS}
        owner = tuple(owner_raw[ma] / 10.0 for ma in CURVE_REGISTERS)
        why = self._outside(points, owner)
        if why is not None:
            return self._refuse(why)
        for ma, name in CURVE_REGISTERS.items():
            # claims nothing yet (an entry kept from before this look is given up too): what
            # the points hold is impctl's only once its writes are read back (:meth:`_write`)
            d.store.journal_record(None, name, ma - 1, int(before[ma].raw))
        self.owner, self._owner_raw = owner, owner_raw
        self._keep(True)
        await self._write(points)
        target = before[2128].value
        self._verify = None if target is None else FollowCheck(
            target, (found[0] / 10.0, found[1] / 10.0), before[2187].value)
        self.held, self.raised_k, self._refused = points, 0.0, None
        text = (f"heating curve set to {points[0]:.1f} °C at −15 °C and {points[1]:.1f} °C at "
                f"+15 °C outside (was {owner[0]:.1f} / {owner[1]:.1f} °C)")
        self._say("info", text)

    def _policy(self, owner: tuple[float, float]):
        """The write policy the points go through: the configured ``[heatpump.writes]
        loop1_curve_c`` where the installer set limits, else :data:`CURVE_FLOW_BOUNDS_C` with
        each point's top raised to the owner's own point where that is higher (a value this
        controller already runs: a radiator house's curve at −15 °C often does)."""
        writes = self.daemon.client.config.writes
        configured = self.daemon.cfg.heatpump.writes.loop1_curve_c
        own = None if configured or max(owner) > CURVE_OWNER_MAX_C else owner
        return replace(writes, loop1_curve_c=configured or CURVE_FLOW_BOUNDS_C,
                       loop1_curve_owner_c=own)

    def _bounds(self, owner: tuple[float, float]) -> tuple[tuple[float, float], ...]:
        """(lowest, highest) each point may be set to [°C] (:meth:`_policy`)."""
        rules = write_rules(self._policy(owner))
        return tuple(rules[ma] for ma in CURVE_REGISTERS)

    def _outside(self, points: tuple[float, ...], owner: tuple[float, float]) -> str | None:
        """Why ``points`` may not be written (one phrase), or None."""
        bounds = self._bounds(owner)
        if all(lo <= p <= hi for p, (lo, hi) in zip(points, bounds, strict=True)):
            return None
        allowed = " and ".join(f"{lo:g}–{hi:g} °C" for lo, hi in bounds)
        return (f"its points {points[0]:.1f} / {points[1]:.1f} °C lie outside {allowed} "
                f"(the owner's own points: {owner[0]:.1f} / {owner[1]:.1f} °C)")

    async def _write(self, points: tuple[float, float]) -> None:
        """Write both points; the caller has checked them against :meth:`_bounds`, so the safe
        path's clamp never changes them (a clamped point would read back as the owner's
        change and the owner's points would never come back).

        impctl's curve is let go first (``held`` None) and held again by the caller once both
        points are read back: a write that may have landed unseen (the link dropped before
        its read-back) leaves a point that is neither impctl's held one nor the owner's, and
        it must never be read as the owner's change. Let go, the owner's points are the
        daemon's restorer's to put back, or the next look sets the curve anew.

        So it is beside each point's journal entry, which outlives the process: given up
        before the point's write, kept again once read back (:class:`~impctl.controller.held.
        Held`). A restore after the daemon died (its restart, ``impctl restore``) then keeps a
        point the owner set meanwhile, and puts the owner's back into one written unseen.

        Raises
        ------
        sqlite3.Error
            The store cannot give a point up: that point is not written."""
        self.held = None
        d = self.daemon
        client = d.client
        # whitelisted while the owner asks for the curve, up to these bounds
        client.config = replace(client.config, writes=self._policy(self.owner))
        held = Held(d.store, {e.address + 1: e.id for e in curve_entries(d.store)})
        self._settle.forget()
        for ma, value in zip(CURVE_REGISTERS, points, strict=True):
            await held.write(ma, lambda ma=ma, value=value: client.write(ma, value))
        self._written_s = d.clock.monotonic_s()

    def _say(self, level: str, text: str) -> None:
        # stored before it is logged: whoever reads the log finds the event already there
        self.daemon.store.add_event(level, text)
        _LOG.warning(text)

    def _intent_off(self, why: str) -> None:
        no_curve(self.daemon.cfg.state_dir, why)

    def _keep(self, held: bool) -> None:
        ctl = self.daemon.controller
        if ctl is not None:
            ctl.keep_registers = KEEP if held else frozenset()

    async def _give_back(self, why: str) -> None:
        from ...controller.restore import restore_entry

        d = self.daemon
        held = dict(zip(CURVE_REGISTERS, self.held, strict=True)) if self.held else {}
        # impctl's curve is let go before the first write: a point a failed write leaves is
        # the daemon's restorer's and the next look's to give back, never read as the
        # owner's change of impctl's curve
        self.held, self._verify = None, None
        self._looks.clear()
        self._since = None
        self._keep(False)
        self._settle.forget()
        for entry in curve_entries(d.store):
            await restore_entry(d.client, d.store, entry, held.get(entry.address + 1))
        text = f"the owner's heating curve restored ({why})"
        self._say("info", text)

    # -- after it is set -------------------------------------------------------------------------
    async def _follow(self, curve: dict | None) -> None:
        d = self.daemon
        client = d.client
        now = {ma: await client.read(ma) for ma in LOOKED_AT}
        seen = tuple(now[ma].value for ma in CURVE_REGISTERS)
        if any(v is None for v in seen):
            # a point that reads as missing (a sentinel, a word out of range) says nothing of
            # who set it: judged at the next look, never taken for the owner's change
            _LOG.info("heating curve: a point reads as missing (%s); next look later",
                      "; ".join(str(now[ma].reason) for ma in CURVE_REGISTERS
                                if now[ma].value is None))
            return None
        if any(abs(v - h) > 0.05 for v, h in zip(seen, self.held, strict=True)):
            return self._owner_changed(now)
        if self._verify is not None and not await self._judge(now):
            return None
        if curve is None or not curve.get("lowers"):
            return await self._give_back("the kept curve no longer lowers the running one")
        new = tuple(float(v) + self.raised_k for v in curve["recommended"]["flow_c"])
        if max(abs(a - b) for a, b in zip(new, self.held, strict=True)) >= MOVE_K:
            why = self._outside(new, self.owner)
            if why is not None:
                return await self._give_back(f"the new fit's curve cannot be set: {why}")
            await self._write(new)   # lets go of the held curve until read back
            self.held = new
            self._say("info", f"heating curve moved to {new[0]:.1f} / {new[1]:.1f} °C "
                              "(a new fit)")
        await self._comfort()

    async def _judge(self, now: dict) -> bool:
        """The follow check (:mod:`.follow`), once impctl's points have stood long enough:
        False when the controller did not follow (the owner's points are back), else True (the
        look goes on; a check not yet due, or without a reading now, waits for a later one)."""
        t_out, target = now[2103].value, now[2128].value
        if (t_out is None or target is None
                or not FollowCheck.due(self._written_s, self.daemon.clock.monotonic_s())):
            return True
        check, self._verify = self._verify, None
        if check.void(now[2187].value):   # the setpoint moved 2128 too: nothing to judge
            _LOG.info("heating curve: the loop-1 setpoint changed; follow check not judged")
            return True
        moved, expected = check.moves(self.held, t_out, target)
        if abs(moved - expected) > FOLLOW_TOL_K:
            # The decision is kept first: a restart between the two finds the journal and
            # restores, and does not set the curve again.
            self._intent_off("the controller did not follow")
            await self._give_back(
                f"the controller did not follow the curve points: its flow target moved "
                f"{moved:+.1f} K where the line moved {expected:+.1f} K at {t_out:.1f} °C "
                "outside")
            self._refuse("the controller does not follow its curve points as documented")
            return False
        _LOG.info("heating curve followed: the flow target moved %+.1f K where the line "
                  "moved %+.1f K at %.1f °C outside", moved, expected, t_out)
        return True

    def _owner_changed(self, now: dict) -> None:
        d = self.daemon
        for entry in curve_entries(d.store):
            reading = now[entry.address + 1]
            d.store.journal_mark_owner_changed(entry.id, int(reading.raw or entry.raw_value))
        self.held, self._verify = None, None
        self._keep(False)
        self._intent_off("the owner changed the curve points")
        text = ("the owner changed the heating curve: their points are kept, impctl sets no "
                "curve until asked again (impctl curve --apply)")
        self._say("warning", text)

    async def _comfort(self) -> None:
        d = self.daemon
        cfg = d.cfg.curve
        snap = await d.client.snapshot()
        t_air, sp = snap.t_air_c.value, snap.loop1_setpoint_c.value
        if t_air is None or sp is None:
            return
        now = d.clock.now_s()
        # Judged on the room's mean over the window, not look by look: a room that sits
        # 0.5 K short on average but crosses the line every few minutes (a thermostat's
        # cycling, a sensor's noise and rounding) would otherwise never count as short.
        window = cfg.short_h * 3600.0
        if self._since is None:
            self._since = now
        self._looks.append((now, sp - t_air))
        while self._looks and self._looks[0][0] < now - window:
            self._looks.popleft()
        if now - self._since < window:
            return
        short = sum(k for _, k in self._looks) / len(self._looks)
        if short <= cfg.short_k:
            return
        self._looks.clear()
        self._since = now
        raised = tuple(p + cfg.raise_k for p in self.held)
        why = (f"the room stayed on average {short:.1f} K below its setpoint {sp:.1f} °C "
               f"over {cfg.short_h:g} h (more than {cfg.short_k:g} K; {t_air:.1f} °C now)")
        back = None
        if all(r >= o for r, o in zip(raised, self.owner, strict=True)):
            back = "raised back to the owner's curve"
        elif self._outside(raised, self.owner) is not None:
            back = "a higher curve than impctl may set: the owner's curve back"
        if back is not None:
            # impctl's curve proved too low for this house: setting it again at the next look
            # would leave the room short once more. Kept first, as when the controller does
            # not follow: a restart between the two restores and does not set it again.
            self._intent_off("the room stayed short under impctl's curve")
            await self._give_back(f"{why}; {back}")
            self._refuse("the room stayed short under impctl's curve even raised back; "
                         "impctl sets no curve until asked again (impctl curve --apply)")
            return
        await self._write(raised)   # lets go of the held curve until read back
        self.held, self.raised_k = raised, self.raised_k + cfg.raise_k
        text = f"{why}: heating curve raised by {cfg.raise_k:g} K to " \
               f"{raised[0]:.1f} / {raised[1]:.1f} °C"
        self._say("warning", text)


def start_curve_watch(daemon: RunningDaemon) -> CurveWatch:
    """The watch and its task (the daemon cancels it on stop, before its restore)."""
    watch = CurveWatch(daemon)
    task = asyncio.create_task(watch.run(), name="heating curve")
    watch.task = task
    return watch
