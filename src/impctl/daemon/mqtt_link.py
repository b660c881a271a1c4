"""The daemon's side of MQTT: what the bridge reads, and the household commands.

Kept out of ``service.py`` so that the service only has small, named hooks:
``start_mqtt`` / ``MqttLink.stop`` / ``MqttLink.wake``, ``run_commands`` (the 1 s command
poll) and ``skip_tonight`` (asked by the night job). Commands go through the store, like
``impctl trigger``: a command queued by any process is executed here.
"""

from __future__ import annotations

import asyncio
import logging
import time
from datetime import UTC, datetime, timedelta
from importlib import metadata
from typing import TYPE_CHECKING

from ..clock import VirtualClock
from ..controller import restore_all
from ..heatpump import HeatPumpError, ModbusLinkError, Snapshot
from .curve.state import curve_path, load_curve, suggested_flow_c
from .nights.adaptive import campaign_state
from .nights.schedule import daytime_reason, request_expiry
from .nights.waiting import SKIP_VALID_H, describe_queued, queue_night, queue_skip, waiting_skips
from .running import RunningDaemon

if TYPE_CHECKING:
    from ..mqtt.bridge import MqttBridge
    from ..mqtt.commands import Command
    from ..mqtt.homeassistant.discovery import DeviceIdentity
    from ..mqtt.homeassistant.payloads import LiveState

_LOG = logging.getLogger("impctl.daemon")
_RUNNING = ("preparing", "active", "restoring")
#: How often the next night's start is re-evaluated for Home Assistant at most [s, wall].
_NEXT_NIGHT_S = 60.0
_TASKS: set[asyncio.Task] = set()
try:
    _VERSION = metadata.version("impctl")
except metadata.PackageNotFoundError:
    _VERSION = "unknown"


