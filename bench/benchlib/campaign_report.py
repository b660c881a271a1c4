"""The tables of ``bench/campaign.py``: per strategy and target, the paired comparison with
the fixed plan (bootstrap over households) and each campaign's trajectory.

A record is the tuple ``bench/campaign.py``'s workers return per campaign: (strategy,
household, nights run, final FitSummary or None, stop label, fits, stop reason, prediction
checks, ((kind, setpoint °C) of each night run), ((kind, setpoint °C) of each night the final fit
used), decision inputs, the nights run (NightRecord), fit extras, constrained nights ended too
early to be valid).
"""

from __future__ import annotations

import numpy as np

from impctl.campaign import Target

STRATEGIES = {"adaptive": "adaptive", "unreachable": "adaptive, stop when unreachable",
              "order": "fixed order, adaptive stop",
              "warmest": "adaptive, normal at the warmest setpoint",
              "balanced": "adaptive, balanced choice",
              "plan": "adaptive, plan order + early stop",
              "plan_warm": "adaptive, plan order warmest first",
              "spread": "adaptive, balanced + farthest setpoint",
              "plan_balanced": "adaptive, balanced among the plan's nights",
              "h18c": "adaptive, h18c rules (balanced, floor 1/2)",
              "full": "plan continued, no early stop",
              "nn": "adaptive, plan c n24 n22 c n23",
              "full_nn": "plan c n24 n22 c n23 continued, no early stop",
              "wide": "adaptive, plan c n24 c n22 n23",
              "full_wide": "plan c n24 c n22 n23 continued, no early stop",
              "normal_after": "adaptive, plan then normal nights",
              "min3": "adaptive, precision limited from 3 nights",
              "fixed": "fixed 2 + 3",
              "fixed_next": "fixed 2 + 3, retry the next night"}


def label(strategy: str) -> str:
    """"adaptive@8" → "adaptive, max 8 nights"."""
    name, at, n = strategy.partition("@")
    return STRATEGIES[name] + (f", max {n} nights" if at else "")


def _errors(records: list, houses, strategy: str) -> dict[int, tuple[float, float, int]]:
    """Per household with a final fit: (|HLC error| %, |τ error| %, nights run)."""
    out = {}
    for r in records:
        if r[0] == strategy and r[3] is not None:
            h = houses.take(r[1])
            out[r[1]] = (abs(r[3].hlc_w_per_k / h.hlc_w_per_k - 1) * 100,
                         abs(r[3].tau_h / h.tau_h - 1) * 100, r[2])
    return out


def paired(records: list, houses, strategies: list[str], n_boot: int, seed: int = 1,
           margin: float = 1.0) -> None:
    """Each strategy against the fixed plan on the same households: the difference of median
    |error| [percentage points] with a bootstrap 95 % interval (households resampled, pairs
    kept), and the nights each ran.

    "At least the same accuracy" (issue 18) is judged as non-inferiority: the interval's upper
    bound at most ``margin`` points on HLC and on τ. Two campaigns that are equally accurate
    can never show an upper bound ≤ 0, whatever the number of households."""
    print("\nwhat nights each strategy ran (kind at setpoint °C: share of all nights run)")
    for s in strategies:
        count: dict[str, int] = {}
        for r in records:
            if r[0] == s:
                for kind, sp in r[8]:
                    key = f"{kind[0]}{sp:g}"
                    count[key] = count.get(key, 0) + 1
        total = sum(count.values()) or 1
        print(f"  {label(s):<40} " + ", ".join(
            f"{k} {100 * v / total:.0f} %" for k, v in sorted(count.items())))
    if "fixed" not in strategies:
        return
    base = _errors(records, houses, "fixed")
    print("\npaired with fixed 2 + 3 (same households): median |error| difference, "
          "percentage points (strategy − fixed), bootstrap 95 % interval")
    for s in strategies:
        if s == "fixed":
            continue
        mine = _errors(records, houses, s)
        common = sorted(set(mine) & set(base))
        if len(common) < 5:
            continue
        a = np.array([mine[i] for i in common])
        b = np.array([base[i] for i in common])
        cells = []
        diffs = paired_diff(a, b, n_boot, seed)
        for q, name, (d, lo, hi) in zip((0, 1), ("HLC", "τ"), diffs, strict=True):
            wins = np.mean(a[:, q] <= b[:, q]) * 100
            cells.append(f"{name} {d:+.1f} ({lo:+.1f} … {hi:+.1f}), no worse in {wins:.0f} %")
        dn = np.median(a[:, 2]) - np.median(b[:, 2])
        print(f"  {label(s):<40} n={len(common)}: " + "; ".join(cells)
              + f"; nights median {dn:+g}")
        ok = [hi <= margin for _, _, hi in diffs]
        print(f"  {'':<40} non-inferior within {margin:g} points (upper bound ≤ margin): "
              f"HLC {'yes' if ok[0] else 'no'}, τ {'yes' if ok[1] else 'no'}")


