"""bench/fit.py's printed tables: per run (methods side by side, by type of house, the seven
parameters, the issue-14 targets), per model-error group and the closing summary; the statistics
they use (:func:`rel`, :func:`stats`, :func:`half_width`).
"""

from __future__ import annotations

import numpy as np

from benchlib.fit_protocol import house_from
from impctl.fit.intervals import model_error
from impctl.fit.ode.parameters import PARAM_NAMES

#: Issue 14's targets (median |error| %, coverage %, max fit time s); None: reported only.
TARGETS = {
    ("iso", "5-min"): {"hlc": 1.0, "tau": 1.0, "c_m": 3.0, "eps": 3.0, "coverage": 90.0,
                       "time": 1.0},
    ("realistic", "5-min"): {"hlc": 5.0, "tau": 5.0, "c_m": 10.0, "eps": 8.0,
                             "coverage": 90.0, "time": 1.0},
    ("realistic", "other"): {"hlc": None, "tau": None, "c_m": None, "eps": None,
                             "coverage": 85.0, "time": None},
}


def targets(plant: str, step_s: float) -> dict:
    """The issue-14 targets of a run; steps other than 5 minutes are reported (coverage
    ≥ 85 % on the realistic plant, nothing set on the ideal one)."""
    if step_s == 300.0:
        return TARGETS[(plant, "5-min")]
    if plant == "realistic":
        return TARGETS[("realistic", "other")]
    return dict.fromkeys(TARGETS[("iso", "5-min")])


def rel(est, true):
    return 100.0 * (np.asarray(est, float) - np.asarray(true, float)) / np.asarray(true, float)


def half_width(estimates) -> float:
    """Median 95 % interval half-width [% of the estimate], (high − low)/2/value."""
    return float(np.median([100.0 * (e.high - e.low) / (2.0 * e.value) for e in estimates]))


def stats(err) -> tuple[float, float]:
    a = np.abs(np.asarray(err, float))
    a = a[np.isfinite(a)]
    if not len(a):
        return float("nan"), float("nan")
    return float(np.median(a)), float(np.percentile(a, 90))


def _meter_scale_line(fits, meter_gain, t_hlc, t_cm) -> None:
    """HLC and C_m against the truth on the heat meter's scale (truth × (1 + its gain
    error)): what the nights can tell at best; the meter's own error is a type-B share beside
    it (class 3: ±5 %, SD 2.9 % as a uniform), not a fit error."""
    g = 1.0 + np.asarray(meter_gain, float)[:len(fits)]
    parts = []
    for k, t in (("hlc", t_hlc), ("c_m", t_cm)):
        est = [f.lumped_[k] for f in fits]
        scaled = np.asarray(t, float) * g
        e = rel([x.value for x in est], scaled)
        cov = 100.0 * np.mean([x.low <= v <= x.high for x, v in zip(est, scaled, strict=True)])
        med, p90 = stats(e)
        parts.append(f"{'HLC' if k == 'hlc' else 'C_m'} {med:.1f} / {p90:.1f} % "
                     f"(coverage {cov:.0f} %)")
    print("on the heat meter's scale (truth × (1 + its gain error), median / P90): "
          + ", ".join(parts) + "; the meter's ±5 % (SD 2.9 %) is a type-B share beside it")


