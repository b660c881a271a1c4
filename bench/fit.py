"""Benchmark of the night-time Neural-ODE fit against the truth and simple baselines.

Run:  .venv/bin/python bench/fit.py [--households 50] [--ranges classifier|true|prior[,…]]
          [--model-dir DIR] [--steps 300,3600] [--compare N] [--adam N] [--quick] [--verbose]
          [--plant iso|realistic] [--fine-households N]
      .venv/bin/python bench/fit.py --speed [--demo-csv impctl-demo/nights.csv]

``--plant realistic``: the same houses, weather and schedule on the realistic plant
(:mod:`impctl.plant`; realism options drawn by ``impctl.population.realism.sample_params`` with the
validation seed): the logged T_air is the room sensor, T_out the outdoor sensor, the power the
heat meter's interval mean (no extra noise); the demand truth is the true heat-pump output.

Validation population: ``impctl.population.households.sample_households`` with seed 20260 (the
classifiers are trained with other seeds, so they never saw these houses). Each household runs
the IMP protocol of ``impctl.population.synth_nights`` on its own seeded winter weather, simulated
with the Annex C model at 60 s: two spin-up days at 21 °C, then 8 nights (2 constrained, 6 normal
at 22/23/24 °C); constrained nights pre-heat to T_set + 1.5 °C and cool 22:00–05:00 (the paper's
case study), normal nights step up from the 21 °C day. Measurements: T_air and T_out rounded to
0.1 °C, each heat-power sample × (1 + 0.05·N(0,1)); samples every ``--steps`` seconds
(temperatures are readings, power the mean until the next sample).

Ranges for floor_area, c_f, u_walls: ``classifier`` (the trained forests of ``impctl train`` on
the household's nights — the whole pipeline), ``true`` (the class holding the true value) or
``prior`` (the union of the classes).

Reported per sample step:
* median and 90th percentile of |relative error| of HLC, τ and C_m; share of households whose
  true value lies in the fit's 95 % interval (coverage);
* heat demand ε: each method's house replayed (Annex C, noise-free) through the same weather
  and setpoints as the truth, |E_model − E_true|/E_true per normal night, mean per household —
  on the realistic plant E_true is the true house replayed the same way (``--eps-truth house``,
  default; ``plant``: the plant's own heat output, which no parameter set reaches) —
  an out-of-sample prediction (the fit's own in-sample ε uses fitted initial mass temperatures
  and is near zero by construction);
* Table IV-style errors of the seven parameters next to the prior-midpoint baseline and the share
  of households where the fit flags each parameter as determined by the data;
* baselines from the same nights: coheating HLC, log-linear τ, C_m = τ·HLC, scipy least squares on
  the exact discretisation (same model and ranges, one start); the prior midpoint;
* how often the likelihood-ratio test rejects the classifiers' ranges;
* fit time per household (one core).
``--compare N`` adds the normal-night models (demand / series / mean) and ``--adam N`` the
paper's optimiser (Adam, backprop through odeint) on N households; ``--virtual-imp N`` fits N
households simulated by the classifiers' own IMP simulator (a second, independent protocol).
Targets (issue 14, :data:`TARGETS`): realistic plant at 5-minute rows median HLC ≤ 5 %, τ ≤ 5 %,
C_m ≤ 10 %, ε ≤ 8 %, coverage ≥ 90 %; at 1-minute and hourly rows reported, coverage ≥ 85 %;
ideal 5R1C ≤ 1 / 1 / 3 %, ε ≤ 3 %, coverage ≥ 90 %; ≤ 1 s per household at 5-minute rows.

``--ranges true,classifier`` fits the same simulated nights with each range source in turn (the
classifiers of ``--model-dir``, e.g. trained by ``impctl train --plant realistic``); a final
summary table has one row per sample step and range source (median / P90, coverage, share of
households whose three classes were right, fit time). ``--fine-households N`` fits only the
first N households at steps under 5 minutes. The issue-14 table, re-runnable as is::

    python bench/fit.py --households 50 --ranges true,classifier --plant realistic \
        --steps 300,60,3600 --fine-households 20 --no-lsq --model-dir MODELS
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import numpy as np
import torch

from impctl.fit import baselines
from impctl.fit.data import prepare_nights, search_bounds
from impctl.fit.estimator import NightFit
from impctl.fit.node import PARAM_NAMES
from impctl.model import HouseParameters
from impctl.population.households import sample_households
from impctl.population.realism import sample_params
from impctl.population.synth_nights import (
    imp_schedule,
    run_schedule,
    run_schedule_plant,
    sample_nights,
)

VAL_SEED = 20260
CLASS_RANGES = {
    "floor_area": ((60.0, 100.0), (100.0, 200.0), (200.0, 300.0)),
    "c_f": ((0.8, 1.65), (1.65, 3.7)),
    "u_walls": ((0.2, 1.0), (1.0, 2.0)),
}
ACH = (0.0, 0.01)
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


def true_ranges(house: HouseParameters) -> dict[str, tuple[float, float]]:
    out = {}
    for name, rs in CLASS_RANGES.items():
        v = float(getattr(house, name))
        out[name] = next((r for r in rs if r[0] <= v < r[1]), rs[-1])
    return out


def classifier_ranges(nights, model_dir):
    from impctl.classifiers import classify_nights

    return {k: tuple(v.range) for k, v in classify_nights(nights, model_dir).items()}


def house_from(params: dict[str, float]) -> HouseParameters:
    return HouseParameters(**{n: params[n] for n in PARAM_NAMES}, ach_vent=ACH[0],
                           ach_infl=ACH[1])


def demand_eps(houses: list[HouseParameters], sched, truth_energy: np.ndarray) -> np.ndarray:
    """Mean |E − E_true|/E_true [%] over the normal nights, per household (NaN if no house)."""
    ok = [h is not None for h in houses]
    out = np.full(len(houses), np.nan)
    if not any(ok):
        return out
    idx = np.flatnonzero(ok)
    sub = HouseParameters.stack([houses[i] for i in idx])
    sched_sub = _sub_schedule(sched, idx)
    sim, _ = run_schedule(sub, sched_sub)
    e = window_energy(sim, sched_sub)
    out[idx] = 100.0 * np.mean(np.abs(e - truth_energy[:, idx]) / truth_energy[:, idx], axis=0)
    return out


def _sub_schedule(sched, idx):
    from dataclasses import replace

    return replace(sched, t_out_c=sched.t_out_c[:, idx], setpoint_c=sched.setpoint_c[:, idx])


def window_energy(sim, sched) -> np.ndarray:
    """Heat delivered in each normal-night window [kWh], (n_normal, n_houses)."""
    phi = np.atleast_2d(sim.phi_hc_w.T).T
    rows = [phi[w0:w1].sum(axis=0) * sched.dt_s / 3.6e6
            for _, kind, w0, w1, _ in sched.windows if kind == "normal"]
    return np.array(rows)


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


class _TrueHeat:
    """The realistic plant's true heat-pump output, for the demand truth (not the meter)."""

    def __init__(self, logged):
        self.phi_hc_w = logged.run["heat_pump_w"]


