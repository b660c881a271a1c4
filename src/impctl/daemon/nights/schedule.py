"""When nights run: the local window, the campaign plan, real vs accelerated time.

Times: the window is local wall time in the configured zone; every instant handed on is
time zone-aware, and durations are differences of absolute instants (a 22:00–05:00 window
across a DST change lasts 6 or 8 hours).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Awaitable, Callable
from datetime import UTC, datetime, timedelta
from zoneinfo import ZoneInfo

from apscheduler.triggers.cron import CronTrigger

from ...clock import VirtualClock
from ...config import Config
from ...imp.protocol import MIN_NIGHT_H
from ...store import Store

_LOG = logging.getLogger("impctl.daemon")
#: Nights that ran (the heat pump was driven, or the process died during it) and are over.
RUN_STATES = ("done", "aborted", "interrupted")


def campaign_plan(cfg: Config) -> list[tuple[str, float]]:
    """The configured fixed campaign as (kind, T_set °C) entries, constrained nights first
    ([] in adaptive mode: the policy chooses night by night)."""
    camp = cfg.campaign
    if camp.adaptive:
        return []
    plan = [("constrained", camp.constrained_setpoint_c)] * camp.constrained_nights
    for sp in camp.normal_setpoints_c:
        plan += [("normal", sp)] * camp.normal_nights_per_setpoint
    return plan


def window_for(start_local_date, cfg: Config) -> tuple[datetime, datetime]:
    """The night window that starts on ``start_local_date`` (a date), as aware instants."""
    tz = ZoneInfo(cfg.timezone)
    s_min, e_min = cfg.window_minutes
    start = datetime(start_local_date.year, start_local_date.month, start_local_date.day,
                     s_min // 60, s_min % 60, tzinfo=tz)
    end_date = start_local_date + timedelta(days=1 if e_min <= s_min else 0)
    end = datetime(end_date.year, end_date.month, end_date.day, e_min // 60, e_min % 60,
                   tzinfo=tz)
    return start, end


def act_trigger(cfg: Config) -> CronTrigger:
    """Cron trigger of a night's first action: preheat_h before the local window start."""
    s_min, _ = cfg.window_minutes
    act_min = int(round(s_min - cfg.night.preheat_h * 60)) % (24 * 60)
    return CronTrigger(hour=act_min // 60, minute=act_min % 60, timezone=cfg.timezone)


def next_act_time(cfg: Config, now: datetime) -> datetime:
    """The next instant (aware) at which a night's preheat starts, after ``now``."""
    return act_trigger(cfg).get_next_fire_time(None, now)


def gap_start(start: datetime) -> bool:
    """Whether the local time ``start`` (aware, in its zone) does not exist: the clocks skip it
    at the spring DST change (a window "02:00-03:00" would last no time that night)."""
    back = start.astimezone(UTC).astimezone(start.tzinfo)
    return back.replace(tzinfo=None) != start.replace(tzinfo=None)


def window_after_act(act: datetime, cfg: Config) -> tuple[datetime, datetime]:
    """The window that a preheat starting at ``act`` belongs to."""
    local = (act + timedelta(hours=cfg.night.preheat_h) + timedelta(minutes=1)).astimezone(
        ZoneInfo(cfg.timezone))
    return window_for(local.date(), cfg)


#: Shortest sleep of :func:`sleep_until` [s of the loop's time]: a clock on the event loop's
#: own (virtual) time wakes on time up to float rounding, and a sleep shorter than the
#: rounding would not move it, for ever.
_MIN_SLEEP_S = 1e-6


async def sleep_until(clock: VirtualClock, when: datetime) -> float:
    """Sleep on the running event loop until ``clock`` shows ``when``; returns how late it
    woke [simulated s], never early. The loop's sleeps and ``clock`` may drift apart (a clock
    on ``time.time``, sleeps on the monotonic clock): it sleeps again until the clock agrees."""
    while (ahead_s := when.timestamp() - clock.now_s()) > 0:
        await asyncio.sleep(max(clock.wall_seconds(ahead_s), _MIN_SLEEP_S))
    return clock.now_s() - when.timestamp()


async def accelerated_nights(cfg: Config, clock: VirtualClock,
                             night_job: Callable[[datetime], Awaitable[None]]) -> None:
    """Simulated time: the nights' cron rule, evaluated and waited for on the daemon's clock,
    ``night_job(act)`` at each preheat start, until cancelled. Not an APScheduler job:
    APScheduler times jobs on the wall clock, which a late or virtual-time event loop lets
    drift from the simulated one (a night starts hours late or never). A night more than
    ``misfire_grace_s`` (at least 1 s of the loop's time) late is skipped with a warning, as
    APScheduler would.

    On an accelerated wall clock (``[clock] speed``, a dry run on a field gateway) the nights
    are load-sensitive: while the process waits for the CPU simulated time runs on, so a busy
    machine makes a night start late or miss samples. On a clock on a virtual-time loop
    (:meth:`VirtualClock.on_loop`, the demo and the tests) it wakes exactly on time."""
    grace_wall_s = max(1, int(cfg.campaign.misfire_grace_s / clock.factor))
    while True:
        act = next_act_time(cfg, clock.now() + timedelta(seconds=1))
        _LOG.info("next night job at %s (daemon's clock)", act)
        late_s = await sleep_until(clock, act)
        if clock.wall_seconds(late_s) > grace_wall_s:
            _LOG.warning("night job at %s missed by %.0f s (daemon's clock)", act, late_s)
            continue
        # Its own task: cancelling this loop (at shutdown, once the night has restored the
        # heat pump) never cancels a night.
        job = asyncio.create_task(night_job(act), name="night job")
        await asyncio.wait({job})
        if not job.cancelled() and job.exception() is not None:  # as APScheduler logs it
            _LOG.error("night job at %s failed", act, exc_info=job.exception())


async def every_second(stop: asyncio.Event, poll: Callable[[], Awaitable[None]],
                       name: str) -> None:
    """Run ``poll`` once a second of the event loop's time until ``stop`` is set.

    The loop's time is monotonic: a wall-clock step (NTP correcting a clock that ran ahead, a
    wrong ``date -s``) neither stops nor hurries it. A poll that fails is logged, once until
    it works again, and polled again a second later."""
    failed: str | None = None
    while not stop.is_set():
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), timeout=1.0)
        if stop.is_set():
            return
        try:
            await poll()
            failed = None
        except Exception as exc:  # noqa: BLE001 - the next second polls again
            if failed != repr(exc):
                _LOG.error("%s failed; polling on", name, exc_info=exc)
                failed = repr(exc)