def report(res: dict, step_s: float, range_source: str, args) -> None:
    truth = res["truth"]
    t_hlc = [h.hlc_w_per_k for h in truth]
    t_tau = [h.tau_h for h in truth]
    t_cm = [h.c_m_j_per_k for h in truth]
    fits = res["fit"]

    def lumped(name):
        return [f.lumped_[name] for f in fits]

    cov = {}
    for name, t in (("hlc", t_hlc), ("tau", t_tau), ("c_m", t_cm)):
        est = lumped(name)
        cov[name] = 100.0 * np.mean([e.low <= v <= e.high for e, v in zip(est, t, strict=True)])
    rows = []
    e_fit = {k: rel([e.value for e in lumped(k)], t)
             for k, t in (("hlc", t_hlc), ("tau", t_tau), ("c_m", t_cm))}
    rows.append(("NODE joint (default)", e_fit["hlc"], e_fit["tau"], e_fit["c_m"],
                 res["eps_fit"], cov, np.median(res["time"])))
    pn = res["per_night_mean"]
    rows.append(("NODE per-night mean", rel([p["lumped"]["hlc"] for p in pn], t_hlc),
                 rel([p["lumped"]["tau"] for p in pn], t_tau),
                 rel([p["lumped"]["c_m"] for p in pn], t_cm), res["eps_pn"], None, None))
    if args.lsq:
        lsq = res["lsq"]
        rows.append(("scipy least_squares (exact)", rel([x["hlc"] for x in lsq], t_hlc),
                     rel([x["tau"] for x in lsq], t_tau), rel([x["c_m"] for x in lsq], t_cm),
                     res["eps_lsq"], None, np.median(res["lsq_time"])))
    coh, ll = np.asarray(res["coh_hlc"]), np.asarray(res["loglin_tau"])
    rows.append(("coheating HLC / log-lin τ / τ·HLC", rel(coh, t_hlc), rel(ll, t_tau),
                 rel(coh * ll * 3600.0, t_cm), res["eps_coh"], None, None))
    mids = [house_from(m) for m in res["mid"]]
    rows.append(("prior midpoint", rel([h.hlc_w_per_k for h in mids], t_hlc),
                 rel([h.tau_h for h in mids], t_tau), rel([h.c_m_j_per_k for h in mids], t_cm),
                 res["eps_mid"], None, None))

    print(f"\n### sample step {step_s:g} s, ranges: {range_source}, "
          f"{len(truth)} households, normal-night model '{args.normal_model}'")
    if "cost" in res:
        print("campaign cost: heat {:.1f} kWh per household (mean, the whole schedule: compare "
              "runs); per night above the day setpoint: {:.2f} h before the window, {:.2f} h in "
              "it, {:.2f} K·h".format(*res["cost"]))
    hits = res["ranges_hit"]
    if hits and hits[0]:
        share = {k: 100.0 * np.mean([h[k] for h in hits]) for k in hits[0]}
        all_in = 100.0 * np.mean([all(h.values()) for h in hits])
        print("true value inside the range used: " + ", ".join(
            f"{k} {v:.0f} %" for k, v in share.items()) + f"; all three {all_in:.0f} %")
        checks = res["class_check"]
        rej = np.array([c["rejected"] for c in checks])
        wrong = np.array([not all(h.values()) for h in hits])
        chi2 = np.array([c.get("chi2", np.nan) for c in checks])
        print(f"class ranges rejected by the likelihood-ratio test: {100 * rej.mean():.0f} % "
              f"of households ({rej[wrong].sum()} of {wrong.sum()} with a wrong class, "
              f"{rej[~wrong].sum()} of {(~wrong).sum()} with right classes); "
              f"median Δχ² right {np.nanmedian(chi2[~wrong]) if (~wrong).any() else np.nan:.1f}"
              f", wrong {np.nanmedian(chi2[wrong]) if wrong.any() else np.nan:.1f}")
    print("| method | HLC med / P90 % | τ med / P90 % | C_m med / P90 % | ε med / P90 % "
          "| coverage HLC/τ/C_m % | time s |")
    print("|---|---|---|---|---|---|---|")
    for name, eh, et, ec, eps, cv, tm in rows:
        cells = [f"{a:.1f} / {b:.1f}" for a, b in (stats(eh), stats(et), stats(ec), stats(eps))]
        cv_s = f"{cv['hlc']:.0f} / {cv['tau']:.0f} / {cv['c_m']:.0f}" if cv else "–"
        tm_s = f"{tm:.2f}" if tm is not None else "–"
        print(f"| {name} | " + " | ".join(cells) + f" | {cv_s} | {tm_s} |")
    signed = ", ".join(f"{k} {np.nanmedian(v):+.1f} % ({np.mean(np.asarray(v) < 0):.0%} low)"
                       for k, v in (("HLC", e_fit["hlc"]), ("τ", e_fit["tau"]),
                                    ("C_m", e_fit["c_m"])))
    print(f"NODE joint, signed median error: {signed}")
    print("NODE joint, median 95 % half-width: " + ", ".join(
        f"{lab} ±{half_width(lumped(k)):.1f} %" for k, lab in (("hlc", "HLC"), ("tau", "τ"),
                                                               ("c_m", "C_m"))))
    if res.get("meter_gain") is not None:
        _meter_scale_line(fits, res["meter_gain"], t_hlc, t_cm)
    _model_error_lines(fits, {"hlc": t_hlc, "tau": t_tau, "c_m": t_cm})
    if args.why and "types" in res:
        ty = res["types"]
        why_table([interval_record(i, step_s, f, {"hlc": t_hlc[i], "c_m": t_cm[i], "tau": t_tau[i]},
                           int(ty["underfloor"][i]), bool(ty["on/off"][i]),
                           int(ty["room thermostat"][i])) for i, f in enumerate(fits)])
    if "types" in res:
        print("\n| NODE joint by type | houses | HLC med / P90 % | τ med / P90 % | C_m med / P90 % "
              "| signed median HLC/τ/C_m % | coverage HLC/τ/C_m % "
              "| median ± half-width HLC/τ/C_m % |")
        print("|---|---|---|---|---|---|---|---|")
        truths = {"hlc": t_hlc, "tau": t_tau, "c_m": t_cm}
        for label, sel in res["types"].items():
            if not sel.any():
                continue
            cells, covs, hws = [], [], []
            for k in ("hlc", "tau", "c_m"):
                cells.append("{:.1f} / {:.1f}".format(*stats(e_fit[k][sel])))
                ests = [e for e, m in zip(lumped(k), sel, strict=True) if m]
                hws.append(half_width(ests))
                tv = np.asarray(truths[k])[sel]
                covs.append(100 * np.mean([e.low <= v <= e.high for e, v in zip(ests, tv,
                                                                                  strict=True)]))
            signed = " / ".join(f"{np.nanmedian(e_fit[k][sel]):+.1f}" for k in ("hlc", "tau",
                                                                                "c_m"))
            print(f"| {label} | {int(sel.sum())} | " + " | ".join(cells) + f" | {signed}"
                  + " | " + " / ".join(f"{c:.0f}" for c in covs) + " | "
                  + " / ".join(f"{h:.0f}" for h in hws) + " |")
    if res.get("eps_floor") is not None:
        print("ε against the true house replayed on the 5R1C (--eps-truth house); the true "
              "parameters against the plant's own heat output: ε median / P90 "
              "{:.1f} / {:.1f} %".format(*stats(res["eps_floor"])))
    t = np.asarray(res["time"])
    print(f"fit time per household: median {np.median(t):.2f} s, max {t.max():.2f} s; "
          "in-sample ε (fitted initial mass temperatures) median "
          f"{np.nanmedian(res['eps_in']):.2f} %")
    if "types" in res:
        print("heat demand ε by type (NODE joint, median / P90 %): " + ", ".join(
            "{} {:.1f} / {:.1f}".format(label, *stats(res["eps_fit"][sel]))
            for label, sel in res["types"].items() if sel.any()))

    print("\n| parameter | true range in population | NODE med / P90 % "
          "| prior midpoint med / P90 % | flagged determined % |")
    print("|---|---|---|---|---|")
    for name in PARAM_NAMES:
        tv = np.array([float(getattr(h, name)) for h in truth])
        # what the fit reports: the prior (range centre) where the data do not determine it
        fv = np.array([(getattr(f, "table_iv_", None) or {}).get(name, {}).get(
            "value", f.parameters_[name]) for f in fits])
        mv = np.array([m[name] for m in res["mid"]])
        det = 100.0 * np.mean([f.determined_[name] for f in fits])
        a, b = stats(rel(fv, tv))
        c, d = stats(rel(mv, tv))
        print(f"| {name} | {tv.min():.3g}–{tv.max():.3g} | {a:.1f} / {b:.1f} | {c:.1f} / {d:.1f} "
              f"| {det:.0f} |")

    med = {k: stats(v)[0] for k, v in e_fit.items()}
    eps_med = stats(res["eps_fit"])[0]
    goal = targets(args.plant, step_s)
    print("\ntargets (median, issue 14): " + ", ".join([
        _verdict("HLC", med["hlc"], goal["hlc"]), _verdict("τ", med["tau"], goal["tau"]),
        _verdict("C_m", med["c_m"], goal["c_m"]), _verdict("ε", eps_med, goal["eps"])]))
    if goal["coverage"] is not None:
        print(f"coverage ≥ {goal['coverage']:g} %: " + ", ".join(
            f"{k} {v:.0f} % {'met' if v >= goal['coverage'] else 'NOT met'}"
            for k, v in cov.items()))
    if goal["time"] is not None:
        print(f"time ≤ {goal['time']:g} s: max {t.max():.2f} s "
              f"{'met' if t.max() <= goal['time'] else 'NOT met'}")


