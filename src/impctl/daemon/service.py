"""The long-running daemon: orphan sweep, APScheduler jobs, manual triggers, fits, systemd.

Never imports torch, scikit-learn or pandas: classification and the fit run in a subprocess
(``impctl export`` then ``impctl fit``) and only their JSON result comes back.
"""

from __future__ import annotations

import asyncio
import logging
import signal
from datetime import datetime, timedelta
from pathlib import Path

from apscheduler.schedulers.asyncio import AsyncIOScheduler

from ..clock import VirtualClock
from ..config import Config
from ..controller import NightController, NightRefused, NightRequest, restore_all
from ..controller.restore import on_owner_kept
from ..heatpump import HeatPumpClient, HeatPumpError
from ..heatpump.health import HEALTH_FILE
from ..store import Store
from .configured import clock_from_config, open_client, policy_from_config
from .curve.intent import KEEP as CURVE_KEEP
from .curve.intent import owner_kept_point
from .curve.watch import start_curve_watch
from .fitting import fit_ready, needs_fit, refresh_season, run_fit
from .locks.heat_pump import HeatPumpLock
from .locks.store import HEARTBEAT_S, DaemonLock
from .mqtt_link import run_commands, skip_tonight, start_mqtt
from .nights import adaptive
from .nights.next_night import adaptive_tonight, next_campaign_night
from .nights.recording import make_recorder, record_house
from .nights.schedule import (
    accelerated_nights,
    act_trigger,
    campaign_plan,
    drop_expired_requests,
    every_second,
    next_act_time,
    night_needs_h,
    now_window,
    window_after_act,
)
from .restoring import restore_pending, sweep_orphans
from .stopping import shut_down
from .systemd import Notifier

_LOG = logging.getLogger("impctl.daemon")
def _log_crash(task: asyncio.Task) -> None:
    if not task.cancelled() and task.exception() is not None:
        _LOG.error("%s failed", task.get_name(), exc_info=task.exception())


