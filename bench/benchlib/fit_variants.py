"""bench/fit.py's side studies: normal-night models and optimisers side by side (``--compare``,
``--adam``) and the fit on the classifiers' own IMP simulator (``--virtual-imp``)."""

from __future__ import annotations

import numpy as np

from benchlib.fit_protocol import (
    VAL_SEED,
    _safe_house,
    demand_eps,
    night_gain,
    simulate_schedule,
    true_ranges,
    val_schedule,
    window_energy,
)
from benchlib.fit_tables import rel, stats
from impctl.fit.estimator import NightFit
from impctl.model import HouseParameters
from impctl.population.households import sample_households
from impctl.population.imp_run.synth import sample_nights


def compare(houses_arr: HouseParameters, args) -> None:
    """Normal-night models (series / mean / demand) and optimisers (LM / Adam) side by side."""
    n = houses_arr.n_houses
    sched = val_schedule(n, args)
    sim, sp, heat = simulate_schedule(houses_arr, sched, args.plant,
                                      getattr(args, "realism", None))
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
                           max_iter=40, per_night=False,
                           **night_gain(args)).fit(nights, true_ranges(house))
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
    from impctl.population.imp_run.ideal import simulate_imp
    from impctl.population.imp_run.setup import ImpSimConfig

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
        # the classifiers' IMP simulator has no gains: the fit is told so
        fit = NightFit(timestamps="interval", night_gain_w=0.0).fit(cons + normal,
                                                                    true_ranges(house))
        kept.append(sum(x.kind == "constrained" for x in fit.nights_))
        for k, t in (("hlc", house.hlc_w_per_k), ("tau", house.tau_h),
                     ("c_m", house.c_m_j_per_k)):
            e = fit.lumped_[k]
            errs[k].append(rel(e.value, t))
            cover[k].append(e.low <= t <= e.high)
        times.append(fit.fit_time_s_)
    print(f"\n### cross-check on impctl.population.imp_run.ideal ({n} households, 10-min samples, "
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