def paired_diff(a: np.ndarray, b: np.ndarray, n_boot: int, seed: int = 1
                ) -> list[tuple[float, float, float]]:
    """Difference of median |error| [percentage points], ``a`` − ``b`` (rows: the same
    households; columns 0 HLC, 1 τ), with its bootstrap 95 % interval (households resampled,
    pairs kept; the same resamples for every strategy compared on the same households)."""
    idx = np.random.default_rng(seed).integers(0, len(a), (n_boot, len(a)))
    out = []
    for q in (0, 1):
        d = np.median(a[:, q]) - np.median(b[:, q])
        boot = np.median(a[idx, q], axis=1) - np.median(b[idx, q], axis=1)
        lo, hi = np.percentile(boot, [2.5, 97.5])
        out.append((float(d), float(lo), float(hi)))
    return out


def trajectories(records: list, houses, strategy: str) -> None:
    """Per household: each fit's ±HLC/±τ [%] (floor in brackets), errors, and why it stopped."""
    print(f"\n{label(strategy)}: per household, each fit ±HLC/±τ % [floor] (error %)")
    for r in sorted((r for r in records if r[0] == strategy), key=lambda r: r[1]):
        h = houses.take(r[1])
        steps = " → ".join(
            f"{f.nights}: {100 * f.hlc_rel:.0f}/{100 * f.tau_rel:.0f} "
            f"[{100 * f.hlc_floor_rel:.0f}/{100 * f.tau_floor_rel:.0f}] "
            f"({100 * (f.hlc_w_per_k / h.hlc_w_per_k - 1):+.0f}/"
            f"{100 * (f.tau_h / h.tau_h - 1):+.0f})" for f in r[5])
        print(f"  {r[1]:3d} {r[2]} nights: {steps} — {r[6][:90]}")


def summarise(records: list, houses, target: Target, strategies: list[str]) -> None:
    print(f"\nTarget: HLC ±{target.hlc_rel:.0%}, τ ±{target.tau_rel:.0%} (95 % half-width / "
          f"estimate), max {target.max_nights} nights, stall {target.stall_nights} nights")
    print(f"{'strategy':<40} {'nights med/P90/max':>18} {'reached':>8} {'no fit':>7} "
          f"{'cover HLC/τ':>12} {'|err| HLC/τ %':>14} {'±HLC/τ % med':>13}  stopped by")
    rows = []
    for s in strategies:
        sub = [r for r in records if r[0] == s]
        nights = np.array([r[2] for r in sub])
        got = [r for r in sub if r[3] is not None]
        cov_h, cov_t, err_h, err_t, w_h, w_t = [], [], [], [], [], []
        for _, i, _, f, *_ in got:
            h = houses.take(i)
            cov_h.append(f.hlc_low <= h.hlc_w_per_k <= f.hlc_high)
            cov_t.append(f.tau_low <= h.tau_h <= f.tau_high)
            err_h.append(abs(f.hlc_w_per_k / h.hlc_w_per_k - 1) * 100)
            err_t.append(abs(f.tau_h / h.tau_h - 1) * 100)
            w_h.append(f.hlc_rel * 100)
            w_t.append(f.tau_rel * 100)
        why: dict[str, int] = {}
        for r in sub:
            why[r[4]] = why.get(r[4], 0) + 1

        def pct(x):
            return 100.0 * np.mean(x) if len(x) else float("nan")

        def med(x):
            return float(np.median(x)) if len(x) else float("nan")

        # "reached": the final fit meets the target — also for the fixed plan, which does not
        # stop on it
        met = [r[3] is not None and target.ratio(r[3].hlc_rel, r[3].tau_rel) <= 1 for r in sub]
        reasons = ", ".join(f"{k} {v}" for k, v in sorted(why.items()))
        print(f"{label(s):<40} {np.median(nights):>6.1f} / {np.percentile(nights, 90):<4.1f} / "
              f"{nights.max():<2d} "
              f"{pct(met):>7.0f}% {len(sub) - len(got):>7d} "
              f"{pct(cov_h):>5.0f}/{pct(cov_t):<4.0f}% {med(err_h):>6.1f} / {med(err_t):<5.1f} "
              f"{med(w_h):>5.1f} / {med(w_t):<5.1f}  {reasons}")
        rows.append(f"| {target.hlc_rel:.0%} / {target.tau_rel:.0%} | {label(s)} | "
                    f"{np.median(nights):g} / {np.percentile(nights, 90):g} / {nights.max()} | "
                    f"{pct(met):.0f} % | "
                    f"{pct(cov_h):.0f} / {pct(cov_t):.0f} % | {med(err_h):.1f} / "
                    f"{med(err_t):.1f} % | {med(w_h):.1f} / {med(w_t):.1f} % | {reasons} |")
    print("markdown:\n" + "\n".join(rows))
    checks = np.array([x for r in records if r[0] == "adaptive" for x in r[7]])
    if len(checks):
        q = np.percentile(checks, [10, 50, 90], axis=0)
        print(f"prediction check (adaptive, {len(checks)} nights): refitted / predicted "
              f"half-width after the chosen night, median (P10–P90): HLC {q[1, 0]:.2f} "
              f"({q[0, 0]:.2f}–{q[2, 0]:.2f}), τ {q[1, 1]:.2f} ({q[0, 1]:.2f}–{q[2, 1]:.2f})")


