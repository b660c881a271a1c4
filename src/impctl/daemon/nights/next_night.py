"""Which night runs next: a waiting ``--tonight`` trigger first, then the adaptive policy's
decision or the fixed plan's next entry without a valid night.

Above :mod:`.schedule` (when nights run, the fixed plan's state) and :mod:`.adaptive` (the
policy), which know nothing of each other's choice.
"""

from __future__ import annotations

from datetime import datetime

from ...campaign import Decision
from ...config import Config
from ...controller import NightRequest
from ...store import Store
from .adaptive import decide_now, record
from .schedule import (
    campaign_plan,
    drop_expired_requests,
    gap_start,
    gave_up,
    retry_waits,
    window_after_act,
)


def peek_next_night(store: Store, cfg: Config, act: datetime
                    ) -> tuple[NightRequest | None, int | None]:
    """What the night whose preheat starts at ``act`` would run, without taking anything:
    (request, id of the manual request it comes from or None). A pending ``--tonight``
    trigger (not expired by ``act``) comes first, then the adaptive campaign's decision or the
    first fixed-plan entry without a valid night — a normal one first when the last night run
    was an invalid constrained night (:func:`retry_waits`); (None, None) when there is
    nothing to run."""
    start, end = window_after_act(act, cfg)
    if gap_start(start):   # no such local time tonight: no window (and no request taken)
        return None, None
    band = cfg.night.comfort_band_k
    for req in store.pending_requests():
        if req.when == "tonight" and (req.expires is None or act < req.expires):
            sp = req.setpoint_c if req.setpoint_c is not None else (
                cfg.campaign.constrained_setpoint_c)
            return NightRequest(req.kind, sp, start, end, band, source="trigger"), req.id
    if not cfg.campaign.enabled:
        return None, None
    if cfg.campaign.adaptive:
        decision, _ = decide_now(store, cfg)
        if decision.action != "run":
            return None, None
        return NightRequest(decision.kind, decision.setpoint_c, start, end, band,
                            source="schedule"), None
    if gave_up(store, cfg) is not None:
        return None, None
    # Before the daemon first ran, the store has no plan yet: the configured one is what runs.
    rows = store.campaign() or [(seq, kind, sp, None, None)
                                for seq, (kind, sp) in enumerate(campaign_plan(cfg))]
    todo = [(seq, kind, sp) for seq, kind, sp, _night_id, valid in rows if not valid]
    if retry_waits(store):
        todo.sort(key=lambda entry: entry[1] != "normal")   # stable: the plan's order within
    if todo:
        seq, kind, sp = todo[0]
        return NightRequest(kind, sp, start, end, band, source="schedule",
                            campaign_seq=seq), None
    return None, None


def why_no_night(store: Store, cfg: Config) -> str:
    """Why the next night runs nothing (when :func:`peek_next_night` gave None)."""
    if not cfg.campaign.enabled:
        return "campaign disabled and no manual request"
    if cfg.campaign.adaptive:
        return decide_now(store, cfg)[0].reason
    stopped = gave_up(store, cfg)
    return stopped if stopped is not None else "campaign complete"


def next_campaign_night(store: Store, cfg: Config, act: datetime) -> NightRequest | None:
    """The request for the night whose preheat starts at ``act``: a pending ``--tonight``
    trigger first (taken, so it runs once), else the campaign's next night
    (:func:`peek_next_night`); None when done."""
    drop_expired_requests(store, act)
    while True:
        req, request_id = peek_next_night(store, cfg, act)
        if request_id is None or store.take_request(request_id):
            return req


def adaptive_tonight(store: Store, cfg: Config, act: datetime, fit_running: bool
                     ) -> NightRequest | None:
    """The night job in adaptive mode: a pending ``--tonight`` trigger first; else the policy
    decides (stored, logged, shown), unless the last night's fit is still running
    (``fit_running``). None when nothing runs tonight."""
    drop_expired_requests(store, act)
    if gap_start(window_after_act(act, cfg)[0]):
        return None
    while True:
        req, request_id = peek_next_night(store, cfg, act)
        if request_id is None:
            break
        if store.take_request(request_id):
            return req
    decision, fc = decide_now(store, cfg)
    if fit_running:
        # Deciding on the previous fit would waste the night just run, or record a stop
        # whose reason the last night's fit is about to change — a second, different stop
        # later (never happens in real time: a fit takes minutes, the next act is ~15 h
        # after a night's end).
        decision = Decision("skip", None, None,
                            "Skipping tonight: the fit of the last night is still running.")
    record(store, decision, fc, act)
    if decision.action != "run":
        return None
    start, end = window_after_act(act, cfg)
    return NightRequest(decision.kind, decision.setpoint_c, start, end,
                        cfg.night.comfort_band_k, source="schedule")