class MqttLink:
    """The :class:`~impctl.mqtt.bridge.StateSource` of a running daemon."""

    def __init__(self, daemon: RunningDaemon):
        self.daemon = daemon
        self._idle: Snapshot | None = None
        self._idle_ok = False
        self._idle_tried = None  # when the last idle read was tried, answered or not
        self.bridge: MqttBridge | None = None
        self._next_at: datetime | None = None
        self._next_checked = -1e9
        self._next_key: tuple = ()
        self._curve: tuple[float | None, dict | None] = (None, None)  # (mtime, result)

    # -- StateSource -------------------------------------------------------------------------
    def identity(self) -> DeviceIdentity:
        from ..mqtt.homeassistant.discovery import DeviceIdentity

        d = self.daemon
        try:
            model = f"Kronoterm heat pump, {d.client.generation.value} controller"
        except HeatPumpError:  # not connected yet: announced again once detected
            model = "Kronoterm heat pump (controller not yet detected)"
        return DeviceIdentity(model=model, link=d.cfg.heatpump.link.describe(),
                              sw_version=_VERSION)

    def live(self) -> LiveState:
        from ..mqtt.homeassistant.payloads import LiveState

        d, store = self.daemon, self.daemon.store
        state = LiveState()
        running = store.nights(states=_RUNNING)
        snap, ok = self._idle, self._idle_ok
        last = d.controller.last_snapshot if d.controller else None
        if running:
            night = running[-1]
            state.night_state, state.night_kind, state.night_id = (night.state, night.kind,
                                                                   night.id)
            snap, ok = last, last is not None
        elif last is not None and (self._idle_tried is None
                                   or last.timestamp > self._idle_tried):
            # a night's last sample, newer than any idle read tried: after a failed one it is
            # no longer what the heat pump says now (missing, the link not OK)
            snap, ok = last, True
        if snap is not None:
            state.ts = snap.timestamp
            state.t_air_c = snap.t_air_c.value
            state.t_out_c = snap.t_out_c.value
            state.q_hc_w = snap.q_hc_w.value
            state.energy_el_kwh = snap.energy_electrical_kwh.value
            state.energy_heat_kwh = snap.energy_thermal_kwh.value
        state.next_night_at = self._next_night((state.night_state, state.night_id))
        state.suggested_flow_c = suggested_flow_c(self.last_curve(), state.t_out_c)
        state.link_ok = bool(ok and d._connected.is_set())
        camp = campaign_state(store, d.cfg)
        state.campaign_mode, state.campaign_status = camp.mode, camp.status
        state.campaign_reason = camp.reason
        state.nights_run, state.nights_valid = camp.nights_run, camp.nights_valid
        state.hlc_rel_pct, state.tau_rel_pct = camp.hlc_rel_pct, camp.tau_rel_pct
        if camp.mode == "adaptive":  # "valid/at most" nights
            state.campaign_valid, state.campaign_planned = (camp.nights_valid,
                                                            d.cfg.campaign.max_nights)
        else:
            plan = store.campaign()
            state.campaign_valid = sum(1 for *_, v in plan if v)
            state.campaign_planned = len(plan)
        budget = d.client.budget if d.client else None
        if budget is not None:
            day = d.clock.now().date()
            state.writes = {str(ma): f"{budget.used(ma, day)}/{budget.limit(ma)}"
                            for ma in (2187, 2042)}
        state.skip_tonight = bool(waiting_skips(store))
        state.restore_pending = [e.register for e in store.journal_pending()
                                 if e.register not in _kept(d)]
        return state

    def _next_night(self, night: tuple) -> datetime | None:
        """When the next night's preheat starts (None: nothing to run), re-evaluated when a
        night starts or ends and at most once a minute of wall time otherwise (an adaptive
        campaign's decision reads the fits)."""
        now = time.monotonic()
        d = self.daemon
        skipped = bool(waiting_skips(d.store))   # a skip pressed: the night after it
        key = (*night, skipped)
        if key == self._next_key and now - self._next_checked < _NEXT_NIGHT_S:
            return self._next_at
        self._next_key = key
        from .nights.next_night import peek_next_night
        from .nights.schedule import next_act_time

        try:
            act = next_act_time(d.cfg, d.clock.now())
            if skipped:   # (a fire time at the instant itself counts: one second on)
                act = next_act_time(d.cfg, act + timedelta(seconds=1))
            req, _ = peek_next_night(d.store, d.cfg, act)
            self._next_at = None if req is None else act
        except Exception as exc:  # noqa: BLE001 - a sensor less, never a failed publish
            _LOG.warning("next night for MQTT not known: %s", exc)
            self._next_at = None
        self._next_checked = now
        return self._next_at

    async def refresh(self) -> None:
        """One snapshot outside a night, if the heat pump is free (never during a night or
        a restore: those hold the heat-pump lock and publish their own samples)."""
        d = self.daemon
        if not d._connected.is_set() or d._heat_pump_lock.locked() or d.stop.is_set():
            return
        async with d._heat_pump_lock:
            self._idle_tried = d.clock.now()
            try:
                self._idle = await d.client.snapshot()
                self._idle_ok = True
                if d.house_inputs is not None:  # the outdoor-sensor check between nights
                    d.house_inputs.record(None, self._idle)
            except (ModbusLinkError, HeatPumpError) as exc:
                if self._idle_ok:
                    _LOG.warning("idle read for MQTT failed: %s", exc)
                self._idle, self._idle_ok = None, False

    def last_fit(self):
        return self.daemon.store.last_fit()

    def last_curve(self) -> dict | None:
        """The kept heating curve (read again when its file changed)."""
        try:
            mtime = curve_path(self.daemon.cfg.state_dir).stat().st_mtime
        except OSError:
            mtime = None
        if mtime != self._curve[0]:
            self._curve = (mtime, None if mtime is None else load_curve(
                self.daemon.cfg.state_dir))
        return self._curve[1]

    def submit(self, command: Command) -> str:
        store = self.daemon.store
        if command.name == "trigger":
            daytime = daytime_reason(self.daemon.cfg, self.daemon.clock.now())
            if command.when == "now" and daytime:
                # The CLI asks for --force here; a button in a household's dashboard has
                # none, so a daytime "now" is refused rather than switching heating off.
                from ..mqtt.commands import BadCommand

                raise BadCommand(f"{daytime}: a 'now' night would run in daytime; send "
                                 "'tonight' instead")
            expires = request_expiry(self.daemon.cfg, self.daemon.clock, command.when)
            rid, joined = queue_night(store, command.kind, command.setpoint_c, command.when,
                                      expires)
            return describe_queued(rid, joined, command.kind, command.setpoint_c,
                                   command.when)
        if command.name == "skip_tonight":  # pressed again: the waiting skip stands
            cid, joined = queue_skip(store, "mqtt")
            return f"command {cid} (skip_tonight) " + ("already waiting" if joined
                                                       else "queued")
        cid = store.add_command(command.name, "mqtt")
        return f"queued command {cid} ({command.name})"

    def note_link(self, state: dict) -> None:
        """The broker link changed: note it in the lock file for ``impctl status``."""
        lock = self.daemon._lock
        if lock is None:
            return
        try:
            lock.note("mqtt", state)
        except OSError as exc:  # status loses a line; MQTT and nights go on
            _LOG.warning("could not note the MQTT link state: %s", exc)

    # -- the daemon's hooks ----------------------------------------------------------------------
    def wake(self) -> None:
        if self.bridge is not None:
            self.bridge.wake()

    async def stop(self) -> None:
        if self.bridge is not None:
            await self.bridge.stop()