_SIMULATED: dict = {}


def simulate_schedule(houses_arr: HouseParameters, sched, plant: str):
    """(what the gateway logs, setpoints, object whose phi_hc_w is the true heat output);
    simulated once per population size and plant, so every sample step and range source
    reads the same nights."""
    key = (houses_arr.n_houses, plant)
    if key not in _SIMULATED:
        _SIMULATED[key] = _simulate_schedule(houses_arr, sched, plant)
    return _SIMULATED[key]


def _simulate_schedule(houses_arr: HouseParameters, sched, plant: str):
    if plant == "iso":
        sim, sp = run_schedule(houses_arr, sched)
        return sim, sp, sim
    params = sample_params(houses_arr.n_houses, VAL_SEED)
    logged, sp = run_schedule_plant(houses_arr, sched, params, seed=VAL_SEED)
    return logged, sp, _TrueHeat(logged)


def run_step(houses_arr: HouseParameters, step_s: float, range_source: str, args,
             limit: int | None = None) -> dict:
    """Fit the first ``limit`` (default all) households at ``step_s`` and the baselines."""
    n = houses_arr.n_houses
    sched = imp_schedule(n, seed=VAL_SEED)
    sim, sp, heat = simulate_schedule(houses_arr, sched, args.plant)
    truth_e = window_energy(heat, sched)
    floor = None
    if args.plant != "iso" and args.eps_truth == "house":
        # The plant's heat output also carries its gains, control and emitter, which no 5R1C
        # parameter set can know (true parameters alone miss it by ~11 %): ε compares with
        # the true house replayed the same way as the estimate.
        house_sim, _ = run_schedule(houses_arr, sched)
        house_e = window_energy(house_sim, sched)
        floor = 100.0 * np.mean(np.abs(house_e - truth_e) / truth_e, axis=0)
        truth_e = house_e
    noise = 0.05 if args.plant == "iso" else 0.0   # the realistic plant's meter has its own
    if limit is not None and limit < n:
        n = limit
        sched, truth_e = _sub_schedule(sched, np.arange(n)), truth_e[:, :n]
    res = {k: [] for k in ("fit", "lsq", "coh_hlc", "loglin_tau", "mid", "time", "lsq_time",
                           "truth", "fit_house", "lsq_house", "mid_house", "ranges_hit",
                           "eps_in", "per_night_mean")}
    if args.plant == "realistic":
        m = houses_arr.n_houses
        params = sample_params(m, VAL_SEED)
        kind = np.broadcast_to(np.asarray(params.emitter.kind), (m,))
        onoff = np.broadcast_to(np.asarray(params.heat_pump.min_modulation), (m,)) >= 0.999
        control = np.broadcast_to(np.asarray(params.heat_pump.control), (m,))
        kind, onoff, control = kind[:n], onoff[:n], control[:n]
        res["types"] = {
            "radiators": kind == 0, "underfloor": kind == 1,
            "modulating": ~onoff, "on/off": onoff,
            "weather curve": control == 0, "room thermostat": control == 1}
    for i in range(n):
        house = houses_arr.take(i)
        nights = sample_nights(sim, sp, sched, i, sample_step_s=step_s, quantise_k=0.1,
                               power_noise=noise, seed=VAL_SEED + i)
        if range_source == "true":
            ranges = true_ranges(house)
        elif range_source == "classifier":
            ranges = classifier_ranges(nights, args.model_dir)
        else:
            ranges = None
        hit = {k: r[0] <= float(getattr(house, k)) <= r[1] for k, r in (ranges or {}).items()}
        fit = NightFit(normal_model=args.normal_model, n_starts=args.starts,
                       ach_vent=ACH[0], ach_infl=ACH[1],
                       emitter_state=args.nuisance,
                       model_error="default" if args.model_error else None).fit(nights, ranges)
        kept, _, _ = prepare_nights(nights)
        box = search_bounds(ranges)
        t0 = time.perf_counter()
        lsq = baselines.least_squares_fit(kept, box, ACH) if args.lsq else None
        res["lsq_time"].append(time.perf_counter() - t0)
        mid = {k: 0.5 * (lo + hi) for k, (lo, hi) in box.items()}
        res["fit"].append(fit)
        res["lsq"].append(lsq)
        res["coh_hlc"].append(baselines.coheating_hlc(kept))
        res["loglin_tau"].append(baselines.loglinear_tau(kept))
        res["mid"].append(mid)
        res["time"].append(fit.fit_time_s_)
        res["truth"].append(house)
        res["ranges_hit"].append(hit)
        res["eps_in"].append(fit.validation_["mean"].get("eps_pct", np.nan))
        res["fit_house"].append(_safe_house(fit.parameters_))
        res["lsq_house"].append(_safe_house(lsq) if lsq else None)
        res["mid_house"].append(_safe_house(mid))
        res["per_night_mean"].append(fit.per_night_mean_)
        res.setdefault("class_check", []).append(fit.class_check_)
        if args.verbose:
            q = fit.lumped_
            print(f"  house {i:3d}: HLC {rel(q['hlc'].value, house.hlc_w_per_k):+6.1f} %  "
                  f"tau {rel(q['tau'].value, house.tau_h):+6.1f} %  "
                  f"C_m {rel(q['c_m'].value, house.c_m_j_per_k):+6.1f} %  "
                  f"{fit.fit_time_s_:.2f} s", flush=True)
    res["eps_fit"] = demand_eps(res["fit_house"], sched, truth_e)
    res["eps_lsq"] = demand_eps(res["lsq_house"], sched, truth_e) if args.lsq else None
    res["eps_mid"] = demand_eps(res["mid_house"], sched, truth_e)
    res["eps_pn"] = demand_eps([_safe_house(p["parameters"]) for p in res["per_night_mean"]],
                               sched, truth_e)
    # Steady-state demand from the coheating HLC: E = HLC·∫(T_air − T_out)dt per window.
    res["eps_coh"] = coheating_eps(res["coh_hlc"], sched, sim, truth_e)
    res["eps_floor"] = floor
    return res


