"""Where the realistic-plant fit errs, per household, and NightFit variants on the same nights.

Run:  .venv/bin/python bench/fit_emitter.py [--households 50] [--step 300]
          [--variant name:key=value,key=value ...] [--diagnose] [--plant realistic|iso]
          [--preheat-h H] [--preheat-h-normal H]

The validation houses and nights of ``bench/fit.py --ranges true --plant realistic`` (same
seeds, same simulation), fitted once per variant (``NightFit`` keyword arguments; ``base`` is
the default fit). Per variant: median |error| and signed median of HLC, τ, C_m by emitter and
control type, and 95 % coverage. ``--diagnose`` adds, for the first variant, the Spearman rank
correlation of each household's signed error with its realism draws (screed capacity, night
gains, sensor offsets, meter gain, …) — which plant factor carries the error. ``--kinds normal``
fits the held nights alone. ``--truth-box`` refits, for the first variant's households with
|HLC error| > 25 %, with the seven parameters pinned to the truth (±0.5 %, nuisance terms free)
and prints the residual RMS of both fits: if the true house fits the nights no better than the
wrong estimate, no model term fixes it.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from scipy.stats import spearmanr

sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))

from fit import ACH, VAL_SEED, rel, simulate_schedule, true_ranges, val_schedule  # noqa: E402

from impctl.fit.estimator import NightFit  # noqa: E402
from impctl.population.households import sample_households  # noqa: E402
from impctl.population.imp_run.synth import sample_nights  # noqa: E402
from impctl.population.realism import params_table, sample_params  # noqa: E402

#: Realism draws the diagnosis correlates with (``params_table`` columns).
FACTORS = ("emitter.kind", "emitter.screed_j_per_m2k", "emitter.ufh_area_share",
           "emitter.buffer_l_per_kw", "heat_pump.min_modulation", "heat_pump.control",
           "gains.night_w",
           "sensors.t_air_offset_k", "sensors.t_out_offset_k", "sensors.meter_gain_error",
           "sensors.t_air_lag_s", "capacities.furniture_j_per_m2k")


def parse_variant(text: str) -> tuple[str, dict]:
    name, _, rest = text.partition(":")
    kw = {}
    for item in filter(None, rest.split(",")):
        k, _, v = item.partition("=")
        kw[k] = {"True": True, "False": False}.get(v, None)
        if kw[k] is None:
            kw[k] = float(v) if "." in v else int(v)
    return name, kw


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=50)
    ap.add_argument("--step", type=float, default=300.0)
    ap.add_argument("--plant", default="realistic", choices=("realistic", "iso"))
    ap.add_argument("--variant", action="append", default=[])
    ap.add_argument("--diagnose", action="store_true")
    ap.add_argument("--truth-box", action="store_true")
    ap.add_argument("--kinds", default="constrained,normal",
                    help="fit only these kinds of night (e.g. normal: held nights alone)")
    ap.add_argument("--preheat-h", type=float, default=None,
                    help="pre-heat of both kinds of night [h] (as bench/fit.py)")
    ap.add_argument("--preheat-h-normal", type=float, default=None,
                    help="pre-heat of the normal nights alone [h]")
    args = ap.parse_args()
    variants = [parse_variant(v) for v in (args.variant or ["base:"])]
    n = args.households
    houses = sample_households(n, seed=VAL_SEED)
    sched = val_schedule(n, args)
    t0 = time.perf_counter()
    sim, sp, _ = simulate_schedule(houses, sched, args.plant)
    print(f"simulated {n} households ({args.plant}) in {time.perf_counter() - t0:.0f} s",
          flush=True)
    table = params_table(sample_params(n, VAL_SEED), n)
    noise = 0.05 if args.plant == "iso" else 0.0
    kinds = set(args.kinds.split(","))
    nights = [[x for x in sample_nights(sim, sp, sched, i, sample_step_s=args.step,
                                        quantise_k=0.1, power_noise=noise, seed=VAL_SEED + i)
               if x.kind in kinds] for i in range(n)]
    truth = [houses.take(i) for i in range(n)]
    t_q = {"hlc": np.array([h.hlc_w_per_k for h in truth]),
           "tau": np.array([h.tau_h for h in truth]),
           "c_m": np.array([h.c_m_j_per_k for h in truth])}
    types = {"all": np.ones(n, bool)}
    if args.plant == "realistic":
        kind, onoff = table["emitter.kind"].to_numpy(), table["heat_pump.min_modulation"] >= 0.999
        ctrl = table["heat_pump.control"].to_numpy()
        types |= {"radiators": kind == 0, "underfloor": kind == 1, "on/off": onoff.to_numpy(),
                  "modulating": ~onoff.to_numpy(), "curve": ctrl == 0, "thermostat": ctrl == 1}
    for vi, (name, kw) in enumerate(variants):
        err = {k: np.full(n, np.nan) for k in t_q}
        sigmas = []
        cov = {k: np.zeros(n, bool) for k in t_q}
        times, selected = [], []
        for i in range(n):
            fit = NightFit(ach_vent=ACH[0], ach_infl=ACH[1], **kw).fit(
                nights[i], true_ranges(truth[i]))
            times.append(fit.fit_time_s_)
            sigmas.append(fit.sigma_)
            selected.append(bool(fit.nuisance_check_.get("selected")))
            for k in t_q:
                e = fit.lumped_[k]
                err[k][i] = rel(e.value, t_q[k][i])
                cov[k][i] = e.low <= t_q[k][i] <= e.high
        print(f"\n== {name} {kw}  ({n} households, {args.step:g} s rows; time/house median "
              f"{np.median(times):.2f} s, max {max(times):.2f} s; nuisance kept "
              f"{sum(selected)}/{n})")
        print(f"{'type':12s} {'n':>3s} | " + " | ".join(
            f"{k:>4s} |e| med / P90 (signed) cov" for k in t_q))
        for tname, m in types.items():
            cells = []
            for k in t_q:
                a = np.abs(err[k][m])
                cells.append(f"{np.median(a):5.1f} / {np.percentile(a, 90):5.1f} "
                             f"({np.median(err[k][m]):+5.1f}) {100 * cov[k][m].mean():3.0f}%")
            print(f"{tname:12s} {int(m.sum()):3d} | " + " | ".join(cells))
        if args.diagnose and vi == 0 and args.plant == "realistic":
            print("\nSpearman ρ of the signed error with the realism draws (|ρ| > 0.28: p < 0.05)")
            print(f"{'factor':34s} " + " ".join(f"{k:>6s}" for k in t_q))
            for f in FACTORS:
                x = table[f].to_numpy()
                if f == "emitter.screed_j_per_m2k":   # only underfloor houses have a screed
                    x = np.where(table["emitter.kind"] == 1,
                                 x * table["emitter.ufh_area_share"], 0.0)
                rho = [spearmanr(x, err[k]).statistic for k in t_q]
                print(f"{f:34s} " + " ".join(f"{r:+6.2f}" for r in rho))
            print("\nper household (signed %): kind ctrl onoff  HLC  tau  C_m")
            for i in range(n):
                print(f"  {i:2d} {'UFH' if table['emitter.kind'][i] else 'rad'} "
                      f"{'thermo' if table['heat_pump.control'][i] else 'curve '} "
                      f"{'on/off' if table['heat_pump.min_modulation'][i] >= 0.999 else 'mod   '}"
                      f" {err['hlc'][i]:+6.1f} {err['tau'][i]:+6.1f} {err['c_m'][i]:+6.1f}")
        if args.truth_box and vi == 0:
            _truth_box(nights, truth, err, sigmas, kw)
        sys.stdout.flush()


def _truth_box(nights, truth, err, sigmas, kw) -> None:
    print("\nworst households: residual RMS, free fit vs the seven pinned to the truth "
          "(power W / constrained T_air K)")
    names = ("floor_area", "wall_height", "walls_area", "windows_area", "c_f", "u_walls",
             "u_windows")
    for i in np.flatnonzero(np.abs(err["hlc"]) > 25.0):
        box = {k: (getattr(truth[i], k) * 0.995, getattr(truth[i], k) * 1.005) for k in names}
        pinned = NightFit(ach_vent=ACH[0], ach_infl=ACH[1], physical_bounds=box, **kw).fit(
            nights[i], None)
        free = sigmas[i]
        print(f"  {i:2d}: HLC {err['hlc'][i]:+6.1f} %   free {free['normal_power_w']:6.0f} W "
              f"{free['constrained_t_air_k']:.3f} K   truth {pinned.sigma_['normal_power_w']:6.0f}"
              f" W {pinned.sigma_['constrained_t_air_k']:.3f} K")


if __name__ == "__main__":
    main()
