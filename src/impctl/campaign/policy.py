"""What the adaptive campaign does next: run a night (which kind, which setpoint), skip
tonight, or stop — and one plain sentence saying why.

Standard library only: the daemon imports this module (idle RSS ≤ 60 MB), the predictions it
chooses among come from ``impctl campaign next`` (:mod:`impctl.campaign.design`) run as a
subprocess.

Rules, in order (:func:`decide`):

1. **reached** — stop when the latest fit's 95 % interval half-widths of HLC and τ, relative to
   their estimates, are within the target and at least ``min_each`` valid nights of each kind
   were run.
2. **max_nights** — stop when ``max_nights`` nights were run (valid or not: each one cost the
   household a night).
3. **precision limited** — with a fit of both kinds, stop when the target cannot be reached
   because the interval is dominated by shares no night reduces (type-B: sensor offsets, heat
   meter, night gains, structure and model-error shares, stated in the fit JSON): the worst
   ratio of that *floor* alone is ≥ 1 (the reason names its largest share), the predicted
   worst ratio after the best candidate night and after :attr:`Outlook.nights` more nights is
   still ≥ 1, and the floor already makes up at least a quarter of the latest interval's
   variance (the floor's worst ratio ≥ 0.35 of the latest one,
   :data:`.records.FLOOR_DOMINANT`: the floor is at least an eighth of the variance; tuned
   with the plan order on another population than the bench's, where 1/2 ran a median of 5
   nights and 0.35 a median of 2 at no worse median errors — README "Adaptive campaign", h18d).
   Without predictions the latest fit's own floor and interval are used. Judged from fits of
   :data:`MIN_FLOOR_NIGHTS` valid nights (2; 3 — as rule 4 — was tried in h18c: it lifts the
   coverage of the campaigns that stopped at 2 nights but runs a median of 5 nights, README
   "Adaptive campaign") that include valid normal nights at :data:`MIN_FLOOR_SETPOINTS`
   different setpoints (2 since h18h, fewer when the plan has fewer: on the fit of stop 24
   most campaigns stopped after c21 n24, whose HLC was 4 points worse than the fixed plan's
   on the tuning population; with the plan's order the rule first speaks after c21 n24 c21
   n23).
4. **more nights would not help** — with predictions and a fit of at least 3 valid nights,
   stop when the best candidate night is predicted to shrink the worst ratio by less than
   10 % (:data:`MIN_GAIN`). A fit of one night of each kind is too fragile (its sandwich has
   one degree of freedom) to trust its own prediction that nights would not help.
5. **cannot be identified** — stop when the worst ratio max(hlc_rel/target, tau_rel/target)
   did not shrink by at least 10 % over the last ``stall_nights`` valid nights: more nights of
   the same house are unlikely to help, and the household should not pay for them.
6. **band** — skip tonight (only tonight) when the forecast outdoor temperature is outside the
   outdoor band.
7. **never two constrained nights in a row** — after a constrained night (valid or not) the
   next night run is normal.
8. **choice** — :data:`CRITERION` "plan" (the default since h18d): the fixed plan's nights
   in :func:`plan_order` — a constrained night, the normal nights warmest setpoint first, the
   second constrained night after the first normal one (c21 n24 c21 n23 n22) — so the nights
   run are always a prefix of the fixed plan's, and the stop rules decide how many; an
   invalid night is repeated, kinds still short of ``min_each`` first. The information
   criterion below picked nights the fitted 5R1C finds informative but realistic houses do
   not (h18c: even five adaptive nights were 2.5 points worse on HLC than the plan's).
   With "balanced" or "worst": until a fit exists (or without predictions) a default
   order: a constrained night, a normal night at the first normal setpoint, then two
   normal nights per constrained one (the fixed 2 + 3 plan's ratio), normal setpoints in
   turn. With a fit and predictions:
   the allowed candidate with the largest predicted joint shrink of the half-widths still
   wider than their targets, Σ log(rel_pred/rel) over HLC and τ (:data:`CRITERION` "balanced"; the
   smallest predicted worst ratio max(±HLC/target, ±τ/target) with "worst", which with an HLC
   floor far above its target only ever looks at HLC), kinds still short of ``min_each``
   first. The stop rules judge the worst ratio either way.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from .records import (
    CONSTRAINED,
    KINDS,
    NORMAL,
    Candidate,
    Decision,
    FitSummary,
    NightRecord,
    Outlook,
    Target,
    _num,
)

#: The worst ratio must shrink by at least this fraction over ``stall_nights`` valid nights.
STALL_SHRINK = 0.10
#: "More nights would not help": the best next night must shrink the worst ratio by this much.
MIN_GAIN = 0.10
#: "Precision limited" judges only fits of at least this many valid nights (2: from the first
#: fit of one night of each kind).
MIN_FLOOR_NIGHTS = 2
#: "Precision limited" also waits for valid normal nights at this many different setpoints
#: (fewer when the plan has fewer): nights at different indoor–outdoor differences are what
#: separate HLC from the night gain (h14q), and a fit of one normal setpoint judges its floor
#: too soon (h18h).
MIN_FLOOR_SETPOINTS = 2
#: How the next night is chosen: "plan" — the fixed plan's next night in :func:`plan_order`
#: (the default since h18d); "worst" — the candidate with the smallest predicted worst ratio
#: max(±HLC/target, ±τ/target); "balanced" — the largest predicted joint shrink of the
#: half-widths still wider than their targets, Σ log(predicted/now) over HLC and τ.
CRITERION = "plan"
#: The criteria :func:`decide` knows (``criterion=``): "plan" runs the fixed plan's nights in
#: :func:`plan_order` (the stop rules decide how many); "spread" is "balanced" for the kind and
#: the normal setpoint farthest from those already run.
CRITERIA = ("balanced", "worst", "plan", "spread", "plan_balanced")


def plan_order(constrained_setpoint_c: float, normal_setpoints_c: Sequence[float],
               constrained_nights: int = 2, normal_nights_per_setpoint: int = 1, *,
               warmest_first: bool = True) -> tuple[tuple[str, float], ...]:
    """The fixed plan's nights as (kind, setpoint [°C]) in the order the adaptive campaign runs
    them with ``criterion="plan"``: a constrained night first, then the normal nights —
    warmest setpoint first (the largest indoor–outdoor difference, the farthest from the
    constrained night's: what separates HLC from the night gain soonest), else in the plan's
    order — with one of the remaining constrained nights after each, so that no two
    constrained nights follow each other (2 + 3 at 21; 22, 23, 24 °C: c21 n24 c21 n23 n22).
    Every prefix is a subset of the fixed plan's nights."""
    order = sorted(normal_setpoints_c, reverse=True) if warmest_first else normal_setpoints_c
    normals = [(NORMAL, float(sp)) for sp in order
               for _ in range(max(normal_nights_per_setpoint, 0))]
    left = max(constrained_nights, 0)
    out: list[tuple[str, float]] = []
    if left:
        out.append((CONSTRAINED, float(constrained_setpoint_c)))
        left -= 1
    for night in normals:
        out.append(night)
        if left:
            out.append((CONSTRAINED, float(constrained_setpoint_c)))
            left -= 1
    return tuple(out)


def decide(history: Sequence[NightRecord], fits: Sequence[FitSummary],
           candidates: Sequence[Candidate], target: Target, *,
           forecast_t_out_c: float | None, t_out_band_c: tuple[float, float],
           constrained_setpoint_c: float, normal_setpoints_c: Sequence[float],
           outlook: Outlook | None = None, criterion: str | None = None,
           plan: Sequence[tuple[str, float]] | None = None) -> Decision:
    """The next step of the campaign (rules in the module docstring).

    Parameters
    ----------
    history : the nights run so far, oldest first (valid or not)
    fits : the fits so far, oldest first (``nights`` = valid nights each used)
    candidates : predictions for tonight from ``impctl campaign next`` (may be empty)
    target : precision target and the household's limits
    forecast_t_out_c : tonight's expected mean outdoor temperature [°C]; None = unknown (run)
    t_out_band_c : (low, high) outdoor temperatures [°C] nights may run in
    constrained_setpoint_c, normal_setpoints_c : the configured setpoints [°C]
    outlook : predictions beyond tonight from ``impctl campaign next`` (None: the latest
        fit's own floor is used)
    criterion : how the next night is chosen, one of :data:`CRITERIA` (None:
        :data:`CRITERION`)
    plan : the nights of the fixed plan, in the order "plan" runs them (None:
        :func:`plan_order` of the setpoints with 2 constrained nights, one per setpoint)
    """
    if not normal_setpoints_c:
        raise ValueError("normal_setpoints_c must name at least one setpoint")
    criterion = CRITERION if criterion is None else criterion
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {', '.join(CRITERIA)}, got {criterion!r}")
    run = len(history)
    valid = {k: sum(1 for n in history if n.valid and n.kind == k) for k in KINDS}
    enough_each = all(valid[k] >= target.min_each for k in KINDS)
    latest = fits[-1] if fits else None

    if latest is not None and enough_each and target.ratio(latest.hlc_rel, latest.tau_rel) <= 1:
        return Decision("stop", None, None, _reached_reason(latest, target, run), reached=True)
    if run >= target.max_nights:
        where = (f"; the last fit has {_precision(latest)} (target ±{target.hlc_rel:.0%} / "
                 f"±{target.tau_rel:.0%})" if latest is not None else "; no fit was possible")
        return Decision("stop", None, None,
                        f"Stopped after {run} nights, the most this household agreed to "
                        f"(max_nights {target.max_nights}){where}.")
    after_constrained = bool(history) and history[-1].kind == CONSTRAINED
    allowed = [c for c in candidates if c.kind in KINDS
               and not (after_constrained and c.kind == CONSTRAINED)
               and math.isfinite(_num(c.hlc_rel_pred)) and math.isfinite(_num(c.tau_rel_pred))]
    short = [k for k in KINDS if valid[k] < target.min_each]
    if short:
        preferred = [c for c in allowed if c.kind in short]
        allowed = preferred or allowed
    best = (min(allowed, key=lambda c: (_score(c, latest, target, criterion),
                                        c.kind != NORMAL, c.setpoint_c))
            if allowed else None)
    if best is not None and best.kind == NORMAL and criterion == "spread":
        best = _farthest(allowed, history)
    if latest is not None and enough_each:
        # judged on every candidate: a constrained night not allowed tonight is tomorrow
        usable = [c for c in candidates if c.kind in KINDS and math.isfinite(_num(c.hlc_rel_pred))
                  and math.isfinite(_num(c.tau_rel_pred))]
        best_any = (min(usable, key=lambda c: (target.ratio(c.hlc_rel_pred, c.tau_rel_pred),
                                               c.kind != NORMAL, c.setpoint_c))
                    if usable else None)
        setpoints = len({float(n.setpoint_c) for n in history
                         if n.valid and n.kind == NORMAL})
        limited = (_floor_limited(latest, best_any, outlook, target)
                   if setpoints >= min(MIN_FLOOR_SETPOINTS, len(set(normal_setpoints_c)))
                   else None)
        if limited is not None:
            return Decision("stop", None, None, limited)
        no_gain = _no_gain(latest, best_any, target)
        if no_gain is not None:
            return Decision("stop", None, None, no_gain)
    stalled = _stalled(fits, target)
    if stalled is not None:
        return Decision("stop", None, None, stalled)
    low, high = t_out_band_c
    if forecast_t_out_c is not None and not (low <= forecast_t_out_c <= high):
        return Decision("skip", None, None,
                        f"Skipping tonight: the forecast outdoor temperature "
                        f"{forecast_t_out_c:.1f} °C is outside the band {low:g}–{high:g} °C.")

    if criterion in ("plan", "plan_balanced"):
        choose = ((lambda c: _score(c, latest, target, "balanced"))
                  if criterion == "plan_balanced" and latest is not None else None)
        return _plan_next(history, plan if plan is not None else
                          plan_order(constrained_setpoint_c, normal_setpoints_c),
                          after_constrained, candidates, latest, choose, short)
    if latest is None or best is None:
        return _default(history, valid, after_constrained, constrained_setpoint_c,
                        normal_setpoints_c, latest is None)
    now = target.ratio(latest.hlc_rel, latest.tau_rel)
    then = target.ratio(best.hlc_rel_pred, best.tau_rel_pred)
    rule = " (never two constrained nights in a row)" if after_constrained else ""
    return Decision("run", best.kind, float(best.setpoint_c),
                    f"Next: a {best.kind} night at {best.setpoint_c:g} °C{rule}, predicted to "
                    f"bring HLC to ±{best.hlc_rel_pred:.1%} and τ to ±{best.tau_rel_pred:.1%} "
                    f"(now {_precision(latest)}; worst ratio to target {now:.2f} → {then:.2f}).")


def _plan_next(history: Sequence[NightRecord], plan: Sequence[tuple[str, float]],
               after_constrained: bool, candidates: Sequence[Candidate],
               latest: FitSummary | None, choose=None, short: Sequence[str] = ()
               ) -> Decision:
    """The first night of ``plan`` (repeated when ``max_nights`` exceeds it) not yet run
    validly; a constrained one right after a constrained night waits for the next normal.
    With ``choose`` (a candidate's score, smaller is better): the best-scored of the plan's
    nights not yet run instead of the first. A kind in ``short`` (fewer valid nights than
    ``min_each``) goes first."""
    if not plan:
        raise ValueError("plan must name at least one night")
    done: dict[tuple[str, float], int] = {}
    for n in history:
        if n.valid:
            key = (n.kind, float(n.setpoint_c))
            done[key] = done.get(key, 0) + 1
    todo, cycle = [], []   # the plan's nights not yet run, and which repetition of the plan
    for i, night in enumerate(list(plan) * (len(history) // len(plan) + 2)):
        key = (night[0], float(night[1]))
        if done.get(key, 0) > 0:
            done[key] -= 1
        else:
            todo.append(key)
            cycle.append(i // len(plan))
    first = [k for k in todo if k[0] in short
             and not (after_constrained and k[0] == CONSTRAINED)]
    kind, setpoint = first[0] if first else todo[0]
    if choose is not None and not first:
        left = {key for key, c in zip(todo, cycle, strict=True) if c == cycle[0]}
        scored = [c for c in candidates if (c.kind, float(c.setpoint_c)) in left
                  and not (after_constrained and c.kind == CONSTRAINED)
                  and math.isfinite(_num(c.hlc_rel_pred)) and math.isfinite(_num(c.tau_rel_pred))]
        if scored:
            pick = min(scored, key=lambda c: (choose(c), c.kind != NORMAL, c.setpoint_c))
            kind, setpoint = pick.kind, float(pick.setpoint_c)
    rule = ""
    if kind == CONSTRAINED and after_constrained:
        normal = next((k for k in todo if k[0] == NORMAL), None)
        if normal is not None:
            (kind, setpoint), rule = normal, " (never two constrained nights in a row)"
    pred = next((c for c in candidates if c.kind == kind and c.setpoint_c == setpoint), None)
    said = (f", predicted to bring HLC to ±{_pct(pred.hlc_rel_pred)} and τ to "
            f"±{_pct(pred.tau_rel_pred)} (now {_precision(latest)})"
            if pred is not None and latest is not None else "")
    return Decision("run", kind, float(setpoint),
                    f"Next: a {kind} night at {setpoint:g} °C, the fixed plan's next "
                    f"night{rule}{said}.")


def _farthest(allowed: Sequence[Candidate], history: Sequence[NightRecord]) -> Candidate:
    """The normal candidate whose setpoint is farthest from every valid normal night's so far
    (ties: the warmest): nights at different ΔT separate HLC from the night gain."""
    run = [n.setpoint_c for n in history if n.valid and n.kind == NORMAL]
    normal = [c for c in allowed if c.kind == NORMAL]
    return max(normal, key=lambda c: (min((abs(c.setpoint_c - sp) for sp in run),
                                          default=math.inf), c.setpoint_c))


def _score(c: Candidate, latest: FitSummary | None, target: Target,
           criterion: str = CRITERION) -> float:
    """A candidate's score for the choice (smaller is better): "worst" — the predicted worst
    ratio; otherwise the balanced joint shrink."""
    if criterion != "worst" and latest is not None:
        now = (_num(latest.hlc_rel), _num(latest.tau_rel))
        pred = (_num(c.hlc_rel_pred), _num(c.tau_rel_pred))
        short = [q for q, goal in enumerate((target.hlc_rel, target.tau_rel)) if now[q] > goal]
        if short and all(math.isfinite(x) and x > 0 for x in now + pred):
            # a quantity already within its target needs no more nights
            return sum(math.log(pred[q] / now[q]) for q in short)
    return target.ratio(c.hlc_rel_pred, c.tau_rel_pred)


def _precision(fit: FitSummary | None) -> str:
    if fit is None:
        return "no fit yet"
    return f"HLC ±{_pct(fit.hlc_rel)} and τ ±{_pct(fit.tau_rel)}"


def _pct(x: float) -> str:
    return f"{x:.1%}" if math.isfinite(x) else "unknown"


def _reached_reason(fit: FitSummary, target: Target, run: int) -> str:
    return (f"Target reached after {run} nights ({fit.nights} valid): HLC {fit.hlc_w_per_k:.0f} "
            f"W/K ±{fit.hlc_rel:.1%} (target ±{target.hlc_rel:.0%}), τ {fit.tau_h:.0f} h "
            f"±{fit.tau_rel:.1%} (target ±{target.tau_rel:.0%}).")


def _floor_limited(latest: FitSummary, best: Candidate | None, outlook: Outlook | None,
                   target: Target) -> str | None:
    """The "precision limited" sentence when no number of nights can reach the target."""
    if latest.nights < MIN_FLOOR_NIGHTS:
        return None
    if outlook is not None:
        hlc_floor, tau_floor = outlook.hlc_floor_rel, outlook.tau_floor_rel
        ahead = target.ratio(outlook.hlc_rel_pred, outlook.tau_rel_pred)
    else:
        hlc_floor, tau_floor = latest.hlc_floor_rel, latest.tau_floor_rel
        ahead = target.ratio(latest.hlc_rel, latest.tau_rel)
    floor = target.ratio(hlc_floor, tau_floor)
    now = target.ratio(latest.hlc_rel, latest.tau_rel)
    tonight = (target.ratio(best.hlc_rel_pred, best.tau_rel_pred) if best is not None
               else now)
    if not (math.isfinite(floor) and floor >= 1 and tonight >= 1 and ahead >= 1
            and floor >= target.floor_dominance * now):
        return None
    # name what limits the quantity that misses its target the most
    by = (latest.hlc_floor_by if hlc_floor / target.hlc_rel >= tau_floor / target.tau_rel
          else latest.tau_floor_by) or "what more nights cannot reduce"
    return (f"Stopped: precision limited by {by}: HLC "
            f"±{_pct(hlc_floor)} and τ ±{_pct(tau_floor)} is the best this house can give "
            f"(target ±{target.hlc_rel:.0%} / ±{target.tau_rel:.0%}; now {_precision(latest)}); "
            f"more nights would not reach the target.")


def _no_gain(latest: FitSummary, best: Candidate | None, target: Target) -> str | None:
    """The "more nights would not help" sentence when the best night is predicted to shrink
    the worst ratio by less than :data:`MIN_GAIN`."""
    if best is None or latest.nights < 3:
        return None
    now = target.ratio(latest.hlc_rel, latest.tau_rel)
    then = target.ratio(best.hlc_rel_pred, best.tau_rel_pred)
    if not (math.isfinite(now) and math.isfinite(then)) or then < (1 - MIN_GAIN) * now:
        return None
    return (f"Stopped: more nights would not help — the best next night (a {best.kind} night "
            f"at {best.setpoint_c:g} °C) is predicted to bring HLC to ±{_pct(best.hlc_rel_pred)} "
            f"and τ to ±{_pct(best.tau_rel_pred)} (now {_precision(latest)}; target "
            f"±{target.hlc_rel:.0%} / ±{target.tau_rel:.0%}), less than {MIN_GAIN:.0%} "
            f"narrower.")


def _stalled(fits: Sequence[FitSummary], target: Target) -> str | None:
    """The "cannot be identified" sentence when the worst ratio stopped shrinking."""
    if not fits:
        return None
    latest = fits[-1]
    earlier = [f for f in fits if f.nights <= latest.nights - target.stall_nights]
    if not earlier:
        return None
    before = earlier[-1]
    r_then = target.ratio(before.hlc_rel, before.tau_rel)
    r_now = target.ratio(latest.hlc_rel, latest.tau_rel)
    if math.isfinite(r_now) and r_now < (1 - STALL_SHRINK) * r_then:
        return None
    return (f"Stopped: this house cannot be identified to the target — after "
            f"{latest.nights - before.nights} more valid nights the intervals went from "
            f"{_precision(before)} to {_precision(latest)} (target ±{target.hlc_rel:.0%} / "
            f"±{target.tau_rel:.0%}); more nights are unlikely to help.")


def _default(history: Sequence[NightRecord], valid: dict, after_constrained: bool,
             constrained_setpoint_c: float, normal_setpoints_c: Sequence[float],
             no_fit: bool) -> Decision:
    """The order without predictions: constrained, normal, then the 2 + 3 plan's ratio."""
    n_normal_run = sum(1 for n in history if n.kind == NORMAL)
    want_constrained = (valid[CONSTRAINED] == 0
                        or (valid[NORMAL] > 0 and 3 * valid[CONSTRAINED] < 2 * valid[NORMAL]))
    why = "no fit yet" if no_fit else "no prediction available"
    if want_constrained and not after_constrained:
        return Decision("run", CONSTRAINED, float(constrained_setpoint_c),
                        f"Next: a constrained night at {constrained_setpoint_c:g} °C (default "
                        f"order, {why}).")
    setpoint = float(normal_setpoints_c[n_normal_run % len(normal_setpoints_c)])
    rule = "; never two constrained nights in a row" if want_constrained else ""
    return Decision("run", NORMAL, setpoint,
                    f"Next: a normal night at {setpoint:g} °C (default order, {why}{rule}).")
