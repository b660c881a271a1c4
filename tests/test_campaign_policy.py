"""The adaptive campaign's decision rules (impctl.campaign.policy): stop, skip, order, choice."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

from impctl.campaign import (
    Candidate,
    FitSummary,
    NightRecord,
    Outlook,
    Target,
    decide,
    parse_candidates,
    parse_outlook,
    policy,
)

BAND = (-25.0, 8.0)
KW = dict(forecast_t_out_c=0.0, t_out_band_c=BAND, constrained_setpoint_c=21.0,
          normal_setpoints_c=(21.0, 22.0, 23.0))
C = NightRecord("constrained", 21.0, True)
N = NightRecord("normal", 21.0, True)


def fit(nights: int, hlc_rel: float, tau_rel: float, floor: tuple[float, float] = (0.0, 0.0)
        ) -> FitSummary:
    return FitSummary(nights, 200.0, 200.0 * (1 - hlc_rel), 200.0 * (1 + hlc_rel),
                      50.0, 50.0 * (1 - tau_rel), 50.0 * (1 + tau_rel), *floor)


CANDS = [Candidate("constrained", 21.0, 0.09, 0.09), Candidate("normal", 21.0, 0.07, 0.12),
         Candidate("normal", 22.0, 0.065, 0.10), Candidate("normal", 23.0, 0.08, 0.11)]


def test_default_order_without_a_fit():
    # the order of the balanced and worst-ratio criteria without a fit or predictions
    target = Target()
    KW = {**globals()["KW"], "criterion": "balanced"}
    first = decide([], [], [], target, **KW)
    assert (first.action, first.kind, first.setpoint_c) == ("run", "constrained", 21.0)
    second = decide([C], [], [], target, **KW)
    assert (second.action, second.kind, second.setpoint_c) == ("run", "normal", 21.0)
    # an invalid constrained night is retried, but never right after a constrained night
    bad_c = NightRecord("constrained", 21.0, False)
    assert decide([bad_c], [], [], target, **KW).kind == "normal"
    assert decide([bad_c, N], [], [], target, **KW).kind == "constrained"
    # with one of each but no prediction: two normal nights per constrained one, setpoints
    # in turn
    third = decide([C, N], [fit(2, 0.5, 0.5)], [], target, **KW)
    assert (third.kind, third.setpoint_c) == ("normal", 22.0)
    fourth = decide([C, N, NightRecord("normal", 22.0, True)], [], [], target, **KW)
    assert fourth.kind == "constrained"


def test_choice_by_predicted_worst_ratio(monkeypatch):
    monkeypatch.setattr(policy, "CRITERION", "worst")
    d = decide([C, N], [fit(2, 0.2, 0.3)], CANDS, Target(), **KW)
    # worst ratios: c 0.09/0.05=1.8; n21 0.12/0.08=1.5; n22 max(1.3, 1.25)=1.3; n23 1.6
    assert (d.action, d.kind, d.setpoint_c) == ("run", "normal", 22.0)
    assert "22 °C" in d.reason and not d.reached
    # the same candidates with a τ-heavy target: the constrained night wins
    d = decide([C, N], [fit(2, 0.2, 0.3)], CANDS, Target(hlc_rel=0.5, tau_rel=0.08), **KW)
    assert d.kind == "constrained"


def test_balanced_choice_shrinks_both_half_widths_still_short_of_their_targets(monkeypatch):
    assert policy.CRITERION == "plan"     # the default since h18d
    monkeypatch.setattr(policy, "CRITERION", "balanced")
    # HLC far above its target (its floor): the worst ratio looks only at HLC and takes the
    # night that narrows HLC a little more; balanced takes the one that narrows both
    wide_hlc = fit(3, 0.80, 0.30)
    cands = [Candidate("constrained", 21.0, 0.78, 0.15), Candidate("normal", 23.0, 0.70, 0.29)]
    d = decide([C, N, N], [wide_hlc], cands, Target(), **KW)
    assert (d.kind, d.setpoint_c) == ("constrained", 21.0)
    # log-shrink: c log(.09/.2) + log(.09/.3) = −2.00; n22 log(.325) + log(.333) = −2.22
    assert decide([C, N], [fit(2, 0.2, 0.3)], CANDS, Target(), **KW).setpoint_c == 22.0
    # HLC already within a loose target: only τ counts, the constrained night wins
    d = decide([C, N], [fit(2, 0.2, 0.3)], CANDS, Target(hlc_rel=0.5, tau_rel=0.08), **KW)
    assert d.kind == "constrained"
    monkeypatch.setattr(policy, "CRITERION", "worst")
    assert decide([C, N, N], [wide_hlc], cands, Target(), **KW).kind == "normal"


def test_never_two_constrained_nights_in_a_row():
    best_is_constrained = [Candidate("constrained", 21.0, 0.01, 0.01),
                           Candidate("normal", 23.0, 0.3, 0.3)]
    d = decide([N, C], [fit(2, 0.2, 0.3)], best_is_constrained, Target(), **KW)
    assert (d.kind, d.setpoint_c) == ("normal", 23.0)
    # also when the constrained night was invalid (it still cost the household a night)
    d = decide([N, NightRecord("constrained", 21.0, False)], [fit(1, 0.2, 0.3)],
               best_is_constrained, Target(), **KW)
    assert d.kind == "normal"
    only_constrained = best_is_constrained[:1]
    d = decide([N, C], [fit(2, 0.2, 0.3)], only_constrained, Target(), **KW)
    assert d.kind == "normal"


def test_stop_when_target_reached_needs_each_kind():
    target = Target(min_each=1)
    d = decide([C, N], [fit(2, 0.04, 0.07)], CANDS, target, **KW)
    assert (d.action, d.reached) == ("stop", True)
    assert "Target reached" in d.reason
    # precise enough, but only one valid constrained night when two are required: the
    # short kind goes first even though a normal night is predicted better
    d = decide([C, N, N], [fit(3, 0.04, 0.07)], CANDS, Target(min_each=2), **KW)
    assert d.action == "run" and d.kind == "constrained"
    # one target met, the other not, and a night predicted to help: keep going
    helps = [Candidate("constrained", 21.0, 0.04, 0.07)]
    assert decide([C, N], [fit(2, 0.04, 0.09)], helps, target, **KW).action == "run"


def test_stop_at_max_nights_counts_invalid_nights():
    bad = NightRecord("normal", 22.0, False)
    history = [C, N, bad, bad]
    d = decide(history, [fit(2, 0.3, 0.3)], CANDS, Target(max_nights=4), **KW)
    assert (d.action, d.reached) == ("stop", False)
    assert "4 nights" in d.reason
    assert decide(history[:3], [fit(2, 0.3, 0.3)], CANDS, Target(max_nights=4),
                  **KW).action == "run"


def test_stop_when_intervals_stall():
    target = Target(stall_nights=3, max_nights=20)
    history = [C, N, N, C, N, N]
    stalled = [fit(2, 0.30, 0.30), fit(3, 0.29, 0.30), fit(4, 0.29, 0.29), fit(5, 0.28, 0.28)]
    d = decide(history, stalled, CANDS, target, **KW)
    assert (d.action, d.reached) == ("stop", False)
    assert "cannot be identified" in d.reason
    shrinking = stalled[:3] + [fit(5, 0.20, 0.20)]
    assert decide(history, shrinking, CANDS, target, **KW).action == "run"
    # too few valid nights since the first fit to judge yet
    assert decide(history[:4], stalled[:3], CANDS, target, **KW).action == "run"
    # an interval that cannot be computed (inf) does not count as shrinking
    undetermined = [fit(2, 0.3, 0.3), FitSummary(5, 200.0, math.nan, math.nan, 50, 40, 60)]
    assert decide(history, undetermined, CANDS, target, **KW).action == "stop"


def test_skip_tonight_outside_the_outdoor_band():
    for t_out in (9.0, -30.0):
        d = decide([C], [], [], Target(), **{**KW, "forecast_t_out_c": t_out})
        assert (d.action, d.kind, d.setpoint_c) == ("skip", None, None)
        assert f"{t_out:.1f} °C" in d.reason
    # unknown forecast: run; stop rules come before the band
    assert decide([C], [], [], Target(), **{**KW, "forecast_t_out_c": None}).action == "run"
    d = decide([C, N], [fit(2, 0.01, 0.01)], [], Target(), **{**KW, "forecast_t_out_c": 30.0})
    assert d.action == "stop"


def test_fit_summary_from_fit_json_and_bad_values():
    result = {"lumped": {"hlc": {"value": 200.0, "low": 190.0, "high": 210.0},
                         "tau": {"value": 50.0, "low": 45.0, "high": 55.0}}}
    s = FitSummary.from_fit_json(result, 3)
    assert s.nights == 3
    assert s.hlc_rel == pytest.approx(0.05) and s.tau_rel == pytest.approx(0.10)
    result["lumped"]["tau"]["high"] = None
    assert math.isinf(FitSummary.from_fit_json(result, 3).tau_rel)
    with pytest.raises(ValueError, match="lumped"):
        FitSummary.from_fit_json({"schema": "x"}, 1)
    with pytest.raises(ValueError, match="hlc_rel"):
        Target(hlc_rel=0.0)
    with pytest.raises(ValueError, match="max_nights"):
        Target(max_nights=0)


def test_parse_candidates():
    block = {"forecast_t_out_c": 1.0, "candidates": [
        {"kind": "constrained", "setpoint_c": 21, "hlc_rel_pred": 0.1, "tau_rel_pred": 0.05},
        {"kind": "normal", "setpoint_c": 22.0, "hlc_rel_pred": None, "tau_rel_pred": 0.2}]}
    cands = parse_candidates(block)
    assert cands[0] == Candidate("constrained", 21.0, 0.1, 0.05)
    assert math.isinf(cands[1].hlc_rel_pred)
    # a failed prediction is never chosen
    d = decide([C, N], [fit(2, 0.3, 0.3)], cands[1:] + cands[:1], Target(), **KW,
               criterion="balanced")
    assert d.kind == "constrained"
    for bad, where in (({"candidates": "x"}, "candidates"),
                       ({"candidates": [{"kind": "warm"}]}, r"candidates\[0\]\.kind"),
                       ({"candidates": [{"kind": "normal", "setpoint_c": "22",
                                         "hlc_rel_pred": 1, "tau_rel_pred": 1}]},
                        r"candidates\[0\]\.setpoint_c")):
        with pytest.raises(ValueError, match=where):
            parse_candidates(bad)


def test_package_import_stays_light():
    code = ("import sys, impctl.campaign; "
            "heavy = {'numpy', 'torch', 'pandas', 'sklearn'} & set(sys.modules); "
            "print(sorted(heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"


def test_stop_when_the_floor_makes_the_target_unreachable():
    # sensors/meter alone give HLC ±9 %, τ ±6 %: a ±5 % HLC target is out of reach, and the
    # interval (±11 %) is mostly that floor
    at_floor = fit(2, 0.11, 0.09, floor=(0.09, 0.06))
    # normal nights at two setpoints: the floor rule waits for them (MIN_FLOOR_SETPOINTS)
    TWO_SP = [C, N, NightRecord("normal", 22.0, True)]
    cands = [Candidate("constrained", 21.0, 0.105, 0.08), Candidate("normal", 22.0, 0.10, 0.085)]
    outlook = Outlook(2, 0.097, 0.075, 0.09, 0.06)
    d = decide(TWO_SP, [at_floor], cands, Target(), **KW, outlook=outlook)
    assert (d.action, d.reached) == ("stop", False)
    assert "precision limited by what more nights cannot reduce" in d.reason
    assert "HLC ±9.0%" in d.reason and "±5%" in d.reason
    # without an outlook the fit's own floor decides the same
    assert "precision limited" in decide(TWO_SP, [at_floor], cands, Target(), **KW).reason
    # the same floor, but the interval is still mostly statistics (±40 %): nights still help,
    # the campaign goes on
    wide = fit(2, 0.40, 0.20, floor=(0.09, 0.06))
    helps = [Candidate("constrained", 21.0, 0.35, 0.12), Candidate("normal", 22.0, 0.30, 0.18)]
    d = decide(TWO_SP, [wide], helps, Target(), **KW,
               outlook=Outlook(2, 0.25, 0.12, 0.09, 0.06))
    assert d.action == "run"
    # ... also when two more nights are predicted to bring it down to the floor: those are
    # the nights that get it there
    d = decide(TWO_SP, [wide], helps, Target(), **KW,
               outlook=Outlook(2, 0.10, 0.08, 0.09, 0.06))
    assert d.action == "run"
    # floor_dominance 0: stop as soon as the floor alone misses the target
    d = decide(TWO_SP, [wide], helps, Target(floor_dominance=0.0), **KW,
               outlook=Outlook(2, 0.25, 0.12, 0.09, 0.06))
    assert "precision limited" in d.reason
    with pytest.raises(ValueError, match="floor_dominance"):
        Target(floor_dominance=1.5)
    # a floor below the target never stops on precision: the target is reachable
    low_floor = fit(2, 0.11, 0.09, floor=(0.03, 0.04))
    d = decide(TWO_SP, [low_floor], [Candidate("normal", 22.0, 0.08, 0.07)], Target(), **KW,
               outlook=Outlook(2, 0.06, 0.06, 0.03, 0.04))
    assert d.action == "run"
    # a loose target the floor allows is not "limited" either
    assert decide(TWO_SP, [at_floor], cands, Target(hlc_rel=0.2, tau_rel=0.2), **KW,
                  outlook=outlook).reached


def test_stop_when_the_next_night_would_not_help():
    now = fit(3, 0.30, 0.20)
    little = [Candidate("constrained", 21.0, 0.295, 0.195), Candidate("normal", 22.0, 0.28, 0.20)]
    d = decide([C, N, N], [now], little, Target(), **KW)
    assert (d.action, d.reached) == ("stop", False)
    assert "more nights would not help" in d.reason and "normal night at 22 °C" in d.reason
    # 10 % narrower or more: run it
    enough = [Candidate("normal", 22.0, 0.26, 0.20)]
    assert decide([C, N, N], [now], enough, Target(), **KW).action == "run"
    # no prediction (the fit could not be simulated): nothing to judge, the default order
    assert decide([C, N, N], [now], [], Target(), **KW).action == "run"
    # a fit of one night of each kind is not trusted to say that nights would not help
    first = fit(2, 0.30, 0.20)
    assert decide([C, N], [first], little, Target(), **KW).action == "run"


def test_floor_and_gain_rules_wait_for_one_night_of_each_kind():
    # only normal nights valid so far: the constrained night must come first, whatever the
    # floor and the predicted gain
    bad_c = NightRecord("constrained", 21.0, False)
    at_floor = fit(2, 0.11, 0.09, floor=(0.09, 0.06))
    cands = [Candidate("constrained", 21.0, 0.105, 0.085), Candidate("normal", 22.0, 0.11, 0.09)]
    d = decide([bad_c, N, N], [at_floor], cands, Target(), **KW,
               outlook=Outlook(2, 0.10, 0.08, 0.09, 0.06))
    assert (d.action, d.kind) == ("run", "constrained")


def test_floor_of_a_fit_json():
    result = {"lumped": {"hlc": {"value": 200.0, "low": 180.0, "high": 220.0},
                         "tau": {"value": 50.0, "low": 45.0, "high": 55.0}},
              "fit": {"offset_allowance": {"relative_sd": 0.04, "meter_relative_sd": 0.03,
                                           "night_gain_relative_sd": 0.01,
                                           "structure_relative_sd": {"hlc": 0.02, "tau": 0.0}},
                      "model_error": {"group": "slow", "share": {"hlc": 0.0, "tau": 0.05}}}}
    s = FitSummary.from_fit_json(result, 2)
    assert s.hlc_floor_rel == pytest.approx(math.sinh(1.959964 * math.sqrt(
        0.04 ** 2 + 0.03 ** 2 + 0.01 ** 2 + 0.02 ** 2)))
    assert s.tau_floor_rel == pytest.approx(math.sinh(1.959964 * math.sqrt(
        0.04 ** 2 + 0.01 ** 2 + 0.05 ** 2)))
    # the reason names the largest share of the floor that misses the target most
    assert s.hlc_floor_by == "the room and outdoor sensors' offsets"
    assert s.tau_floor_by == "the model's error on houses like this one"
    d = decide([C, N, NightRecord("normal", 22.0, True)], [s], [],
               Target(hlc_rel=0.5, tau_rel=0.06), **KW)
    assert d.reason.startswith("Stopped: precision limited by the model's error on houses "
                               "like this one: HLC ±")
    # an older fit states no shares: no floor, the rule never fires
    del result["fit"]
    assert FitSummary.from_fit_json(result, 2).hlc_floor_rel == 0.0


def test_parse_outlook():
    block = {"candidates": [], "outlook": {"nights": 2, "hlc_rel_pred": 0.1,
                                           "tau_rel_pred": None, "hlc_floor_rel": 0.08,
                                           "tau_floor_rel": 0.05}}
    o = parse_outlook(block)
    assert (o.nights, o.hlc_rel_pred, o.hlc_floor_rel) == (2, 0.1, 0.08)
    assert math.isinf(o.tau_rel_pred)
    assert parse_outlook({"candidates": []}) is None
    for bad, where in (({"outlook": 3}, "outlook is not"),
                       ({"outlook": {**block["outlook"], "nights": 0}}, "outlook.nights"),
                       ({"outlook": {**block["outlook"], "hlc_floor_rel": -1}},
                        "outlook.hlc_floor_rel")):
        with pytest.raises(ValueError, match=where):
            parse_outlook(bad)


def test_plan_criterion_runs_a_prefix_of_the_fixed_plan():
    assert policy.plan_order(21.0, (22.0, 23.0, 24.0), warmest_first=False) == (
        ("constrained", 21.0), ("normal", 22.0), ("constrained", 21.0), ("normal", 23.0),
        ("normal", 24.0))
    plan = policy.plan_order(21.0, (22.0, 23.0, 24.0))
    assert plan == (("constrained", 21.0), ("normal", 24.0), ("constrained", 21.0),
                    ("normal", 23.0), ("normal", 22.0))
    # the default plan: 2 constrained nights, one per setpoint
    kw = {**KW, "normal_setpoints_c": (22.0, 23.0, 24.0), "criterion": "plan"}
    n22, n23 = NightRecord("normal", 24.0, True), NightRecord("normal", 23.0, True)
    # the best predicted night is normal at 23 °C; the plan's next night is constrained
    cands = [Candidate("constrained", 21.0, 0.5, 0.5), Candidate("normal", 22.0, 0.4, 0.4),
             Candidate("normal", 23.0, 0.1, 0.1), Candidate("normal", 24.0, 0.4, 0.4)]
    seen = []
    history: list[NightRecord] = []
    for _ in range(5):
        d = decide(history, [fit(2, 0.6, 0.6)] if len(history) >= 2 else [], cands,
                   Target(), **kw)
        assert d.action == "run" and "fixed plan" in d.reason
        seen.append((d.kind, d.setpoint_c))
        history.append(NightRecord(d.kind, d.setpoint_c, True))
    assert tuple(seen) == plan
    assert decide(history, [fit(5, 0.6, 0.6)], cands, Target(), **kw).action == "stop"
    # an invalid constrained night is repeated, never right after a constrained night
    bad_c = NightRecord("constrained", 21.0, False)
    d = decide([C, n22, bad_c], [fit(2, 0.6, 0.6)], cands, Target(), **kw)
    assert (d.kind, d.setpoint_c) == ("normal", 23.0) and "in a row" in d.reason
    d = decide([C, n22, bad_c, n23], [fit(3, 0.6, 0.6)], cands, Target(), **kw)
    assert (d.kind, d.setpoint_c) == ("constrained", 21.0)
    # also when the first night was an invalid constrained one (no fit, every kind short),
    # and after two in a row (the daemon's fixed plan since h18g waits the same way)
    for history in ([bad_c], [bad_c, bad_c], [NightRecord("normal", 24.0, True), bad_c]):
        d = decide(history, [], cands, Target(), **kw)
        assert (d.action, d.kind) == ("run", "normal"), history
    # a kind short of min_each goes first
    d = decide([C, n22, n23], [fit(3, 0.04, 0.07)], cands, Target(min_each=2), **kw)
    assert (d.action, d.kind) == ("run", "constrained")
    # the stop rules still apply: precise enough after three nights stops
    assert decide([C, n22, C], [fit(3, 0.04, 0.07)], cands, Target(),
                  **kw).reached
    with pytest.raises(ValueError, match="criterion"):
        decide([], [], [], Target(), **{**kw, "criterion": "nonsense"})


def test_spread_criterion_takes_the_setpoint_farthest_from_those_run():
    kw = {**KW, "normal_setpoints_c": (22.0, 23.0, 24.0)}
    n22 = NightRecord("normal", 22.0, True)
    cands = [Candidate("constrained", 21.0, 0.5, 0.5), Candidate("normal", 22.0, 0.2, 0.2),
             Candidate("normal", 23.0, 0.3, 0.3), Candidate("normal", 24.0, 0.35, 0.35)]
    assert decide([C, n22], [fit(2, 0.6, 0.6)], cands, Target(), **kw,
                  criterion="balanced").setpoint_c == 22.0
    d = decide([C, n22], [fit(2, 0.6, 0.6)], cands, Target(), **kw, criterion="spread")
    assert (d.kind, d.setpoint_c) == ("normal", 24.0)
    n24 = NightRecord("normal", 24.0, True)
    d = decide([C, n22, n24], [fit(3, 0.6, 0.6)], cands, Target(), **kw, criterion="spread")
    assert (d.kind, d.setpoint_c) == ("normal", 23.0)


def test_plan_balanced_chooses_among_the_plan_nights_not_yet_run():
    plan = policy.plan_order(21.0, (22.0, 23.0, 24.0))
    kw = {**KW, "normal_setpoints_c": (22.0, 23.0, 24.0), "criterion": "plan_balanced",
          "plan": plan}
    n22, n24 = NightRecord("normal", 22.0, True), NightRecord("normal", 24.0, True)
    cands = [Candidate("constrained", 21.0, 0.5, 0.5), Candidate("normal", 22.0, 0.1, 0.1),
             Candidate("normal", 23.0, 0.3, 0.3), Candidate("normal", 24.0, 0.2, 0.2)]
    # 22 °C is predicted best but already run: the best of the rest, 24 °C
    d = decide([C, n22], [fit(2, 0.6, 0.6)], cands, Target(), **kw)
    assert (d.kind, d.setpoint_c) == ("normal", 24.0)
    # both constrained nights run: only 23 °C is left of the plan
    d = decide([C, n22, C, n24], [fit(4, 0.6, 0.6)], cands, Target(), **kw)
    assert (d.kind, d.setpoint_c) == ("normal", 23.0)


def test_daemon_plan_from_the_campaign_config():
    from impctl.config import CampaignConfig, Config
    from impctl.daemon.nights.adaptive import _plan

    cfg = Config(campaign=CampaignConfig(constrained_setpoint_c=20.0,
                                         normal_setpoints_c=(21.0, 23.0),
                                         normal_nights_per_setpoint=2))
    assert _plan(cfg) == (("constrained", 20.0), ("normal", 23.0), ("constrained", 20.0),
                          ("normal", 23.0), ("normal", 21.0), ("normal", 21.0))
    # counts that leave out a kind: the policy's default plan instead
    assert _plan(Config(campaign=CampaignConfig(constrained_nights=0))) is None


def test_a_raised_max_nights_continues_the_plan_in_its_order():
    # max_nights above the plan's five (h18e's bench): the plan again from its start, never
    # two constrained nights in a row, stopped at max_nights, valid or not
    plan = policy.plan_order(21.0, (22.0, 23.0, 24.0))
    kw = {**KW, "normal_setpoints_c": (22.0, 23.0, 24.0), "criterion": "plan", "plan": plan}
    history: list[NightRecord] = []
    for n in range(8):
        d = decide(history, [fit(max(n, 2), 0.6, 0.6)] if n >= 2 else [], [],
                   Target(max_nights=8), **kw)
        assert d.action == "run", d.reason
        # the 7th night is invalid: repeated as the 8th
        history.append(NightRecord(d.kind, d.setpoint_c, n != 6))
    assert [(n.kind, n.setpoint_c) for n in history] == list(plan) + [
        ("constrained", 21.0), ("normal", 24.0), ("normal", 24.0)]
    d = decide(history, [fit(7, 0.6, 0.6)], [], Target(max_nights=8), **kw)
    assert d.action == "stop" and "max_nights 8" in d.reason


def test_precision_limited_waits_for_normal_nights_at_two_setpoints():
    # h18h: a fit of one constrained and one normal night (c21 n24) is not trusted to say the
    # target is out of reach — nights at a second indoor–outdoor difference separate HLC from
    # the night gain; from the second normal setpoint on the floor rule speaks
    assert policy.MIN_FLOOR_SETPOINTS == 2
    kw = {**KW, "normal_setpoints_c": (22.0, 23.0, 24.0)}
    n24, n23 = NightRecord("normal", 24.0, True), NightRecord("normal", 23.0, True)
    at_floor = fit(2, 0.11, 0.09, floor=(0.09, 0.06))
    # each night still predicted to help by more than 10 % (the gain rule stays quiet)
    cands = [Candidate("constrained", 21.0, 0.09, 0.08), Candidate("normal", 22.0, 0.08, 0.085)]
    outlook = Outlook(2, 0.097, 0.075, 0.09, 0.06)
    d = decide([C, n24], [at_floor], cands, Target(), **kw, outlook=outlook)
    assert (d.action, d.kind) == ("run", "constrained"), d.reason
    # an invalid night at a second setpoint does not count
    bad23 = NightRecord("normal", 23.0, False)
    d = decide([C, n24, C, bad23], [fit(3, 0.11, 0.09, floor=(0.09, 0.06))], cands, Target(),
               **kw, outlook=outlook)
    assert (d.action, d.kind, d.setpoint_c) == ("run", "normal", 23.0), d.reason
    d = decide([C, n24, C, n23], [fit(4, 0.11, 0.09, floor=(0.09, 0.06))], cands, Target(),
               **kw, outlook=outlook)
    assert d.action == "stop" and "precision limited" in d.reason
    # a plan with one normal setpoint: one is all it can have
    d = decide([C, n24], [at_floor], cands, Target(), **{**kw, "normal_setpoints_c": (24.0,)},
               outlook=outlook)
    assert d.action == "stop" and "precision limited" in d.reason
    # the target reached still stops at once
    assert decide([C, n24], [fit(2, 0.04, 0.07)], cands, Target(), **kw).reached