def drop_expired_requests(store: Store, now: datetime) -> list[int]:
    """Close the pending manual requests whose expiry (on the daemon's clock) has passed;
    one log line each. Returns their ids."""
    dropped = []
    for req in store.pending_requests():
        if req.expires is not None and now >= req.expires and store.close_request(
                req.id, "expired"):
            _LOG.warning("manual request %d (%s night, %s) expired unstarted at %s; dropped",
                         req.id, req.kind, req.when, req.expires.isoformat())
            store.add_event("warning", f"request {req.id} expired unstarted")
            dropped.append(req.id)
    return dropped


def retry_waits(store: Store) -> bool:
    """Whether the fixed plan's constrained nights wait for a normal night: the last night
    run (scheduled or manual) was a constrained night that ended invalid. A constrained night
    right after a constrained one is more often too short than one after a normal night
    (consecutive nights share the weather, and the house starts colder): on the campaign
    bench's households, retries after a normal night leave 33 of 150 without a valid
    constrained night against 36 retried the next night (bench/RESULTS.md, branch h18g)."""
    last = store.nights(states=RUN_STATES)[-1:]
    return bool(last) and last[0].kind == "constrained" and last[0].valid is False


def gave_up(store: Store, cfg: Config) -> str | None:
    """Why the campaign (fixed or adaptive) stopped repeating nights (None while it goes on): a
    house whose scheduled nights keep ending invalid (a constrained night that reaches T_min
    before 3 h of cooling, every night) would otherwise cost the household a cold night, night
    after night."""
    invalid = [n for n in store.nights(states=RUN_STATES, valid=False) if n.source == "schedule"]
    limit = cfg.campaign.max_invalid_nights
    if len(invalid) < limit:
        return None
    last = invalid[-1]
    why = "; ".join(last.reasons) or "no reason recorded"
    return (f"campaign stopped: {len(invalid)} scheduled nights were not valid (limit "
            f"campaign.max_invalid_nights = {limit}; the last, a {last.kind} night, because: "
            f"{why}). If constrained nights keep reaching T_min too early, a wider "
            f"night.comfort_band_k gives them room; raise the limit to go on")


