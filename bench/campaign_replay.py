"""Stop rules of the plan-order adaptive campaign replayed offline on ``bench/campaign.py``'s
dump (issue 18, h18e): how many nights, how accurate, against the fixed 2 + 3 plan.

Run:  .venv/bin/python bench/campaign_replay.py DUMP.pkl [--full full@8] [--bootstrap 2000]
          [--rules NAME,...]

``DUMP.pkl`` comes from ``bench/campaign.py --strategies …,full@8,fixed --dump DUMP.pkl``. The
``full@N`` campaigns ran the plan's nights continued in its order (c21 n24 c21 n23 n22 c21 n24
c21 …) with no stop rule but ``max_nights`` and recorded every decision's inputs (night,
forecast, candidates, outlook, fits so far). Every plan-order campaign runs a prefix of those
nights, so a stop rule is replayed exactly by asking :func:`impctl.campaign.decide` — with the
rule's settings — at each recorded decision and stopping at the first "stop" (checked: the
replayed ``adaptive`` and ``adaptive@N`` rows equal ``bench/campaign.py``'s own). Rules that
need more than the policy reads (``veto``: a stop is overruled, the plan's next night runs)
try what the data suggest before any is built into the policy.

Every rule runs on the policy of main before h18h (``MIN_FLOOR_SETPOINTS`` 1) unless it sets
the constant (``msp2@N``: the rule since h18h); ``--plan`` names the ``full`` campaign's order
(``nn``, ``wide``: the orders tried in h18h). The bench's give-up rule (3 invalid nights) is
applied as the bench applies it.

Printed per rule: nights run median / P90 / max (mean), truth inside the final HLC / τ interval,
median |error|, the paired difference of median |error| against the fixed plan (bootstrap 95 %
interval over households) and what stopped the campaigns.
"""

from __future__ import annotations

import argparse
import math
import pickle
import sys
from dataclasses import replace

import numpy as np

from impctl.campaign import decide, policy

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from campaign import BAND_C, CONSTRAINED_C, MAX_INVALID, NORMAL_SETPOINTS, PLANS  # noqa: E402
from campaign_report import paired_diff  # noqa: E402


def _disagree(extras: dict, limit: float, quantity: str = "tau") -> bool:
    """The fit's per-night estimates of ``quantity`` (each night fitted alone: the
    constrained and the normal night) differ by more than ``limit`` (|log| of the largest
    over the smallest)."""
    values = [p["lumped"].get(quantity) for p in extras.get("per_night", [])
              if isinstance(p.get("lumped"), dict)]
    values = [v for v in values if isinstance(v, (int, float)) and v > 0]
    return len(values) >= 2 and math.log(max(values) / min(values)) > limit


def _floor_share(fit) -> float:
    """The floor's share of the worst ratio (HLC's, the one that misses most)."""
    return fit.hlc_floor_rel / fit.hlc_rel if fit.hlc_rel > 0 else 0.0


#: name → (target overrides, policy constants, veto(fits, extras, history) -> bool or None)
RULES: dict[str, tuple[dict, dict, object]] = {}
for _n in (5, 6, 7, 8):
    RULES[f"adaptive@{_n}"] = ({"max_nights": _n}, {}, None)
    RULES[f"min3@{_n}"] = ({"max_nights": _n}, {"MIN_FLOOR_NIGHTS": 3}, None)
    RULES[f"min4@{_n}"] = ({"max_nights": _n}, {"MIN_FLOOR_NIGHTS": 4}, None)
    # stop at 4 valid nights (c n24 c n23) when a stop rule says so, else at max_nights
    RULES[f"four_or_max@{_n}"] = (
        {"max_nights": _n}, {"MIN_FLOOR_NIGHTS": 4},
        (lambda fits, extras, hist: bool(fits) and fits[-1].nights != 4))
    for _lim in (0.3, 0.6, 1.0):
        for _q in ("tau", "hlc"):
            # a stricter stop for houses whose first nights disagree: no stop at 2 nights
            RULES[f"disagree_{_q}{_lim:g}@{_n}"] = (
                {"max_nights": _n}, {},
                (lambda fits, extras, hist, lim=_lim, q=_q: bool(extras)
                 and fits[-1].nights < 3 and _disagree(extras[-1], lim, q)))
    # the model-error group of the two-night fit: no stop at 2 nights for "plain" fits
    RULES[f"not_plain_at_2@{_n}"] = (
        {"max_nights": _n}, {},
        (lambda fits, extras, hist: bool(extras) and fits[-1].nights < 3
         and (extras[-1].get("model_error") or {}).get("group") == "plain"))
    for _lim in (0.4, 0.6, 0.8):
        # both: no stop at 2 when the first nights disagree on τ, none between 3 and max
        RULES[f"disagree_tau{_lim:g}_or_max@{_n}"] = (
            {"max_nights": _n}, {},
            (lambda fits, extras, hist, lim=_lim: bool(fits) and (
                fits[-1].nights >= 3 or _disagree(extras[-1], lim, "tau"))))
    # stop at 2 nights (as adaptive) or at max_nights, never in between
    RULES[f"two_or_max@{_n}"] = (
        {"max_nights": _n}, {}, (lambda fits, extras, hist: bool(fits) and fits[-1].nights >= 3))
    for _share in (0.5, 0.6, 0.7):
        # a minimum of 3 nights when the floor is most of the two-night interval
        RULES[f"min3_share{_share:g}@{_n}"] = (
            {"max_nights": _n}, {},
            (lambda fits, extras, hist, sh=_share: bool(fits) and fits[-1].nights < 3
             and _floor_share(fits[-1]) >= sh))
    for _fd in (0.25, 0.5):
        RULES[f"floor{_fd:g}@{_n}"] = ({"max_nights": _n, "floor_dominance": _fd}, {}, None)
    RULES[f"gain20@{_n}"] = ({"max_nights": _n}, {"MIN_GAIN": 0.2}, None)
    RULES[f"stall2@{_n}"] = ({"max_nights": _n, "stall_nights": 2}, {}, None)