def _mix(fitted: tuple) -> str:
    """A final fit's nights: "1c+3n" (constrained + normal)."""
    c = sum(kind == "constrained" for kind, _ in fitted)
    return f"{c}c+{len(fitted) - c}n"


def by_night_set(records: list, houses, strategies: list[str], top: int = 6) -> None:
    """Coverage of the true HLC and τ by the final interval, per kind mix of the final fit's
    nights and per exact night sequence (the ``top`` most frequent): where intervals miss."""
    print("\ntruth in final interval HLC / τ by the final fit's nights (n: fits)")
    for s in strategies:
        got = [r for r in records if r[0] == s and r[3] is not None]
        for group, key in (("kind mix", lambda r: _mix(r[9])),
                           ("sequence", lambda r: " ".join(f"{k[0]}{sp:g}" for k, sp in r[9]))):
            groups: dict[str, list[tuple[bool, bool]]] = {}
            for r in got:
                h = houses.take(r[1])
                groups.setdefault(key(r), []).append(
                    (r[3].hlc_low <= h.hlc_w_per_k <= r[3].hlc_high,
                     r[3].tau_low <= h.tau_h <= r[3].tau_high))
            ranked = sorted(groups.items(), key=lambda kv: -len(kv[1]))[:top]
            print(f"  {label(s):<32} {group}: " + "; ".join(
                f"{k} n={len(v)} {100 * np.mean([a for a, _ in v]):.0f}/"
                f"{100 * np.mean([b for _, b in v]):.0f} %" for k, v in ranked))


def invalid_nights(records: list, strategies: list[str]) -> None:
    """Per strategy: constrained nights run, how many the gateway ended too early to be valid
    (< MIN_NIGHT_H after the lag: record[13]), how many were invalid on the outdoor band, and
    the households that ended with no valid constrained night (no fit of both kinds)."""
    print("\nconstrained nights per strategy (the gateway's validity: ≥ 3 h after the 1 h lag)")
    print(f"{'strategy':<40} {'run':>5} {'short':>6} {'band':>5} {'households w/o valid c':>23}")
    for s in strategies:
        sub = [r for r in records if r[0] == s]
        hist = [n for r in sub for n in r[11] if n.kind == "constrained"]
        short = sum(r[13] for r in sub)
        bad = sum(not n.valid for n in hist)
        none = sum(not any(n.kind == "constrained" and n.valid for n in r[11]) for r in sub)
        print(f"{label(s):<40} {len(hist):>5d} {short:>6d} {bad - short:>5d} "
              f"{none:>10d} of {len(sub):<4d}")
        print(f"markdown: | {label(s)} | {len(hist)} | {short} | {bad - short} | "
              f"{none} / {len(sub)} |")