def _model_error_lines(fits, truths: dict) -> None:
    """The interval method and, per model-error group
    (:mod:`impctl.fit.intervals.model_error`), how many
    houses, their coverage and median half-width."""
    me = [getattr(f, "model_error_", None) for f in fits]
    if not any(me):
        print("intervals: measurement only (--no-model-error)")
        return
    first = next(m for m in me if m)
    print(f"intervals: {first['method'].split(', group')[0]}; by group:")
    for group in sorted({m["group"] for m in me if m}):
        sel = [i for i, m in enumerate(me) if m and m["group"] == group]
        cells = []
        for k in ("hlc", "tau", "c_m"):
            ests = [fits[i].lumped_[k] for i in sel]
            cov = 100 * np.mean([e.low <= truths[k][i] <= e.high for e, i in zip(ests, sel,
                                                                                  strict=True)])
            cells.append(f"{k} {cov:.0f} % (±{half_width(ests):.0f} %)")
        share = ", ".join(f"{k} {100 * v:.1f}" for k, v in me[sel[0]]["share"].items())
        print(f"  {group:8s} {len(sel):3d} houses, share (log SD %) {share}: coverage "
              + "; ".join(cells))


def _verdict(name, value, target):
    if target is None:
        return f"{name} {value:.1f} % (reported)"
    return f"{name} {value:.1f} % {'met' if value <= target else 'NOT met'} (≤ {target:g} %)"