def _setpoints(hist) -> int:
    """Distinct normal setpoints among the valid nights."""
    return len({n.setpoint_c for n in hist if n.valid and n.kind == "normal"})


# h18h, on the fit of stop 24 (one σ per night, the C_m prior): the floor rule's threshold
# again, and "precision limited" only once two normal setpoints were run (vetoes that take the
# stop's reason)
for _n in (5, 6, 8):
    for _fd in (0.2, 0.3, 0.4, 0.45, 0.6, 0.7, 0.8):
        RULES[f"floor{_fd:g}@{_n}"] = ({"max_nights": _n, "floor_dominance": _fd}, {}, None)
    RULES[f"two_sp@{_n}"] = (
        {"max_nights": _n}, {},
        (lambda fits, extras, hist, reason: "precision limited" in reason
         and _setpoints(hist) < 2))
    RULES[f"two_sp_any@{_n}"] = (
        {"max_nights": _n}, {}, (lambda fits, extras, hist, reason: _setpoints(hist) < 2))
    for _fd in (0.25, 0.45, 0.5, 0.6):
        RULES[f"two_sp_floor{_fd:g}@{_n}"] = (
            {"max_nights": _n, "floor_dominance": _fd}, {},
            (lambda fits, extras, hist, reason: "precision limited" in reason
             and _setpoints(hist) < 2))
    RULES[f"three_or_max@{_n}"] = (
        {"max_nights": _n}, {}, (lambda fits, extras, hist: bool(fits) and (
            fits[-1].nights < 3 or fits[-1].nights > 3)))


def _group(extras: list) -> str | None:
    """The latest fit's model-error group (``fit.model_error.group``)."""
    return (extras[-1].get("model_error") or {}).get("group") if extras else None


for _n in (5, 6, 8):
    # "precision limited" waits for two normal setpoints only where the latest fit's
    # model-error group is "plain" (the group whose two-night fits err most on the tuning
    # population, h18h)
    RULES[f"plain_two_sp@{_n}"] = (
        {"max_nights": _n}, {},
        (lambda fits, extras, hist, reason: "precision limited" in reason
         and _setpoints(hist) < 2 and _group(extras) == "plain"))
    RULES[f"two_sp_gain20@{_n}"] = (
        {"max_nights": _n}, {"MIN_GAIN": 0.2},
        (lambda fits, extras, hist, reason: "precision limited" in reason
         and _setpoints(hist) < 2))


for _n in (5, 6, 8):
    # policy.MIN_FLOOR_SETPOINTS (h18h): the product form of two_sp (the gain rule still
    # speaks from 3 nights)
    RULES[f"msp2@{_n}"] = ({"max_nights": _n}, {"MIN_FLOOR_SETPOINTS": 2}, None)
    for _fd in (0.25, 0.45, 0.5):
        RULES[f"msp2_floor{_fd:g}@{_n}"] = ({"max_nights": _n, "floor_dominance": _fd},
                                             {"MIN_FLOOR_SETPOINTS": 2}, None)
    RULES[f"msp2_gain20@{_n}"] = ({"max_nights": _n},
                                   {"MIN_FLOOR_SETPOINTS": 2, "MIN_GAIN": 0.2}, None)


#: the policy constants a rule runs on unless it sets them (main before h18h)
BEFORE_H18H = {"MIN_FLOOR_SETPOINTS": 1}


