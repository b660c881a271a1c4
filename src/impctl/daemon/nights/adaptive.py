"""The adaptive campaign on the device: what the policy is told, what it decided.

At each night's act time (``mode = "adaptive"``) the daemon asks
:func:`impctl.campaign.decide` with

* the nights run so far (every finished night, scheduled or triggered, valid or not — each one
  cost the household a night; a *refused* night never touched the heat pump and is left out);
* the fits so far, each with the number of valid nights it used;
* the predictions ``impctl campaign next`` made from the latest fit (none until then);
* the forecast outdoor temperature: the daemon has no weather service, so it is the **mean
  T_out of the most recent night's samples** (said so in the log, the status and the stored
  decision), None before the first night (the controller still refuses a night whose live
  T_out is outside the band);
* the outdoor band ``[night] t_out_min_c``..``t_out_max_c`` and the configured setpoints.

The decision (run / skip tonight / stop) is stored with its reason; ``impctl status`` and Home
Assistant show it. Standard library only: the policy module is stdlib-only too.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from datetime import datetime
from typing import TYPE_CHECKING
from zoneinfo import ZoneInfo

from ...campaign import (
    Candidate,
    Decision,
    FitSummary,
    NightRecord,
    Outlook,
    Target,
    decide,
    parse_candidates,
    parse_outlook,
    plan_order,
)
from ...config import Config
from ...store import Store
from .schedule import (
    RUN_STATES,
    gave_up,
)

if TYPE_CHECKING:
    from ...store import CampaignDecision

_LOG = logging.getLogger("impctl.daemon")


@dataclass(frozen=True)
class Forecast:
    """Tonight's expected mean outdoor temperature [°C] (None = unknown) and its source."""

    t_out_c: float | None
    source: str


def target(cfg: Config) -> Target:
    """The precision target and household limits of ``[campaign]``."""
    camp = cfg.campaign
    return Target(hlc_rel=camp.target_rel_halfwidth.hlc, tau_rel=camp.target_rel_halfwidth.tau,
                  max_nights=camp.max_nights, min_each=camp.min_each_kind,
                  stall_nights=camp.stall_nights)


def night_history(store: Store) -> list[NightRecord]:
    """Every finished night that ran, oldest first, with its mean T_out [°C]."""
    means = store.night_t_out_means()
    return [NightRecord(n.kind, n.setpoint_c, bool(n.valid), means.get(n.id))
            for n in store.nights(states=RUN_STATES)]


def fit_history(store: Store) -> list[FitSummary]:
    """The stored fits, oldest first, as the policy reads them."""
    out = []
    for fit in store.fits():
        try:
            out.append(FitSummary.from_fit_json(fit.result, fit.night_count))
        except ValueError as exc:  # a fit stored by an older impctl without intervals
            _LOG.warning("fit %d not usable by the campaign: %s", fit.id, exc)
    return out


def latest_candidates(store: Store) -> tuple[list[Candidate], Outlook | None]:
    """The predictions made from the newest fit: the candidates ([] when none: then the policy
    follows its default order) and the outlook beyond tonight (None when none)."""
    fits = store.fits()
    if not fits or fits[-1].candidates is None:
        return [], None
    try:
        return parse_candidates(fits[-1].candidates), parse_outlook(fits[-1].candidates)
    except ValueError as exc:
        _LOG.warning("stored predictions of fit %d not usable: %s", fits[-1].id, exc)
        return [], None


def forecast(store: Store, cfg: Config) -> Forecast:
    """Mean T_out of the most recent night with outdoor readings (the daemon's own history)."""
    means = store.night_t_out_means()
    for night in reversed(store.nights()):
        if night.id in means:
            local = night.window_start.astimezone(ZoneInfo(cfg.timezone))
            return Forecast(round(means[night.id], 2),
                            f"mean T_out of night {night.id} ({local:%Y-%m-%d})")
    return Forecast(None, "no outdoor reading yet")


def decide_now(store: Store, cfg: Config) -> tuple[Decision, Forecast]:
    """The policy's decision for the next night from what the store holds now.

    Before the policy: after ``campaign.max_invalid_nights`` scheduled nights ended invalid the
    campaign stops, as the fixed plan does (:func:`.schedule.gave_up`): a house whose
    constrained nights keep reaching T_min too early would otherwise pay every night up to
    ``max_nights`` for no fit (bench/RESULTS.md, "Issue 18: the campaign on the gateway's
    nights")."""
    fc = forecast(store, cfg)
    stopped = gave_up(store, cfg)
    if stopped is not None:
        return Decision("stop", None, None, stopped[0].upper() + stopped[1:] + "."), fc
    camp = cfg.campaign
    candidates, outlook = latest_candidates(store)
    decision = decide(night_history(store), fit_history(store), candidates,
                      target(cfg), forecast_t_out_c=fc.t_out_c,
                      t_out_band_c=(cfg.night.t_out_min_c, cfg.night.t_out_max_c),
                      constrained_setpoint_c=camp.constrained_setpoint_c,
                      normal_setpoints_c=camp.normal_setpoints_c, outlook=outlook,
                      plan=_plan(cfg), criterion=CRITERION_OF[camp.next_night])
    return decision, fc