def summary_row(res: dict, step_s: float, source: str) -> dict:
    """The NODE joint fit's figures of one (sample step, range source) run."""
    truth = res["truth"]
    true = {"hlc": [h.hlc_w_per_k for h in truth], "tau": [h.tau_h for h in truth],
            "c_m": [h.c_m_j_per_k for h in truth]}
    row = {"step_s": step_s, "ranges": source, "n": len(truth)}
    for k, t in true.items():
        est = [f.lumped_[k] for f in res["fit"]]
        row[k] = stats(rel([e.value for e in est], t))
        row[f"cov_{k}"] = 100.0 * np.mean([e.low <= v <= e.high
                                           for e, v in zip(est, t, strict=True)])
        row[f"hw_{k}"] = half_width(est)
    row["eps"] = stats(res["eps_fit"])
    hits = res["ranges_hit"]
    row["classes_right"] = (100.0 * np.mean([all(h.values()) for h in hits])
                            if hits and hits[0] else None)
    t = np.asarray(res["time"])
    row["time"] = (float(np.median(t)), float(t.max()))
    return row


def print_summary(rows: list[dict], args) -> None:
    """One line per sample step and range source: the issue-14 table's NODE rows."""
    if not rows:
        return
    print(f"\n### summary: NODE joint fit, plant {args.plant} (median / P90 of |error|; "
          "coverage of the 95 % intervals)")
    print("| rows | ranges | households | HLC % | τ % | C_m % | ε % | coverage HLC/τ/C_m % "
          "| median ± half-width HLC/τ/C_m % | truth in all three searched class ranges % "
          "| time med / max s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        step = f"{r['step_s'] / 60:g}-min" if r["step_s"] < 3600 else f"{r['step_s'] / 3600:g}-h"
        cells = " | ".join(f"{r[k][0]:.1f} / {r[k][1]:.1f}" for k in ("hlc", "tau", "c_m", "eps"))
        right = "–" if r["classes_right"] is None else f"{r['classes_right']:.0f}"
        print(f"| {step} | {r['ranges']} | {r['n']} | {cells} | {r['cov_hlc']:.0f} / "
              f"{r['cov_tau']:.0f} / {r['cov_c_m']:.0f} | {r['hw_hlc']:.0f} / {r['hw_tau']:.0f} / "
              f"{r['hw_c_m']:.0f} | {right} | {r['time'][0]:.2f} / "
              f"{r['time'][1]:.2f} |")


def gateway_lines(gate: dict, comfort: dict, sched, valid_h: float) -> None:
    """What the gateway's constrained nights give and cost (``bench/fit.py``, stop at T_min):
    invalid nights, repeats, households identified, the household's comfort."""
    n_planned = gate["run"].shape[0] - sched.n_spare
    usable = gate["usable_h"]
    short_planned = usable[:n_planned] < valid_h - 1e-9
    run, used = gate["run"], gate["used"]
    n_used = used.sum(axis=0)
    paid = gate["paid"]
    n_normal = sum(kind == "normal" for _, kind, *_ in sched.windows)
    dist = ", ".join(f"{k}: {int((paid == k).sum())}" for k in range(n_planned, paid.max() + 1))
    print(f"gateway's constrained nights (band ±{sched.band_k:g} K, valid = ≥ {valid_h:g} h after "
          f"the 1 h lag): planned nights too short {short_planned.sum()} of {short_planned.size} "
          f"({100.0 * short_planned.mean():.0f} %); usable hours of the planned nights median "
          f"{np.median(usable[:n_planned]):.1f} h, P10 {np.percentile(usable[:n_planned], 10):.1f}"
          f" h; nights run {run.sum()}, invalid {(run & ~used).sum()} "
          f"({100.0 * (run & ~used).sum() / run.sum():.0f} %)")
    print(f"  constrained nights paid per household: mean {paid.mean():.2f} ({dist}); campaign "
          f"nights {n_normal} normal + those, mean {n_normal + paid.mean():.2f}; households "
          f"with 2 valid {(n_used >= 2).sum()}, 1 valid {(n_used == 1).sum()}, none valid (not "
          f"identified by this campaign) {(n_used == 0).sum()} of {len(paid)}")
    cold, kh = comfort["coldest_c"], comfort["kh_per_night"]
    print(f"  comfort (true T_air, window start to 3 h after its end, the nights run): coldest "
          f"median {np.median(cold):.1f} °C, P10 {np.percentile(cold, 10):.1f} °C, min "
          f"{cold.min():.1f} °C; below the day setpoint per night median {np.median(kh):.1f} "
          f"K·h, P90 {np.percentile(kh, 90):.1f}; per household (all nights run) median "
          f"{np.median(comfort['kh_total']):.1f}, P90 {np.percentile(comfort['kh_total'], 90):.1f}"
          " K·h", flush=True)


def gateway_types(gate: dict, n: int, valid_h: float) -> dict:
    """Households by what the gateway kept: valid constrained nights (0 = not identified: its
    fit has normal nights only, τ and C_m not determined) and the shortest used night."""
    used = gate["used"][:, :n]
    n_used = used.sum(axis=0)
    short = np.where(used, gate["usable_h"][:, :n], np.inf).min(axis=0)
    out = {"identified (≥ 1 valid constrained night)": n_used >= 1,
           "— 2 valid": n_used >= 2, "— 1 valid (campaign stopped)": n_used == 1,
           "NOT identified (0 valid; τ, C_m not determined)": n_used == 0}
    edges = sorted({valid_h, 3.0, 4.0, 5.0})
    for lo, hi in zip(edges, [*edges[1:], np.inf], strict=True):
        if lo < valid_h:
            continue
        label = f"shortest used night {lo:g}–{hi:g} h" if np.isfinite(hi) \
            else f"shortest used night ≥ {lo:g} h"
        out[label] = (short >= lo) & (short < hi)
    return out


def dump(res: dict, path: str) -> None:
    """Per household: signed errors [%] of HLC, τ, C_m, ε [%], interval hits, the same
    errors of the per-night average (``pn_*``, ``eps_pn_pct``), the household's types
    (``type:…``) and, on the gateway's nights, the valid constrained nights used, those paid
    and the comfort cost."""
    import json

    truth = res["truth"]
    true = {"hlc": [h.hlc_w_per_k for h in truth], "tau": [h.tau_h for h in truth],
            "c_m": [h.c_m_j_per_k for h in truth]}
    out = {"eps_pct": [float(x) for x in res["eps_fit"]]}
    for k, t in true.items():
        est = [f.lumped_[k] for f in res["fit"]]
        out[f"{k}_err_pct"] = [float(x) for x in rel([e.value for e in est], t)]
        out[f"{k}_covered"] = [bool(e.low <= v <= e.high) for e, v in zip(est, t, strict=True)]
        out[f"{k}_halfwidth_pct"] = [50.0 * float(np.log(e.high / e.low))
                                     for e in est]
    if res.get("meter_gain") is not None:   # on the heat meter's scale
        g = 1.0 + np.asarray(res["meter_gain"], float)[:len(truth)]
        for k in ("hlc", "c_m"):
            out[f"{k}_meter_err_pct"] = [float(x) for x in rel(
                [f.lumped_[k].value for f in res["fit"]], np.asarray(true[k], float) * g)]
    # where each fit's night gain came from, and its value [W]
    out["gain_source"] = [(getattr(f, "night_gain_", None) or {}).get("source")
                          for f in res["fit"]]
    out["gain_w"] = [(getattr(f, "night_gain_", None) or {}).get("value_w") for f in res["fit"]]
    out["inflation"] = [max([(1 + r) / (1 - r) for r in f.residual_autocorrelation_.values()]
                            or [1.0]) for f in res["fit"]]
    # the adequacy check's statistics per residual group (for its calibration)
    for g in ("constrained", "normal_power"):
        for k in ("lag1_autocorrelation", "rmse_over_noise", "low_frequency_ratio", "blocks",
                  "whiteness_p", "rmse_over_reading_noise", "rmse", "reading_noise"):
            out[f"adequacy:{g}:{k}"] = [((getattr(f, "adequacy_", None) or {}).get("groups", {})
                                         .get(g, {}).get(k)) for f in res["fit"]]
    out["mean_power_w"] = [float(np.nanmean(np.concatenate(
        [np.asarray(p["q_measured_w"], float) for p in f.predictions_ if p["kind"] == "normal"]
        or [np.array([np.nan])]))) for f in res["fit"]]
    out["adequate"] = [bool((getattr(f, "adequacy_", None) or {}).get("adequate", True))
                       for f in res["fit"]]
    # the held nights' defrosts: their share of the time, and whether the fit said that the
    # reading did not go negative in them (the draw not read)
    defrost = [(getattr(f, "cross_checks_", None) or {}).get("defrost") or {} for f in res["fit"]]
    out["defrost_share"] = [d.get("share") for d in defrost]
    out["defrost_flagged"] = [bool(d.get("flagged")) for d in defrost]
    priors = [getattr(f, "prior_", None) for f in res["fit"]]
    if any(p is not None for p in priors):   # the population prior (h14z)
        for k in ("hlc", "c_m", "tau"):
            said = [(p or {}).get("parameters", {}).get(k) for p in priors]
            if any(x is not None for x in said):
                out[f"{k}_prior_ratio"] = [None if x is None else x["posterior_to_prior_sd"]
                                           for x in said]
    # the paper's way (per-night fits averaged) of the same run, per household
    out["eps_pn_pct"] = [float(x) for x in res["eps_pn"]]
    for k, t in true.items():
        out[f"pn_{k}_err_pct"] = [float(x) for x in rel(
            [p["lumped"][k] for p in res["per_night_mean"]], t)]
    for name, m in (res.get("types") or {}).items():
        out[f"type:{name}"] = [bool(x) for x in np.asarray(m)[:len(truth)]]
    gate = res.get("gateway")
    if gate is not None:
        n = len(truth)
        out["n_used"] = gate["used"][:, :n].sum(axis=0).tolist()
        out["paid"] = gate["paid"][:n].tolist()
        out["coldest_c"] = gate["comfort"]["coldest_c"][:n].tolist()
        out["kh_per_night"] = gate["comfort"]["kh_per_night"][:n].tolist()
    with open(path, "w") as fh:
        json.dump(out, fh)
    print(f"per-household figures written to {path}")


def interval_record(i, step_s, fit, truth, kind, onoff, control) -> dict:
    """One household's interval record (log errors, SDs, coverage, the fit's diagnostics)."""
    rec = {"index": i, "step_s": step_s, "diagnostics": model_error.diagnostics(fit),
           "emitter": "underfloor" if kind == 1 else "radiators", "on_off": bool(onoff),
           "control": "room thermostat" if control == 1 else "weather curve",
           "log_error": {}, "sd": {}, "covered": {}}
    for q in model_error.QUANTITIES:
        e = fit.lumped_[q]
        rec["log_error"][q] = float(np.log(e.value / truth[q]))
        rec["sd"][q] = float(np.log(e.high / e.low) / (2 * model_error.Z95))
        rec["covered"][q] = bool(e.low <= truth[q] <= e.high)
    return rec


def why_table(records: list[dict]) -> None:
    """What the fit could see, for the houses whose interval missed a truth (and for all)."""
    print("\n### why intervals miss: what the fit could see for each missed house")
    print("| house | emitter | control | on/off | group | missed | log error HLC/τ/C_m ×100 | "
          "95 % half-width in log ×100 | ρ cons | ρ power | RMSE/noise cons | RMSE/noise power | "
          "discharge h | adequate |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in records:
        miss = [q for q in model_error.QUANTITIES if not r["covered"][q]]
        if not miss:
            continue
        d = r["diagnostics"]
        f = (lambda v: "–" if v is None else f"{v:.2f}")   # noqa: E731
        print(f"| {r['index']} | {r['emitter']} | {r['control']} | {'yes' if r['on_off'] else 'no'}"
              f" | {model_error.group_of(d)} | {','.join(miss)} | "
              + "/".join(f"{100 * r['log_error'][q]:+.0f}" for q in ("hlc", "tau", "c_m"))
              + " | " + "/".join(f"{100 * model_error.Z95 * r['sd'][q]:.0f}"
                                 for q in ("hlc", "tau", "c_m"))
              + f" | {f(d['rho_constrained'])} | {f(d['rho_power'])} | "
              f"{f(d['rmse_over_noise_constrained'])} | {f(d['rmse_over_noise_power'])} | "
              f"{f(d['emitter_discharge_h'])} | {d['adequate']} |")
    print("\nmedians, missed (any quantity) vs covered (all three):")
    keys = ("rho_constrained", "rho_power", "rmse_over_noise_constrained",
            "rmse_over_noise_power", "emitter_discharge_h", "structure_share")
    for label, sel in (("missed", lambda r: not all(r["covered"].values())),
                       ("covered", lambda r: all(r["covered"].values()))):
        rs = [r for r in records if sel(r)]
        cells = []
        for k in keys:
            v = [r["diagnostics"][k] for r in rs if r["diagnostics"][k] is not None]
            cells.append(f"{k} {np.median(v):.2f}" if v else f"{k} –")
        ad = np.mean([r["diagnostics"]["adequate"] for r in rs]) if rs else float("nan")
        nu = np.mean([r["diagnostics"]["nuisance_selected"] for r in rs]) if rs else float("nan")
        print(f"  {label:8s} n={len(rs):3d}: " + ", ".join(cells)
              + f", adequate {100 * ad:.0f} %, nuisance selected {100 * nu:.0f} %")