def start_mqtt(daemon: RunningDaemon) -> MqttLink | None:
    """Start the bridge when ``[mqtt]`` is configured; None otherwise (nothing imported)."""
    cfg = daemon.cfg
    if cfg.mqtt is None:
        return None
    from ..mqtt.bridge import MqttBridge
    from ..mqtt.homeassistant.discovery import Limits

    lo, hi = cfg.heatpump.writes.loop1_setpoint_c
    link = MqttLink(daemon)
    link.bridge = MqttBridge(
        cfg.mqtt, link,
        Limits(setpoint_min_c=lo, setpoint_max_c=hi,
               comfort_band_k=cfg.night.comfort_band_k,
               default_setpoint_c=cfg.campaign.constrained_setpoint_c),
        clock=daemon.clock)
    link.bridge.on_link_change = link.note_link
    link.bridge.inputs = daemon.house_inputs  # [inputs]: the house's sensors, or None
    link.bridge.start()
    return link


async def run_commands(daemon: RunningDaemon) -> None:
    """Execute queued ``abort`` commands (the 1 s poll); ``skip_tonight`` waits for the
    night job (:func:`skip_tonight`)."""
    store = daemon.store
    for cmd in store.pending_commands("abort"):
        if (daemon.night_running() and daemon.controller is not None
                and not daemon.controller.running):
            # A night is starting (waiting for the heat pump, or about to prepare): the
            # command stays queued until the night can take it, at a later poll.
            continue
        if not store.take_command(cmd.id):
            continue
        reason = f"aborted on request ({cmd.source})"
        if daemon.controller is not None and daemon.controller.abort(reason):
            _LOG.warning("abort requested (%s): ending the night and restoring", cmd.source)
            store.add_event("warning", f"abort requested ({cmd.source}): night ended")
        elif [e for e in store.journal_pending() if e.register not in _kept(daemon)]:
            # No night runs but the owner's settings are not back: restore, as
            # `impctl restore` does.
            _LOG.warning("abort requested (%s): restoring the owner's settings", cmd.source)
            store.add_event("warning", f"abort requested ({cmd.source}): restoring")
            if daemon._connected.is_set() and not daemon._heat_pump_lock.locked():
                # Its own task: this 1 s poll must return at once (a restore may wait for
                # the link); a held lock means a night or the restorer is at it already.
                task = asyncio.create_task(_restore(daemon), name="abort restore")
                _TASKS.add(task)
                task.add_done_callback(_TASKS.discard)
        else:
            _LOG.info("abort requested (%s): no night running, nothing to restore",
                      cmd.source)
        if daemon.mqtt is not None:
            daemon.mqtt.wake()


def _kept(daemon: RunningDaemon) -> frozenset[str]:
    """The registers a restore leaves: the heating curve's while the owner has it set."""
    from .curve.watch import KEEP

    curve = getattr(daemon, "curve", None)
    return KEEP if curve is not None and curve.held is not None else frozenset()


async def _restore(daemon: RunningDaemon) -> None:
    async with daemon._heat_pump_lock:
        await restore_all(daemon.client, daemon.store, clock=VirtualClock.real(),
                          timeout_s=60.0, retry_s=1.0, keep=_kept(daemon))


def skip_tonight(daemon: RunningDaemon) -> bool:
    """True (and the request consumed) when a household asked to skip this night."""
    store = daemon.store
    now = datetime.now(UTC)  # commands are stamped in real time, whatever the night's clock
    skipped = False
    for cmd in store.pending_commands("skip_tonight"):
        if not store.take_command(cmd.id):
            continue
        if now - cmd.created <= timedelta(hours=SKIP_VALID_H):
            skipped = True
    if skipped:
        _LOG.warning("night skipped on request (skip_tonight)")
        store.add_event("info", "night skipped on request")
    return skipped