#: ``[campaign] next_night`` → :func:`impctl.campaign.decide`'s criterion.
CRITERION_OF = {"plan": "plan", "information": "balanced"}


def _plan(cfg: Config) -> tuple[tuple[str, float], ...] | None:
    """The fixed plan's nights in the order the adaptive campaign runs them; None (the
    policy's default plan) when the configured counts leave out a kind."""
    camp = cfg.campaign
    plan = plan_order(camp.constrained_setpoint_c, camp.normal_setpoints_c,
                      camp.constrained_nights, camp.normal_nights_per_setpoint)
    return plan if {kind for kind, _ in plan} == {"constrained", "normal"} else None


def record(store: Store, decision: Decision, fc: Forecast, act: datetime) -> None:
    """Store the decision and log it; a stop repeated night after night is kept once."""
    last = store.decisions(1)
    if (decision.action == "stop" and last and last[0].action == "stop"
            and last[0].reason == decision.reason):
        return
    store.add_decision(decision.action, decision.reason, kind=decision.kind,
                       setpoint_c=decision.setpoint_c, reached=decision.reached, act=act,
                       forecast_t_out_c=fc.t_out_c, forecast_source=fc.source)
    forecast_text = ("unknown" if fc.t_out_c is None else f"{fc.t_out_c:.1f} °C") + (
        f" ({fc.source})")
    if decision.action == "run":
        _LOG.info("adaptive campaign: %s Forecast T_out %s.", decision.reason, forecast_text)
        return
    level = logging.WARNING if decision.action == "stop" and not decision.reached else (
        logging.INFO)
    _LOG.log(level, "adaptive campaign: %s Forecast T_out %s.", decision.reason, forecast_text)
    store.add_event("info" if level == logging.INFO else "warning",
                    f"campaign {decision.action}: {decision.reason}")


@dataclass(frozen=True)
class CampaignState:
    """What ``impctl status`` and Home Assistant show of the campaign (both modes).

    ``status`` is short (a Home Assistant state holds at most 255 characters); ``reason`` is
    the policy's full sentence. Relative half-widths in % (None = no fit or undetermined).
    """

    mode: str
    nights_run: int
    nights_valid: int
    hlc_rel_pct: float | None
    tau_rel_pct: float | None
    status: str
    reason: str
    decision: CampaignDecision | None


def rel_pct(x: float) -> float | None:
    """A relative half-width in % (one decimal); None when unknown (infinite)."""
    return round(100 * x, 1) if math.isfinite(x) else None


def absurd(fit: FitSummary) -> bool:
    """An interval from too few nights that is wider than ±100 %: shown as "too few nights
    yet", never as a number (a fit that says it is model-based and stays narrower is shown)."""
    return fit.too_few_nights and not (fit.hlc_rel <= 1.0 and fit.tau_rel <= 1.0)


def campaign_state(store: Store, cfg: Config) -> CampaignState:
    """The campaign as one record (read from the store only)."""
    nights = store.nights(states=RUN_STATES)
    run, valid = len(nights), sum(1 for n in nights if n.valid)
    hlc = tau = None
    last_fit = store.last_fit()  # only the newest: this runs at every MQTT publish
    if last_fit is not None:
        try:
            fit = FitSummary.from_fit_json(last_fit[2], len(last_fit[1]))
            if not absurd(fit):  # hundreds of % from 2 nights: Home Assistant shows unknown
                hlc, tau = rel_pct(fit.hlc_rel), rel_pct(fit.tau_rel)
        except ValueError:
            pass
    last = store.decisions(1)
    decision = last[0] if last else None
    if not cfg.campaign.adaptive:
        plan = store.campaign()
        done = sum(1 for *_, v in plan if v)
        status = (f"fixed plan complete ({done} valid nights)" if plan and done == len(plan)
                  else f"fixed plan: {done}/{len(plan)} valid nights")
        return CampaignState("fixed", run, valid, hlc, tau, status, status, None)
    if decision is None:
        status, reason = "running", "No decision yet: the first night starts the campaign."
    else:
        reason = decision.reason
        if decision.action == "run":
            status = f"running: last chose a {decision.kind} night at {decision.setpoint_c:g} °C"
        elif decision.action == "skip":
            status = "running: last night skipped"
        elif decision.reached:
            status = f"finished: precision reached after {run} nights"
        elif reason.startswith("Campaign stopped:"):   # schedule.gave_up
            status = "stopped: too many invalid nights (max_invalid_nights)"
        elif run >= cfg.campaign.max_nights:
            status = f"stopped: {run} nights, the most allowed (max_nights)"
        elif "precision limited" in reason:
            status = "stopped: precision limited (more nights cannot reach the target)"
        elif "would not help" in reason:
            status = "stopped: more nights would not help"
        else:
            status = "stopped: the house cannot be identified to the target"
    return CampaignState("adaptive", run, valid, hlc, tau, status, reason, decision)