def campaign_complete(store: Store) -> bool:
    """Every plan entry has a valid night."""
    rows = store.campaign()
    return bool(rows) and all(valid for *_, valid in rows)


def daytime_reason(cfg: Config, now: datetime) -> str | None:
    """Why ``now`` is daytime (outside the night window and its preheat), or None — a
    ``now`` night then needs ``--force`` on the CLI and is refused from Home Assistant."""
    local = now.astimezone(ZoneInfo(cfg.timezone))
    s_min, e_min = cfg.window_minutes
    first = (s_min - round(cfg.night.preheat_h * 60)) % 1440
    minute = local.hour * 60 + local.minute
    inside = (first <= minute < e_min) if first < e_min else (minute >= first or minute < e_min)
    if inside:
        return None
    return (f"it is {local:%H:%M %Z}, outside the night window {cfg.night.window} and its "
            f"{cfg.night.preheat_h:g} h preheat")


def now_window(cfg: Config, now: datetime, forced: bool) -> tuple[datetime, datetime] | str:
    """(window start, window end) of a ``now`` night taken at ``now``, or why it does not
    run. Forced (``--force``): the preheat from now and a whole window's length after it,
    whenever that falls. Else only inside the night window: taken in the window or its
    preheat, it ends when the configured window ends, and a rest shorter than a night needs
    (:data:`~impctl.imp.protocol.MIN_NIGHT_H`) does not run — a request left waiting behind
    another night, or pressed late, never runs into the morning."""
    s_min, e_min = cfg.window_minutes
    start = now + timedelta(hours=cfg.night.preheat_h)
    if forced:
        return start, start + timedelta(minutes=(e_min - s_min) % 1440)
    why = daytime_reason(cfg, now)
    if why is not None:
        return f"{why}; a now night runs in daytime only with --force"
    local = now.astimezone(ZoneInfo(cfg.timezone))
    ends = [window_for(local.date() + timedelta(days=d), cfg)[1] for d in (-1, 0, 1)]
    end = min(e for e in ends if e > now)
    need_h = night_needs_h(cfg)
    if (end - start).total_seconds() < need_h * 3600.0:
        return (f"only {max(0.0, (end - start).total_seconds() / 3600.0):.1f} h of the night "
                f"window {cfg.night.window} left after the {cfg.night.preheat_h:g} h preheat, "
                f"less than the {need_h:g} h a night needs")
    return start, end


def night_needs_h(cfg: Config) -> float:
    """The least of a night window a night is started on [h]: what the fit needs
    (:data:`~impctl.imp.protocol.MIN_NIGHT_H`), or the whole window where it is shorter."""
    s_min, e_min = cfg.window_minutes
    return min(MIN_NIGHT_H, ((e_min - s_min) % 1440) / 60.0)


def request_expiry(cfg: Config, clock: VirtualClock, when: str,
                   expires_h: float | None = None) -> datetime:
    """The instant (daemon's clock) after which the daemon drops a manual request unstarted:
    ``expires_h`` real hours, by default 1 h for ``now`` and the end of its night for
    ``tonight`` — the same rule for the CLI and for commands from Home Assistant."""
    now = clock.now()
    if expires_h is None and when == "tonight":
        return window_after_act(next_act_time(cfg, now), cfg)[1]
    # Real hours: on an accelerated demo clock, as long in simulated time as it takes.
    return now + timedelta(hours=(1.0 if expires_h is None else expires_h) * clock.factor)