class Daemon:
    """The impctl service.

    Parameters
    ----------
    cfg : Config
    clock : VirtualClock, optional (default from ``cfg.clock``)
    """

    def __init__(self, cfg: Config, clock: VirtualClock | None = None):
        self.cfg = cfg
        self.clock = clock or clock_from_config(cfg)
        self.stop = asyncio.Event()
        self.notifier = Notifier()
        self.store: Store | None = None
        self.client: HeatPumpClient | None = None
        self.controller: NightController | None = None
        self.scheduler: AsyncIOScheduler | None = None
        self._night_task: asyncio.Task | None = None
        self._fit_task: asyncio.Task | None = None
        self._accelerated_task: asyncio.Task | None = None  # nights on a simulated clock
        self._polls: list[asyncio.Task] = []  # the 1 s trigger and command polls
        self._recorder_task: asyncio.Task | None = None  # [record]: the owner recording
        self.recorder = None  # its OwnerRecorder while it runs
        self._connected = asyncio.Event()
        # Held by a night and by the background restore: never both at once (a restore
        # marking an entry done while a night re-journals it would lose the owner's value).
        self._heat_pump_lock = asyncio.Lock()
        self._lock: DaemonLock | None = None  # one process per store (daemon.lock)
        self.mqtt = None  # MqttLink when [mqtt] is configured (issue 17)
        self.house_inputs = None  # HouseInputs when [inputs] is configured
        self.curve = None  # the heating curve's watch (impctl.daemon.curve.watch)

    # -- lifecycle -------------------------------------------------------------------------
    async def run(self) -> int:
        """Run until SIGTERM, SIGINT or SIGHUP; returns the exit status."""
        loop = asyncio.get_running_loop()
        # SIGHUP too: its default ends the process at once, the heat pump as the night left it
        for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
            loop.add_signal_handler(sig, self._request_stop, sig)
        self.store = Store(self.cfg.db_path)
        # a curve point the owner set while impctl's curve was on, kept by any restore of this
        # process (the start's, the background one, a night's, the stop's): no curve until
        # the owner asks again
        on_owner_kept(self.store, owner_kept_point(self.cfg.state_dir))
        try:
            self._lock = DaemonLock(self.cfg.state_dir).acquire()
        except BaseException:
            self.store.close()
            raise
        try:  # one daemon per heat pump, whatever its state directory
            hp_lock = HeatPumpLock(self.cfg.heatpump.link, self.cfg.state_dir).acquire()
        except BaseException:
            self._lock.release()
            self.store.close()
            raise
        try:
            self.client = open_client(self.cfg, self.clock)
            self.controller = NightController(
                self.client, self.store, self.clock, policy_from_config(self.cfg),
                on_status=self._status, stop=self.stop)
            if self.cfg.inputs is not None:  # the house's own sensors, stored per sample
                from .house_inputs import HouseInputs

                self.house_inputs = HouseInputs(self.cfg.inputs, self.clock, self.store)
                self.controller.on_sample = self.house_inputs.record
            taken = self.store.recover_journal()  # what a truncated store lost, if anything
            if taken:
                _LOG.warning("the store had lost the owner's values of %s; taken back from %s",
                             ", ".join(e.register for e in taken), self.store.owner_file)
            if not self.cfg.campaign.adaptive:  # the fixed plan (adaptive: none to keep)
                self.store.set_campaign(campaign_plan(self.cfg))
            orphans = sweep_orphans(self.store)
        except BaseException:  # e.g. a store that cannot write: never keep the lock
            hp_lock.release()
            self._lock.release()
            self.store.close()
            raise
        self.notifier.ready(f"started; {len(orphans)} interrupted night(s) to restore")
        _LOG.info("impctl daemon started (state %s, heat pump %s, clock %r)",
                  self.cfg.state_dir, self.cfg.heatpump.link.describe(), self.clock)
        watchdog = asyncio.create_task(self._watchdog())
        self.mqtt = start_mqtt(self)  # MQTT hook: never awaited by the control loop
        restorer = asyncio.create_task(restore_pending(self), name="background restore")
        restorer.add_done_callback(_log_crash)
        try:
            await self._connect()
            if not self.stop.is_set() and self.store.journal_pending():
                self._status("restoring the owner's settings after an interruption")
                async with self._heat_pump_lock:
                    await restore_all(self.client, self.store, clock=self.clock,
                                      timeout_s=policy_from_config(self.cfg).restore_timeout_s,
                                      retry_s=2.0)
            if not self.stop.is_set():
                self._start_scheduler()
                self._start_recording()
                self.curve = start_curve_watch(self)  # sets nothing unless the owner asks
                if self.cfg.campaign.adaptive or self.cfg.campaign.fit_when_complete:
                    self._want_fit()  # a fit the last run did not finish (stopped mid-fit)
                self._status(self._idle_status())
                await self.stop.wait()
        finally:
            restorer.cancel()
            await shut_down(self)
            watchdog.cancel()
            hp_lock.release()
            self._lock.release()
        return 0

    def _request_stop(self, sig: int) -> None:
        _LOG.info("received %s: stopping (restoring first if a night runs)",
                  signal.Signals(sig).name)
        self.notifier.stopping("stopping: restoring the heat pump if needed")
        self.stop.set()

    async def _connect(self) -> None:
        # Generation evidence and link quirks for `impctl status` (issue 15).
        self.client.health_path = Path(self.cfg.state_dir) / HEALTH_FILE
        failed = False
        # The first try is short, so an unreachable heat pump is reported within seconds.
        wait_s = max(5.0, 3 * self.cfg.heatpump.link.timeout_s)
        while not self.stop.is_set():
            try:
                if not await self._until_stop(self.client.connect(
                        max_wait_s=wait_s if not failed else 30.0)):
                    return  # stop requested while connecting
                self.client.write_health()
                self._connected.set()
                _LOG.info("heat pump connected: %s, generation %s, Q_HC from %s",
                          self.cfg.heatpump.link.describe(), self.client.generation.value,
                          self.client.heat_power_source() or "nowhere (IMP nights refused)")
                return
            except HeatPumpError as exc:
                # Link failures and device exceptions alike (a gateway's 10/11 during the
                # generation probe): keep waiting, never exit; systemd restarts fix nothing.
                if not failed:  # WARNING, so log_level = "warning" shows it; once per outage
                    _LOG.warning("heat pump not reachable: %s; retrying", exc)
                    failed = True
                self._status(f"waiting for the heat pump: {exc}")
                self.client.write_health()
                await asyncio.sleep(1.0)

    async def _until_stop(self, coro) -> bool:
        """Run ``coro`` unless a stop is requested first (then cancel it); True when it ran."""
        work = asyncio.ensure_future(coro)
        stopper = asyncio.ensure_future(self.stop.wait())
        try:
            await asyncio.wait({work, stopper}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            stopper.cancel()
        if not work.done():
            work.cancel()
            await asyncio.gather(work, return_exceptions=True)
            return False
        work.result()
        return True

    def _restorable(self) -> list:
        """Pending journal entries but the heating curve's while the owner has it set."""
        held = self.curve is not None and self.curve.held is not None
        return [e for e in self.store.journal_pending()
                if not (held and e.register in CURVE_KEEP)]


    # -- systemd ---------------------------------------------------------------------------
    def _status(self, text: str) -> None:
        self.notifier.status(text)
        _LOG.debug("status: %s", text)
        if self.mqtt is not None:  # MQTT hook: publish now (every sample during a night)
            self.mqtt.wake()

    def _idle_status(self) -> str:
        if self.cfg.campaign.adaptive:
            st = adaptive.campaign_state(self.store, self.cfg)
            return (f"idle; adaptive campaign {st.nights_valid}/{st.nights_run} valid nights; "
                    f"{st.status}")
        rows = self.store.campaign()
        done = sum(1 for *_, valid in rows if valid)
        return f"idle; campaign {done}/{len(rows)} valid nights"

    async def _watchdog(self) -> None:
        """WATCHDOG=1 only while the event loop runs and the store answers."""
        interval = min((self.notifier.watchdog_interval_s or 30.0) / 2, HEARTBEAT_S)
        while True:
            try:
                if self.store is not None:
                    self.store.nights(states=["active"])  # the store still answers
                self.notifier.watchdog()
                self._lock.heartbeat()  # what `impctl status` shows as alive
            except Exception as exc:  # noqa: BLE001 - a sick store must stop the pings
                _LOG.error("health check failed, withholding the watchdog ping: %s", exc)
            await asyncio.sleep(interval)

    # -- scheduling ------------------------------------------------------------------------
    def night_running(self) -> bool:
        """True from a night's first action (its pre-heat) to the end of its restore."""
        return self._night_task is not None and not self._night_task.done()

    def _start_recording(self) -> None:
        """``[record] enabled``: record the house whenever no IMP night runs."""
        if not self.cfg.record.enabled:
            _LOG.info("owner recording off (record.enabled = false)")
            return
        self.recorder = make_recorder(self)
        self._recorder_task = asyncio.create_task(record_house(self, self.recorder),
                                                  name="owner recording")
        self._recorder_task.add_done_callback(_log_crash)

    def _start_scheduler(self) -> None:
        self.scheduler = AsyncIOScheduler(timezone=self.cfg.timezone)
        grace = int(self.cfg.campaign.misfire_grace_s)
        accelerated = not (self.clock.factor == 1.0
                           and abs(self.clock.epoch_s - self.clock.wall_epoch_s) < 1)
        if not accelerated:
            self.scheduler.add_job(self._night_job, act_trigger(self.cfg), id="imp-night",
                                   replace_existing=True, misfire_grace_time=grace,
                                   coalesce=True, max_instances=1)
        # Manual triggers and household commands (abort, skip_tonight) queued in the store:
        # each second of the loop's monotonic time, never an APScheduler job (APScheduler
        # waits for a wall-clock time; a clock stepped back 3 h would stop them for 3 h).
        self._polls = [
            asyncio.create_task(every_second(self.stop, self._poll_requests, "trigger poll"),
                                name="trigger poll"),
            asyncio.create_task(every_second(self.stop, lambda: run_commands(self),
                                             "command poll"), name="command poll")]
        self.scheduler.start()
        if accelerated:
            self._accelerated_task = asyncio.create_task(accelerated_nights(
                self.cfg, self.clock, self._night_job), name="accelerated nights")
            self._accelerated_task.add_done_callback(_log_crash)
        else:
            job = self.scheduler.get_job("imp-night")
            _LOG.info("next night job at %s (wall clock)", job.next_run_time)

    async def _night_job(self, act: datetime | None = None) -> None:
        if skip_tonight(self):  # a household's skip_tonight, also when a night still runs
            self._status(self._idle_status() + "; tonight skipped on request")
            return
        if self._night_task is not None and not self._night_task.done():
            _LOG.warning("night job skipped: a night is still running")
            return
        if act is None:
            # The preheat time this job was scheduled for, not the moment it fired: fired
            # late (a resume from suspend, a clock stepped forward at boot) within the
            # misfire grace, it is still tonight's night, not the next day's.
            now = self.clock.now()
            scheduled = next_act_time(self.cfg, now - timedelta(
                seconds=self.cfg.campaign.misfire_grace_s + 1))
            act = min(scheduled, now)
        left_h = (window_after_act(act, self.cfg)[1] - self.clock.now()).total_seconds() / 3600
        if left_h < night_needs_h(self.cfg):
            # fired so late (a resume from suspend within the misfire grace) that tonight's
            # window cannot hold a night any more: no night, no write, nothing counted
            _LOG.warning("night job at %s skipped: %.1f h of tonight's window left, less than "
                         "the %g h a night needs", self.clock.now().isoformat(),
                         max(left_h, 0.0), night_needs_h(self.cfg))
            return
        if self.cfg.campaign.adaptive and self.cfg.campaign.enabled:
            fit_running = self._fit_task is not None and not self._fit_task.done()
            req = adaptive_tonight(self.store, self.cfg, act, fit_running)
        else:
            req = next_campaign_night(self.store, self.cfg, act)
        if req is None:
            self._status(self._idle_status() + "; nothing to run tonight")
            return
        await self._run_night(req)

    async def _poll_requests(self) -> None:
        if self.stop.is_set() or (self._night_task is not None and not self._night_task.done()):
            return
        drop_expired_requests(self.store, self.clock.now())
        for req in self.store.pending_requests():
            if req.when != "now":
                continue
            window = now_window(self.cfg, self.clock.now(), bool(req.extra.get("forced")))
            if isinstance(window, str):
                if self.store.close_request(req.id, "refused"):
                    _LOG.warning("manual trigger %d not run: %s", req.id, window)
                    self.store.add_event("warning", f"request {req.id} not run: {window}")
                continue
            if not self.store.take_request(req.id):
                continue
            start, end = window
            sp = req.setpoint_c if req.setpoint_c is not None else (
                self.cfg.campaign.constrained_setpoint_c)
            _LOG.info("manual trigger %d: %s night at %.1f °C now", req.id, req.kind, sp)
            # Its own task, so this 1 s poll returns at once (the commands are polled
            # beside it all night).
            self._night_task = asyncio.create_task(self._run_night(NightRequest(
                req.kind, sp, start, end, self.cfg.night.comfort_band_k,
                source="trigger")), name=f"manual night {req.id}")
            self._night_task.add_done_callback(_log_crash)
            return

    async def _run_night(self, req: NightRequest) -> None:
        self._night_task = asyncio.current_task()
        async with self._heat_pump_lock:
            try:
                night = await self.controller.run(req)
            except NightRefused as exc:  # not even created (the store cannot record); logged
                self._status(f"night not started: {exc}")
                return
        self._status(self._idle_status())
        if night.valid and (self.cfg.campaign.adaptive or self.cfg.campaign.fit_when_complete):
            self._want_fit()

    def _want_fit(self) -> None:
        """Fit after a valid night; one fit at a time (the running one refits when done)."""
        if self._fit_task is None or self._fit_task.done():
            self._fit_task = asyncio.create_task(self._fits(), name="fit")
            self._fit_task.add_done_callback(_log_crash)

    def want_season(self) -> None:
        """A new usable owner night: the morning refit of the season model, in the fit's slot
        (one subprocess chain at a time; a running fit reads every night itself)."""
        if self._fit_task is None or self._fit_task.done():
            self._fit_task = asyncio.create_task(self._season(), name="season refit")
            self._fit_task.add_done_callback(_log_crash)

    async def _season(self) -> None:
        await refresh_season(self.store, self.cfg)
        camp = self.cfg.campaign
        if (camp.adaptive or camp.fit_when_complete) and needs_fit(self.store):
            await self._fits()  # a valid night ended while the refit ran: its full fit now

    async def _fits(self) -> None:
        while needs_fit(self.store):
            why = fit_ready(self.store)
            if why is not None:
                _LOG.info("no fit yet: %s", why)
                return
            if await self.run_fit() is None:
                return  # failed (logged); the next valid night tries again

    async def run_fit(self) -> dict | None:
        """Export the valid nights and run ``impctl fit`` (and in adaptive mode ``impctl
        campaign next``) in subprocesses; store the result."""
        n = len(self.store.nights(valid=True))
        self._status(f"fitting {n} nights in a subprocess")
        result = await run_fit(self.store, self.cfg)
        self._status(self._idle_status() + ("; fit stored" if result else "; fit failed"))
        return result
