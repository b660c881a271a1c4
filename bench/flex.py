"""How right is the traded flexibility figure (``coast_h``) on realistic houses?

``impctl.flex`` computes the coast — hours until T_air has fallen by 1 K after the heating is
switched off at steady state (21 °C indoors, 0 °C outdoors) — from the fit's JSON summary: the
fitted 5R1C plus the switch-off terms the fit kept (emitter release, air/furniture, night gain;
without them the 5R1C's instantaneous switch-off drop is not counted). This bench compares it
with the coast of the **realistic plant** itself (``impctl.plant``: air, furniture and emitter
capacity, the heat pump's control, sensors), the house the fit never sees whole:

* truth: the plant held at 21 °C for 24 h at a constant 0 °C outdoors (its control, its emitter,
  its night gains at the household's own level — or none with ``--gains off``), then the
  space-heating loop switched off; the coast is the time until the *true* air temperature has
  fallen 1 K below its mean over the last heated hour;
* ``impctl fit`` (joint fit, true class ranges, 2 constrained + 6 normal nights of 5-minute
  rows on the same plant, as ``bench/fit.py --plant realistic``) → its JSON summary →
  ``impctl.flex`` coast and its interval (the product's path); the same fits through the pure
  5R1C with the jump not counted and τ's interval only (before issue 16);
* the true 5R1C parameters through ``impctl.flex`` (what a perfect fit would say: the model's
  own structural error);
* the log-linear cooling baseline: τ from ln(T_air − T_out) on the constrained nights, coast
  = τ·ln(ΔT₀/(ΔT₀ − 1 K)) for a single-capacity house.

Run: ``python bench/flex.py --households 50`` (prints the table and the command).
``--save FILE`` keeps truth and fit summaries; ``--load FILE`` reruns only ``impctl.flex`` on
them (seconds: for work on the coast itself).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

from impctl.fit import baselines
from impctl.fit.estimator import NightFit
from impctl.fit.nights.data import prepare_nights
from impctl.fit.ode.parameters import PARAM_NAMES
from impctl.fit.result.report import fit_to_dict
from impctl.flex import flexibility_many, flexibility_of_fit, house_from_fit
from impctl.model import HouseParameters
from impctl.plant import simulate_plant
from impctl.population.households import sample_households
from impctl.population.imp_run.synth import imp_schedule, run_schedule_plant, sample_nights
from impctl.population.realism import sample_params

sys.path.insert(0, str(Path(__file__).parent))
from fit import ACH, VAL_SEED, true_ranges  # noqa: E402  (bench/fit.py: the same validation houses)

T_SET_C, T_OUT_C, DROP_K = 21.0, 0.0, 1.0


def plant_coast_h(houses: HouseParameters, params, gains: bool, dt_s: float = 60.0,
                  heated_h: float = 24.0, off_h: float = 72.0) -> np.ndarray:
    """Hours until the plant's true T_air falls ``DROP_K`` below its last heated hour's mean
    after the loop is switched off (NaN if not within ``off_h``)."""
    n = houses.n_houses
    n_on, n_off = int(heated_h * 3600 / dt_s), int(off_h * 3600 / dt_s)
    sp = np.concatenate([np.full(n_on, T_SET_C), np.full(n_off, np.nan)])
    gain_w = np.broadcast_to(np.asarray(params.gains.night_w, float), (n,)) if gains \
        else np.zeros(n)
    run = simulate_plant(houses, params, np.full(n_on + n_off, T_OUT_C), dt_s,
                         setpoint_c=sp, internal_gains_w=np.broadcast_to(
                             gain_w, (n_on + n_off, n)), t_init_c=T_SET_C, seed=VAL_SEED,
                         outputs=("t_air_c",))
    air = np.asarray(run["t_air_c"])
    ref = air[n_on - int(3600 / dt_s):n_on].mean(axis=0)
    after = air[n_on:]
    out = np.full(n, np.nan)
    for j in range(n):
        below = np.flatnonzero(after[:, j] <= ref[j] - DROP_K)
        if below.size:
            i = below[0]
            a0 = after[i - 1, j] if i else ref[j]
            frac = (a0 - (ref[j] - DROP_K)) / (a0 - after[i, j]) if a0 != after[i, j] else 1
            out[j] = (i + frac) * dt_s / 3600.0
    return out


def loglinear_coast_h(tau_h: float) -> float:
    dt0 = T_SET_C - T_OUT_C
    return float(tau_h * np.log(dt0 / (dt0 - DROP_K)))


def summarise(name: str, est: np.ndarray, truth: np.ndarray, groups: dict, lo=None, hi=None
              ) -> list[str]:
    ok = np.isfinite(est) & np.isfinite(truth)
    err = 100.0 * (est - truth) / truth
    rows = []
    for gname, mask in groups.items():
        m = ok & mask
        if not m.any():
            continue
        e = err[m]
        cov = width = "–"
        if lo is not None:
            inside = (lo[m] <= truth[m]) & (truth[m] <= hi[m])
            cov = f"{100.0 * inside.mean():.0f} %"
            width = f"{100.0 * np.median((hi[m] - lo[m]) / 2.0 / est[m]):.0f} %"
        rows.append(f"| {name} | {gname} ({m.sum()}) | {np.median(np.abs(e)):.1f} / "
                    f"{np.percentile(np.abs(e), 90):.1f} % | {np.median(e):+.1f} % | {cov} | "
                    f"{width} |")
    return rows


def _slim(summary: dict) -> dict:
    """What :func:`impctl.flex.flexibility_of_fit` reads of a fit summary (for ``--save``)."""
    return {k: summary[k] for k in ("parameters", "fixed", "lumped", "nuisance", "fit")
            if k in summary}


def fit_households(houses, params, n: int, step_s: float, t_start: float) -> dict:
    """The ``impctl fit`` summary (slimmed) and the log-linear coast of every household."""
    sched = imp_schedule(n, seed=VAL_SEED)
    logged, sp = run_schedule_plant(houses, sched, params, seed=VAL_SEED)
    summaries, loglin = [], []
    last = time.perf_counter()
    for i in range(n):
        house = houses.take(i)
        nights = sample_nights(logged, sp, sched, i, sample_step_s=step_s,
                               quantise_k=0.1, power_noise=0.0, seed=VAL_SEED + i)
        fit = NightFit(ach_vent=ACH[0], ach_infl=ACH[1]).fit(nights, true_ranges(house))
        # the product's path: the JSON summary is what impctl.flex reads
        summaries.append(_slim(json.loads(json.dumps(fit_to_dict(fit)))))
        kept, _, _ = prepare_nights(nights)
        loglin.append(loglinear_coast_h(baselines.loglinear_tau(kept)))
        if time.perf_counter() - last > 5 or i == n - 1:
            print(f"  fitted {i + 1}/{n} households "
                  f"({time.perf_counter() - t_start:.0f} s)", flush=True)
            last = time.perf_counter()
    return {"summaries": summaries, "loglinear_h": loglin}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--households", type=int, default=50)
    ap.add_argument("--step-s", type=float, default=300.0, help="row step of the fitted nights")
    ap.add_argument("--gains", choices=("night", "off"), default="night",
                    help="the truth's internal gains while coasting")
    ap.add_argument("--save", type=Path, help="write truth and fit summaries to this JSON")
    ap.add_argument("--load", type=Path,
                    help="read truth and fit summaries from a --save file (no simulation, no "
                         "fits: only impctl.flex runs)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    n = args.households
    t_start = time.perf_counter()
    houses = sample_households(n, seed=VAL_SEED)
    params = sample_params(n, VAL_SEED)
    if args.load:
        cached = json.loads(args.load.read_text())
        if cached["households"] != n or cached["gains"] != args.gains:
            sys.exit(f"{args.load}: saved for --households {cached['households']} "
                     f"--gains {cached['gains']}")
        truth = np.array(cached["truth_h"], float)
    else:
        print(f"simulating the coast of {n} realistic houses …", flush=True)
        truth = plant_coast_h(houses, params, gains=args.gains == "night")
        print(f"simulating their IMP nights … ({time.perf_counter() - t_start:.0f} s)",
              flush=True)
        cached = {"households": n, "gains": args.gains, "truth_h": truth.tolist(),
                  **fit_households(houses, params, n, args.step_s, t_start)}
        if args.save:
            args.save.write_text(json.dumps(cached))
    fit_flex = [flexibility_of_fit(s, t_set_c=T_SET_C, t_out_c=T_OUT_C, drop_k=DROP_K)
                for s in cached["summaries"]]
    true_5r1c = flexibility_many(HouseParameters(**{k: np.asarray(getattr(houses, k), float)
                                                     for k in PARAM_NAMES},
                                                  ach_vent=ACH[0], ach_infl=ACH[1]),
                                 t_set_c=T_SET_C, t_out_c=T_OUT_C, drop_k=DROP_K)
    # before issue 16: the same fits, pure 5R1C, switch-off jump not counted, τ interval only
    old = [flexibility_many(house_from_fit(s), s["lumped"]["tau"]["low"],
                            s["lumped"]["tau"]["high"], structure_share=False,
                            t_set_c=T_SET_C, t_out_c=T_OUT_C, drop_k=DROP_K)[0]
           for s in cached["summaries"]]
    before, before_lo, before_hi = (np.array([getattr(f, k) for f in old])
                                    for k in ("coast_h", "coast_h_low", "coast_h_high"))
    est = np.array([f.coast_h for f in fit_flex])
    lo = np.array([f.coast_h_low for f in fit_flex])
    hi = np.array([f.coast_h_high for f in fit_flex])
    perfect = np.array([f.coast_h for f in true_5r1c])
    kind = np.broadcast_to(np.asarray(params.emitter.kind), (n,))
    groups = {"all": np.ones(n, bool), "radiators": kind == 0, "underfloor": kind == 1}
    methods = {}
    for f in fit_flex:
        methods[f.coast_method] = methods.get(f.coast_method, 0) + 1
    print()
    print(f"`{' '.join(['python'] + sys.argv)}` ({time.perf_counter() - t_start:.0f} s, "
          f"load average {os.getloadavg()[0]:.1f}); truth: realistic plant, gains "
          f"{args.gains}; coast median {np.nanmedian(truth):.1f} h (P10–P90 "
          f"{np.nanpercentile(truth, 10):.1f}–{np.nanpercentile(truth, 90):.1f} h); "
          f"coast methods: {'; '.join(f'{k} ({v})' for k, v in methods.items())}")
    print()
    print("| coast_h from | houses | median / P90 abs. error | signed median | "
          "truth in 95 % interval | median interval half-width / coast_h |")
    print("|---|---|---|---|---|---|")
    for line in (summarise("impctl fit → impctl.flex", est, truth, groups, lo, hi)
                 + summarise("impctl fit → pure 5R1C, jump not counted (before)", before,
                             truth, groups, before_lo, before_hi)
                 + summarise("true 5R1C parameters → impctl.flex", perfect, truth, groups)
                 + summarise("log-linear τ baseline", np.array(cached["loglinear_h"]),
                             truth, groups)):
        print(line)


if __name__ == "__main__":
    main()