def _stop_label(reason: str) -> str:
    """A stop reason in a word or two (as ``bench/campaign.py``'s table)."""
    for text, label in (("most this", "max nights"), ("precision limited", "precision limited"),
                        ("would not help", "no gain"), ("cannot be", "cannot be identified"),
                        ("gave up", "gave up"), ("Target reached", "reached")):
        if text in (reason or ""):
            return label
    return reason or "–"


def _veto(veto, fits, extras, hist, reason: str) -> bool:
    if "reason" in veto.__code__.co_varnames[:veto.__code__.co_argcount]:
        return bool(veto(fits, extras, hist, reason))
    return bool(veto(fits, extras, hist))


def replay(rec: tuple, rule: tuple[dict, dict, object], target,
           plan: tuple = PLANS["plan_warm"]) -> tuple[int, object, str]:
    """(nights run, final FitSummary or None, stop reason) of one household under ``rule``,
    its nights in ``plan``'s order (the dump's ``full`` campaign's)."""
    overrides, constants, veto = rule
    # every rule on the policy of main before h18h unless it says otherwise
    constants = {**BEFORE_H18H, **constants}
    target = replace(target, **overrides)
    history, fits, seen, extras = rec[11], rec[5], rec[10], rec[12]
    saved = {k: getattr(policy, k) for k in constants}
    for k, value in constants.items():
        setattr(policy, k, value)
    try:
        h = 0
        for _j, forecast, cands, outlook, n_fits in seen:
            d = decide(history[:h], fits[:n_fits], cands, target, forecast_t_out_c=forecast,
                       t_out_band_c=BAND_C, constrained_setpoint_c=CONSTRAINED_C,
                       normal_setpoints_c=NORMAL_SETPOINTS, outlook=outlook,
                       criterion="plan", plan=plan)
            if (d.action == "stop" and veto is not None and not d.reached
                    and h < target.max_nights and _veto(veto, fits[:n_fits],
                                                        extras[:n_fits], history[:h],
                                                        d.reason)):
                d = replace(d, action="run" if BAND_C[0] <= forecast <= BAND_C[1]
                            else "skip")
            if d.action == "stop":
                return h, (fits[n_fits - 1] if n_fits else None), d.reason
            if d.action == "skip":
                continue
            if h >= len(history):
                break
            h += 1
            if sum(not n.valid for n in history[:h]) >= MAX_INVALID:
                # the give-up rule of the bench's campaigns (daemon.schedule.gave_up)
                valid = sum(n.valid for n in history[:h])
                done = [f for f in fits if f.nights <= valid]
                return h, (done[-1] if done else None), f"gave up: {MAX_INVALID} invalid nights"
        return h, (fits[-1] if fits else None), "ran out of the full campaign's nights"
    finally:
        for k, value in saved.items():
            setattr(policy, k, value)


