"""The stochastic state-space fit (impctl.fit.statespace) against today's NightFit, same nights.

Run:  .venv/bin/python bench/fit_statespace.py [--plant realistic|iso|twin] [--households 40]
          [--ranges true|prior] [--step 300] [--batch 20] [--no-nightfit] [--verbose]

Data sets (the protocol is bench/fit.py's, imported read-only):
* ``realistic``: bench/fit.py's validation houses (seed 20260) on the realistic plant, the
  gateway's nights (2 valid constrained + 6 normal, constrained nights ending at T_min), 5-min
  rows. NightFit with bench/fit.py's options (its default assumed 250 W gain); the state-space
  fit estimates the gain as a constant term under its prior. HLC and C_m are scored on the heat
  meter's scale (truth × (1 + the plant's meter gain error)), the meter's ±5 % stated beside
  them; "true scale" rows score the true values with that type-B share added.
* ``iso``: the same houses on the ideal 5R1C, gain declared 0 W (both fits), power ×(1 + 5 %
  noise) per sample, T rounded to 0.1 K.
* ``twin``: the Annex 58 twin houses N2, O5 (../shared/realdata/twinhouse/*_labelled.csv,
  time zone Etc/GMT-1), declared empty (0 W); references: co-heating HLC, free-float τ and their
  product C (realdata/README.md).

Printed: median and P90 |error| of HLC, τ, C_m with bootstrap 95 % CIs on the medians, coverage
of the 95 % intervals and median half-width, fit time per household, the adequacy verdicts
(false alarms; on the realistic plant, flagged share among the worst-quarter houses vs the rest).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from benchlib.fit_protocol import (  # noqa: E402
    ACH,
    VAL_SEED,
    gateway_campaign,
    simulate_schedule,
    true_ranges,
    val_schedule,
)

from impctl.fit.estimator import NightFit  # noqa: E402
from impctl.fit.statespace.estimator import StateSpaceFit, fit_households  # noqa: E402
from impctl.imp.protocol import MIN_NIGHT_H  # noqa: E402
from impctl.population.households import sample_households  # noqa: E402
from impctl.population.imp_run.synth import sample_nights  # noqa: E402
from impctl.population.realism import sample_params  # noqa: E402

TWIN = Path("/work/shared/realdata/twinhouse")
TWIN_REF = {"N2": (126.4, 57.8e6, 127.0), "O5": (114.1, 47.6e6, 116.0)}
NAMES = ("hlc", "tau", "c_m")


def simulated(args):
    """[(nights, ranges, truth (hlc, c_m, tau), meter gain error, house type)] per household."""
    houses = sample_households(args.households, seed=VAL_SEED)
    n = houses.n_houses
    sched = val_schedule(n, argparse.Namespace(stop_at_t_min=True, band_k=None))
    sim, sp, _ = simulate_schedule(houses, sched, args.plant, stop_at_t_min=True)
    gate = gateway_campaign(sp, sched, need_h=MIN_NIGHT_H)
    meter = np.zeros(n)
    if args.plant == "realistic":
        meter = np.broadcast_to(np.asarray(sample_params(n, VAL_SEED).sensors.meter_gain_error,
                                           float), (n,))
    out = []
    for i in range(n):
        house = houses.take(i)
        nights = sample_nights(sim, sp, sched, i, sample_step_s=args.step, quantise_k=0.1,
                               power_noise=0.05 if args.plant == "iso" else 0.0,
                               seed=VAL_SEED + i)
        used = iter(gate["used"][:, i])
        nights = [x for x in nights if x.kind != "constrained" or next(used)]
        ranges = true_ranges(house) if args.ranges == "true" else None
        truth = (float(house.hlc_w_per_k), float(house.c_m_j_per_k), float(house.tau_h))
        out.append((nights, ranges, truth, float(meter[i])))
    return out


def twin(args):
    from impctl.imp.nights_csv import read_nights

    out = []
    for name, (hlc, c, tau) in TWIN_REF.items():
        nights = read_nights(TWIN / f"{name}_labelled.csv", tz="Etc/GMT-1")
        out.append((nights, None, (hlc, c, tau), 0.0))
    return out


def run_nightfit(jobs, args):
    res = []
    for nights, ranges, *_ in jobs:
        gain = {"night_gain_w": 0.0} if args.plant in ("iso", "twin") else {}
        try:
            f = NightFit(ach_vent=ACH[0], ach_infl=ACH[1], min_night_h=MIN_NIGHT_H, **gain
                         ).fit(nights, ranges)
            res.append({"lumped": f.lumped_, "time": f.fit_time_s_,
                        "adequate": f.adequacy_.get("adequate")})
        except Exception as exc:  # a household the fit refuses is counted as missing
            print(f"  NightFit failed: {exc}")
            res.append(None)
    return res


def run_statespace(jobs, args):
    gain = 0.0 if args.plant in ("iso", "twin") else None
    est = StateSpaceFit(night_gain_w=gain, ach_vent=ACH[0], ach_infl=ACH[1],
                        min_night_h=1.0)
    res = []
    for k in range(0, len(jobs), args.batch):
        part = jobs[k:k + args.batch]
        t0 = time.perf_counter()
        fits = fit_households([(n, r, None) for n, r, *_ in part], est)
        print(f"  state-space batch {k // args.batch}: {len(part)} households, "
              f"{time.perf_counter() - t0:.1f} s", flush=True)
        for f in fits:
            res.append({"lumped": f["lumped_"], "with_meter": f["lumped_with_meter_"],
                        "time": f["fit_time_s_"], "adequate": f["adequacy_"]["adequate"],
                        "adequacy": f["adequacy_"], "gain": f["night_gain_"]["value_w"],
                        "par": f["parameters_"], "converged": f["converged_"]})
    return res


def boot_ci(x, rng, n=2000):
    x = np.asarray(x)
    if len(x) < 3:
        return (np.nan, np.nan)
    meds = np.median(x[rng.integers(0, len(x), (n, len(x)))], axis=1)
    return tuple(np.percentile(meds, [2.5, 97.5]))


def score(res, jobs, key="lumped", meter_scale=True):
    """Per quantity: |rel. error| [%], covered (bool), half-width [%] per household."""
    out = {q: {"err": [], "cov": [], "hw": []} for q in NAMES}
    for r, (_, _, truth, g) in zip(res, jobs, strict=True):
        if r is None:
            continue
        t = {"hlc": truth[0], "c_m": truth[1], "tau": truth[2]}
        if meter_scale:
            t["hlc"] *= 1 + g
            t["c_m"] *= 1 + g
        for q in NAMES:
            e = r[key][q]
            out[q]["err"].append(100 * abs(e.value / t[q] - 1))
            out[q]["cov"].append(e.low <= t[q] <= e.high)
            out[q]["hw"].append(100 * 0.5 * (e.high - e.low) / e.value)
    return out


def table(label, sc, times, rng):
    print(f"\n{label}")
    print(f"  {'':5s} {'median |err| % [95% CI]':>26s} {'P90 %':>7s} {'coverage':>9s} "
          f"{'med. half-width %':>18s}")
    for q in NAMES:
        e = np.asarray(sc[q]["err"])
        lo, hi = boot_ci(e, rng)
        print(f"  {q:5s} {np.median(e):8.2f} [{lo:6.2f}, {hi:6.2f}]      "
              f"{np.percentile(e, 90):7.2f} {100 * np.mean(sc[q]['cov']):8.1f}% "
              f"{np.median(sc[q]['hw']):14.2f}")
    print(f"  fit time per household: {np.mean(times):.2f} s (n = {len(sc['hlc']['err'])})")


def adequacy_lines(res, sc, label):
    flags = np.array([not r["adequate"] for r in res if r is not None])
    print(f"  {label} adequacy: flagged {100 * flags.mean():.1f} % of {len(flags)} houses")
    if len(flags) >= 8:
        for q in ("hlc", "worst of three"):
            err = (np.asarray(sc["hlc"]["err"]) if q == "hlc" else
                   np.max([sc[k]["err"] for k in NAMES], axis=0))
            worst = err >= np.percentile(err, 75)
            print(f"    worst quarter by {q} |error|: flagged {100 * flags[worst].mean():.0f} %"
                  f" (n={worst.sum()}); the rest {100 * flags[~worst].mean():.0f} %")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plant", choices=("realistic", "iso", "twin"), default="realistic")
    ap.add_argument("--households", type=int, default=40)
    ap.add_argument("--ranges", choices=("true", "prior"), default="true")
    ap.add_argument("--step", type=float, default=300.0)
    ap.add_argument("--batch", type=int, default=20)
    ap.add_argument("--no-nightfit", dest="nightfit", action="store_false")
    ap.add_argument("--verbose", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(1)
    print("command: " + " ".join(["python"] + sys.argv))
    print(f"machine: {platform.processor() or platform.machine()}, torch {torch.__version__}, "
          "1 thread")
    jobs = twin(args) if args.plant == "twin" else simulated(args)
    rng = np.random.default_rng(0)
    ss = run_statespace(jobs, args)
    meter_scale = args.plant == "realistic"
    sc = score(ss, jobs, meter_scale=meter_scale)
    table("state-space (Kalman MAP, Laplace intervals" + (", meter scale)" if meter_scale
                                                            else ")"), sc,
          [r["time"] for r in ss], rng)
    if meter_scale:
        table("state-space, true scale (meter ±5 % type B added)",
              score(ss, jobs, "with_meter", False), [r["time"] for r in ss], rng)
    adequacy_lines(ss, sc, "state-space")
    if args.verbose or args.plant == "twin":
        for (_, _, truth, _), r in zip(jobs, ss, strict=True):
            q = r["lumped"]
            print("   ", "  ".join(
                f"{k} {q[k].value:.4g} [{q[k].low:.4g}, {q[k].high:.4g}] ref {t:.4g}"
                for k, t in zip(("hlc", "c_m", "tau"), truth, strict=True)),
                f"gain {r['gain']:.0f} W, adequate {r['adequate']}, "
                f"LB p {r['adequacy']['ljung_box_p']:.3f}, "
                f"var p {r['adequacy']['bartlett_p']:.3f}, "
                f"tau_e {r['par']['tau_emitter_h']:.2f} h, conv {r['converged']}")
    if args.nightfit:
        nf = run_nightfit(jobs, args)
        ok = [i for i, r in enumerate(nf) if r is not None]
        jobs_ok = [jobs[i] for i in ok]
        nf_ok = [nf[i] for i in ok]
        table("NightFit (today's, its own intervals" + (", meter scale)" if meter_scale
                                                        else ")"),
              score(nf_ok, jobs_ok, meter_scale=meter_scale), [r["time"] for r in nf_ok], rng)
        if meter_scale:
            table("NightFit, true scale", score(nf_ok, jobs_ok, meter_scale=False),
                  [r["time"] for r in nf_ok], rng)
        flags = np.array([r["adequate"] is False for r in nf_ok])
        print(f"  NightFit adequacy: flagged {100 * flags.mean():.1f} % of {len(flags)}")
        if args.plant == "twin":
            for (_, _, truth, _), r in zip(jobs_ok, nf_ok, strict=True):
                q = r["lumped"]
                print("   ", "  ".join(
                    f"{k} {q[k].value:.4g} [{q[k].low:.4g}, {q[k].high:.4g}] ref {t:.4g}"
                    for k, t in zip(("hlc", "c_m", "tau"), truth, strict=True)))


if __name__ == "__main__":
    main()