def coheating_eps(hlc, sched, sim, truth_e):
    t_air = np.atleast_2d(sim.t_air_c.T).T[:, :len(hlc)]
    rows = [((t_air[w0:w1] - sched.t_out_c[w0:w1]).sum(axis=0) * sched.dt_s / 3.6e6)
            for _, kind, w0, w1, _ in sched.windows if kind == "normal"]
    e = np.array(rows) * np.asarray(hlc)[None, :]
    return 100.0 * np.mean(np.abs(e - truth_e) / truth_e, axis=0)


def _safe_house(params):
    try:
        return house_from(params)
    except Exception:  # a parameter set outside the model's domain cannot be replayed
        return None


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
    _model_error_lines(fits, {"hlc": t_hlc, "tau": t_tau, "c_m": t_cm})
    if args.why and "types" in res:
        from calibrate_intervals import _record, why_table

        ty = res["types"]
        why_table([_record(i, step_s, f, {"hlc": t_hlc[i], "c_m": t_cm[i], "tau": t_tau[i]},
                           int(ty["underfloor"][i]), bool(ty["on/off"][i]),
                           int(ty["room thermostat"][i])) for i, f in enumerate(fits)])
    if "types" in res:
        print("\n| NODE joint by type | houses | HLC med / P90 % | τ med / P90 % | C_m med / P90 % "
              "| coverage HLC/τ/C_m % | median ± half-width HLC/τ/C_m % |")
        print("|---|---|---|---|---|---|---|")
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
            print(f"| {label} | {int(sel.sum())} | " + " | ".join(cells)
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
        fv = np.array([f.parameters_[name] for f in fits])
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
    """The interval method and, per model-error group (:mod:`impctl.fit.model_error`), how many
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


def compare(houses_arr: HouseParameters, args) -> None:
    """Normal-night models (series / mean / demand) and optimisers (LM / Adam) side by side."""
    n = houses_arr.n_houses
    sched = imp_schedule(n, seed=VAL_SEED)
    sim, sp, heat = simulate_schedule(houses_arr, sched, args.plant)
    truth_e = window_energy(heat, sched)
    noise = 0.05 if args.plant == "iso" else 0.0
    variants = [("demand", "lm"), ("series", "lm"), ("mean", "lm")]
    if args.adam:
        variants.append(("demand", "adam"))
    print(f"\n### variants on {n} households, 5-min samples, true class ranges")
    print("| normal nights | optimiser | HLC med / P90 % | τ med / P90 % | C_m med / P90 % "
          "| ε med / P90 % | time med / max s |")
    print("|---|---|---|---|---|---|---|")
    for model, opt in variants:
        errs = {"hlc": [], "tau": [], "c_m": []}
        houses, times = [], []
        for i in range(n):
            if opt == "adam" and i >= args.adam:
                break
            house = houses_arr.take(i)
            nights = sample_nights(sim, sp, sched, i, sample_step_s=300.0, quantise_k=0.1,
                                   power_noise=noise, seed=VAL_SEED + i)
            fit = NightFit(normal_model=model, optimizer=opt, n_starts=args.starts,
                           max_iter=40, per_night=False).fit(nights, true_ranges(house))
            for k, t in (("hlc", house.hlc_w_per_k), ("tau", house.tau_h),
                         ("c_m", house.c_m_j_per_k)):
                errs[k].append(rel(fit.lumped_[k].value, t))
            houses.append(_safe_house(fit.parameters_))
            times.append(fit.fit_time_s_)
        m = len(houses)
        houses += [None] * (n - m)
        eps = demand_eps(houses, sched, truth_e)[:m]
        cells = [f"{a:.1f} / {b:.1f}" for a, b in (stats(errs["hlc"]), stats(errs["tau"]),
                                                   stats(errs["c_m"]), stats(eps))]
        label = opt if opt == "lm" else f"adam ({m} houses, 400 steps)"
        print(f"| {model} | {label} | " + " | ".join(cells)
              + f" | {np.median(times):.2f} / {np.max(times):.2f} |", flush=True)


def virtual_imp_check(n: int, args) -> None:
    """The fit on the classifiers' own IMP simulator: steady normal nights (spun up at T_set),
    an emitter ramp during the lag, constrained nights cut at T_min, "interval" stamps."""
    from impctl.population.virtual_imp import ImpSimConfig, simulate_imp

    houses = sample_households(n, seed=VAL_SEED + 1)
    cfg = ImpSimConfig(days=2, step_s=600.0, noise_t_air_k=0.0, noise_q_rel=0.05)
    res = simulate_imp(houses, config=cfg, seed=VAL_SEED)
    errs = {"hlc": [], "tau": [], "c_m": []}
    cover = {k: [] for k in errs}
    times, kept = [], []
    for i in range(n):
        house = houses.take(i)
        nights = res.nights_of(i)
        cons = [x for x in nights if x.kind == "constrained"][:2]
        normal = [x for x in nights if x.kind == "normal"]
        fit = NightFit(timestamps="interval").fit(cons + normal, true_ranges(house))
        kept.append(sum(x.kind == "constrained" for x in fit.nights_))
        for k, t in (("hlc", house.hlc_w_per_k), ("tau", house.tau_h),
                     ("c_m", house.c_m_j_per_k)):
            e = fit.lumped_[k]
            errs[k].append(rel(e.value, t))
            cover[k].append(e.low <= t <= e.high)
        times.append(fit.fit_time_s_)
    print(f"\n### cross-check on impctl.population.virtual_imp ({n} households, 10-min samples, "
          "interval stamps, 2 constrained + 6 normal nights, true class ranges)")
    print(f"constrained nights still ≥ 3 h after the lag: {np.mean(kept) / 2 * 100:.0f} %")
    print("| HLC med / P90 % | τ med / P90 % | C_m med / P90 % | coverage HLC/τ/C_m % "
          "| time med / max s |")
    print("|---|---|---|---|---|")
    cells = [f"{a:.1f} / {b:.1f}" for a, b in (stats(errs["hlc"]), stats(errs["tau"]),
                                               stats(errs["c_m"]))]
    cov = " / ".join(f"{100 * np.mean(cover[k]):.0f}" for k in ("hlc", "tau", "c_m"))
    print("| " + " | ".join(cells) + f" | {cov} | {np.median(times):.2f} / "
          f"{np.max(times):.2f} |")


def speed(args) -> None:
    """The issue's three speed figures: ``impctl fit`` wall time on the demo's export and on 8
    nights of 1-minute rows (subprocess, imports and classification included), and the
    in-process fit per household at 5-minute rows (one core)."""
    import os
    import subprocess
    import tempfile
    from pathlib import Path

    from impctl.imp.nights_csv import write_nights

    houses = sample_households(4, seed=VAL_SEED)
    sched = imp_schedule(4, seed=VAL_SEED)
    sim, sp = run_schedule(houses, sched)
    tmp = Path(tempfile.mkdtemp(prefix="impctl-bench-fit-"))
    files = []
    if args.demo_csv:
        files.append(("demo export (" + Path(args.demo_csv).name + ")", Path(args.demo_csv)))
    minute = sample_nights(sim, sp, sched, 0, sample_step_s=60.0, quantise_k=0.1,
                           power_noise=0.05, seed=VAL_SEED)
    files.append(("8 nights of 1-minute rows", write_nights(minute, tmp / "minute.csv")))
    env = dict(os.environ, OMP_NUM_THREADS="1")
    print("\n### speed (target: impctl fit ≤ 5 s wall per file, in-process ≤ 1 s per household "
          f"at 5-minute rows, one core); each command run {args.repeat} times, min / median")
    if args.model_dir:
        from impctl.classifiers.compact import COMPACT_FILE

        have = (Path(args.model_dir) / COMPACT_FILE).is_file()
        what = "compact forests" if have else "pickled forests only: retrain for the fast path"
        print(f"classifiers: {args.model_dir} ({what})")
    out = tmp / "fit.json"
    cmds = []
    for label, path in files:
        cmd = [str(Path(sys.executable).parent / "impctl"), "fit", "--nights", str(path),
               "--json", str(out)]
        cmds.append(cmd + (["--model-dir", str(args.model_dir)] if args.model_dir else []))
        print(f"{label}: OMP_NUM_THREADS=1 {' '.join(cmds[-1])}")
    print("| what | rows | wall s | CPU s (user+sys) | fit s (in JSON) "
          "| load average before / after |")
    print("|---|---|---|---|---|---|")
    for (label, path), cmd in zip(files, cmds, strict=True):
        walls, cpus, fits = [], [], []
        load0 = os.getloadavg()[0]
        for _ in range(args.repeat):
            before = os.times()
            t0 = time.perf_counter()
            done = subprocess.run(cmd, env=env, capture_output=True, text=True)
            walls.append(time.perf_counter() - t0)
            after = os.times()
            cpus.append(after.children_user - before.children_user
                        + after.children_system - before.children_system)
            if done.returncode != 0:
                break
            import json

            fits.append(json.loads(out.read_text())["fit"]["time_s"])
        if done.returncode != 0:
            print(f"| {label} | – | failed: {done.stderr.strip().splitlines()[-1]} | | | |")
            continue
        rows = sum(1 for _ in open(path)) - 1
        print(f"| {label} | {rows} | {min(walls):.1f} / {np.median(walls):.1f} "
              f"| {min(cpus):.1f} / {np.median(cpus):.1f} | {min(fits):.2f} / "
              f"{np.median(fits):.2f} | {load0:.1f} / {os.getloadavg()[0]:.1f} |", flush=True)
    times, cpu = [], []
    for i in range(houses.n_houses):
        nights = sample_nights(sim, sp, sched, i, sample_step_s=300.0, quantise_k=0.1,
                               power_noise=0.05, seed=VAL_SEED + i)
        c0 = time.process_time()
        times.append(NightFit().fit(nights, true_ranges(houses.take(i))).fit_time_s_)
        cpu.append(time.process_time() - c0)
    print(f"| in-process NightFit.fit, 5-minute rows, {len(times)} households | 8 nights "
          f"| median {np.median(times):.2f}, max {np.max(times):.2f} "
          f"| median {np.median(cpu):.2f}, max {np.max(cpu):.2f} | – |")
    print(f"load average during the run: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores "
          "(other work slows every figure)")


def _verdict(name, value, target):
    if target is None:
        return f"{name} {value:.1f} % (reported)"
    return f"{name} {value:.1f} % {'met' if value <= target else 'NOT met'} (≤ {target:g} %)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=50)
    ap.add_argument("--ranges", default="classifier",
                    help="classifier, true or prior; several comma-separated (true,classifier) "
                         "run on the same simulated nights, side by side in the summary")
    ap.add_argument("--fine-households", type=int, default=0, metavar="N",
                    help="fit only the first N households at sample steps under 5 minutes "
                         "(1-minute rows cost ~5× the fit time)")
    ap.add_argument("--steps", default="300,3600", help="sample steps [s], comma-separated")
    ap.add_argument("--normal-model", default="demand")
    ap.add_argument("--model-dir", default=None,
                    help="trained classifiers (default: impctl's per-user model directory)")
    ap.add_argument("--starts", type=int, default=4)
    ap.add_argument("--no-lsq", dest="lsq", action="store_false")
    ap.add_argument("--quick", action="store_true", help="10 households, 5-min samples only")
    ap.add_argument("--verbose", action="store_true")
    ap.add_argument("--compare", type=int, default=0, metavar="N",
                    help="also compare normal-night models and optimisers on N households")
    ap.add_argument("--adam", type=int, default=0, metavar="N",
                    help="include Adam (backprop through odeint) on N of those households")
    ap.add_argument("--no-nuisance", dest="nuisance", action="store_false",
                    help="fit without the emitter-release term (the issue-4 model)")
    ap.add_argument("--no-model-error", dest="model_error", action="store_false",
                    help="intervals without the calibrated model-error share (impctl.fit."
                         "model_error): the measurement-only intervals, for comparison")
    ap.add_argument("--why", action="store_true",
                    help="realistic plant: the diagnostics of every house whose interval misses "
                         "(bench/calibrate_intervals.py's table)")
    ap.add_argument("--speed", action="store_true",
                    help="only the speed figures (impctl fit wall time, in-process time)")
    ap.add_argument("--repeat", type=int, default=3,
                    help="--speed: run each impctl fit command this many times")
    ap.add_argument("--demo-csv", default=None,
                    help="the demo's export (impctl demo --out D writes D/nights.csv) for --speed")
    ap.add_argument("--virtual-imp", type=int, default=0, metavar="N",
                    help="also fit N households simulated by impctl.population.virtual_imp")
    ap.add_argument("--plant", choices=("iso", "realistic"), default="iso",
                    help="validation houses on the ideal 5R1C (iso) or on the realistic plant "
                         "(impctl.plant, realism drawn with seed 20260)")
    ap.add_argument("--eps-truth", choices=("house", "plant"), default="house",
                    help="realistic plant: heat-demand truth from the true house replayed like "
                         "the estimate (house) or the plant's heat-pump output (plant)")
    args = ap.parse_args()
    if args.quick:
        args.households, args.steps = 10, "300"
    torch.set_num_threads(1)
    print("command: " + " ".join(["python"] + sys.argv))
    print(f"plant: {args.plant}")
    print(f"machine: {platform.processor() or platform.machine()}, python "
          f"{platform.python_version()}, torch {torch.__version__}, 1 thread")
    if args.speed:
        speed(args)
        return
    sources = []
    for source in args.ranges.split(","):
        if source not in RANGE_SOURCES:
            ap.error(f"--ranges: {source!r} is not one of {', '.join(RANGE_SOURCES)}")
        if source == "classifier":
            source = _classifier_source(args.model_dir)
        sources.append(source)
    if args.compare:
        compare(sample_households(args.compare, seed=VAL_SEED), args)
    if args.virtual_imp:
        virtual_imp_check(args.virtual_imp, args)
    rows = []
    houses = sample_households(args.households, seed=VAL_SEED)
    for step in (float(s) for s in args.steps.split(",") if s):
        limit = args.fine_households if step < 300 and args.fine_households else None
        for source in sources:
            res = run_step(houses, step, source, args, limit)
            report(res, step, source, args)
            rows.append(summary_row(res, step, source))
    print_summary(rows, args)


RANGE_SOURCES = ("classifier", "true", "prior")


def _classifier_source(model_dir) -> str:
    """"classifier", or "prior" (said) when no trained classifiers can be loaded."""
    from impctl.classifiers import load_models
    from impctl.errors import InputError

    try:
        _, meta = load_models(model_dir)
    except InputError as exc:
        print(f"classifiers unavailable ({exc}): using the prior ranges instead")
        return "prior"
    data = meta.get("dataset", {})
    print(f"classifiers: {model_dir or 'default model dir'}, trained on "
          f"{meta.get('n_households')} households, plant {data.get('plant', 'iso')}, "
          f"compact forests {'yes' if meta.get('compact') else 'no'}")
    return "classifier"


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
          "| median ± half-width HLC/τ/C_m % | all three classes right % | time med / max s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        step = f"{r['step_s'] / 60:g}-min" if r["step_s"] < 3600 else f"{r['step_s'] / 3600:g}-h"
        cells = " | ".join(f"{r[k][0]:.1f} / {r[k][1]:.1f}" for k in ("hlc", "tau", "c_m", "eps"))
        right = "–" if r["classes_right"] is None else f"{r['classes_right']:.0f}"
        print(f"| {step} | {r['ranges']} | {r['n']} | {cells} | {r['cov_hlc']:.0f} / "
              f"{r['cov_tau']:.0f} / {r['cov_c_m']:.0f} | {r['hw_hlc']:.0f} / {r['hw_tau']:.0f} / "
              f"{r['hw_c_m']:.0f} | {right} | {r['time'][0]:.2f} / "
              f"{r['time'][1]:.2f} |")


if __name__ == "__main__":
    main()