def _compare(records: list, other_path: str, truth: list, n_boot: int) -> None:
    """Each strategy in both dumps, paired: this dump's median |error| − the other's."""
    with open(other_path, "rb") as fh:
        other = pickle.load(fh)["records"][0]

    def errors(recs, strategy):
        return {r[1]: (abs(r[3].hlc_w_per_k / truth[r[1]][0] - 1) * 100,
                       abs(r[3].tau_h / truth[r[1]][1] - 1) * 100)
                for r in recs if r[0] == strategy and r[3] is not None}

    for strategy in sorted({r[0] for r in records} & {r[0] for r in other}):
        mine, theirs = errors(records, strategy), errors(other, strategy)
        common = sorted(set(mine) & set(theirs))
        (dh, lh, hh), (dt, lt, ht) = paired_diff(np.array([mine[i] for i in common]),
                                                 np.array([theirs[i] for i in common]), n_boot)
        print(f"{strategy}: fitted {len(mine)} here, {len(theirs)} there; paired on "
              f"{len(common)} (here − there): HLC {dh:+.1f} ({lh:+.1f} … {hh:+.1f}), "
              f"τ {dt:+.1f} ({lt:+.1f} … {ht:+.1f}) points")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dump")
    ap.add_argument("--full", default="full@8", help="the dump's no-early-stop strategy")
    ap.add_argument("--bootstrap", type=int, default=2000)
    ap.add_argument("--rules", default=None, help="comma-separated names (default: all)")
    ap.add_argument("--compare", default=None,
                    help="another dump of the same households (e.g. --after-same): each "
                         "strategy both ran, paired (this − that) on the households both fit")
    ap.add_argument("--plan", default="plan_warm",
                    help="the --full campaign's plan (bench/campaign.py PLANS): plan_warm "
                         "(c21 n24 c21 n23 n22) or nn (c21 n24 n22 c21 n23)")
    ap.add_argument("--online-as", default=None,
                    help="the online strategy the replayed adaptive@5 must equal (default "
                         "adaptive)")
    ap.add_argument("--online", default="",
                    help="also these strategies as the bench ran them (comma-separated), "
                         "e.g. normal_after@8, whose nights are not the continued plan's")
    ap.add_argument("--prefixes", action="store_true",
                    help="also every household stopped after the first k valid nights of the "
                         "continued plan, k = 2 … max (no stop rule)")
    args = ap.parse_args()
    with open(args.dump, "rb") as fh:
        dump = pickle.load(fh)
    target, records = dump["targets"][0], dump["records"][0]
    truth = dump["truth"]
    full = {r[1]: r for r in records if r[0] == args.full}
    fixed = {r[1]: r for r in records if r[0] == "fixed" and r[3] is not None}
    online = {}
    for r in records:
        online.setdefault(r[0], {})[r[1]] = r
    if args.compare:
        _compare(records, args.compare, truth, args.bootstrap)
        return
    names = args.rules.split(",") if args.rules else list(RULES)
    print(f"{len(full)} households ({args.full}), {len(fixed)} fixed fits; target "
          f"±{target.hlc_rel:.0%} / ±{target.tau_rel:.0%}")
    print("| rule | nights median / P90 / max (mean) | truth inside HLC / τ | median abs. error "
          "HLC / τ | paired − fixed HLC / τ, pp (95 % interval) | stopped by |")
    print("|---|---|---|---|---|---|")

    def row(name: str, out: dict) -> None:
        nights = np.array([n for n, _, _ in out.values()])
        got = {i: f for i, (_, f, _) in out.items() if f is not None}
        cov = np.mean([[f.hlc_low <= truth[i][0] <= f.hlc_high,
                        f.tau_low <= truth[i][1] <= f.tau_high] for i, f in got.items()],
                      axis=0) * 100
        err = {i: (abs(f.hlc_w_per_k / truth[i][0] - 1) * 100,
                   abs(f.tau_h / truth[i][1] - 1) * 100) for i, f in got.items()}
        med = np.median(np.array(list(err.values())), axis=0)
        common = sorted(set(err) & set(fixed))
        a = np.array([err[i] for i in common])
        b = np.array([(abs(fixed[i][3].hlc_w_per_k / truth[i][0] - 1) * 100,
                       abs(fixed[i][3].tau_h / truth[i][1] - 1) * 100) for i in common])
        (dh, lh, hh), (dt, lt, ht) = paired_diff(a, b, args.bootstrap)
        stops: dict[str, int] = {}
        for _, _, reason in out.values():
            label = _stop_label(reason)
            stops[label] = stops.get(label, 0) + 1
        print(f"| {name} | {np.median(nights):g} / {np.percentile(nights, 90):g} / "
              f"{nights.max()} (mean {nights.mean():.1f}) | {cov[0]:.0f} / {cov[1]:.0f} % | "
              f"{med[0]:.1f} / {med[1]:.1f} % | "
              f"{dh:+.1f} ({lh:+.1f} … {hh:+.1f}) / {dt:+.1f} ({lt:+.1f} … {ht:+.1f}) | "
              + ", ".join(f"{k} {v}" for k, v in sorted(stops.items(), key=lambda x: -x[1]))
              + " |", flush=True)

    row("fixed 2 + 3", {i: (r[2], r[3], r[6]) for i, r in fixed.items()})
    for name in filter(None, args.online.split(",")):
        row(f"{name} (as run)", {i: (r[2], r[3], r[6]) for i, r in online[name].items()})
    if args.prefixes:
        for k in range(2, max(len(r[11]) for r in full.values()) + 1):
            out = {}
            for i, rec in full.items():
                fits = [f for f in rec[5] if f.nights <= k]
                valid = np.cumsum([n.valid for n in rec[11]])
                out[i] = (int(np.searchsorted(valid, k) + 1) if valid[-1] >= k else len(valid),
                          fits[-1] if fits else None, "")
            row(f"first {k} valid nights of the continued plan", out)
    for name in names:
        out = {i: replay(rec, RULES[name], target, PLANS[args.plan]) for i, rec in full.items()}
        same = (args.online_as or "adaptive") if name == "adaptive@5" else name
        if same in online:   # the replay must equal the bench's own campaign
            diff = [i for i, (n, f, _) in out.items()
                    if (n, f) != (online[same][i][2], online[same][i][3])]
            if diff:
                print(f"  ! {name}: replay differs from the online campaign for households "
                      f"{diff[:10]}")
        row(name, out)


if __name__ == "__main__":
    main()
