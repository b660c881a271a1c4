"""Why the campaign bench leaves more households without a valid constrained night than the fit
bench (issue 18, branch hfloor): the two benches' constrained nights side by side, on each
other's households.

Run:  OMP_NUM_THREADS=1 nice .venv/bin/python bench/unidentified.py [--fit-households 50]
          [--campaign-households 150] [--nights 7]

``bench/fit.py --households 50`` (h14w) reports 7 of 50 households with no valid constrained
night; ``bench/campaign.py --households 150`` (h18f) 37 / 36 of 150 (adaptive / fixed). Both
draw ``sample_households(N, seed=20260)`` with ``sample_params(N, 20260)``, run the gateway's
constrained nights (ΔT 2.5 K, 2 h pre-heat, ended at T_min or the anticipated end, valid with
≥ ``night_protocol.MIN_NIGHT_H`` after the 1 h lag) on the realistic plant, and give up after
``campaign.max_invalid_nights`` invalid ones. What differs, each measured here:

* **the households**: ``sample_households`` draws each parameter as one vector of N values, so
  the 50 households of the fit bench are not the first 50 of the campaign bench's 150 (only
  the floor areas and the realism options are prefix-stable);
* **the nights**: the fit bench's constrained nights are nights 2 and 6 of its 2 + 6 plan (after
  a normal night at 22 / 24 °C), repeated on spare nights 9–11; the campaign bench's are
  nights 1, 2, … of a schedule of constrained nights only (each after a constrained night; the
  fixed 2 + 3 plan runs its constrained nights first, so its first three tries are nights 1–3);
* **the outdoor band**: the campaign bench counts a night whose first outdoor reading is above
  ``[night] t_out_max_c`` (8 °C) invalid, as the gateway refuses it; the fit bench does not;
* **the weather**: both draw each house's weather with seed 20260·1000 + h, but a schedule of
  another length draws other daily amplitudes, so night j is not the same night.

Per population and protocol: constrained nights too short (of those a campaign runs and of all
simulated), households with no valid constrained night among the first tries the gateway's
rule runs (``population.imp_run.gateway.campaign_runs``: until 2 valid or 3 invalid), with and
without the outdoor band; the outdoor temperatures of those nights; and the households' τ.
"""

from __future__ import annotations

import argparse
import sys
import time
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from _fit_protocol import VAL_SEED, gateway_campaign, short_constrained, val_schedule  # noqa: E402
from campaign_nights import variant_schedule  # noqa: E402

from impctl.config import CampaignConfig, NightConfig  # noqa: E402
from impctl.imp.protocol import DEFAULT_BAND_K, DEFAULT_CONSTRAINED_SETPOINT_C  # noqa: E402
from impctl.population.households import sample_households  # noqa: E402
from impctl.population.imp_run.gateway import campaign_runs  # noqa: E402
from impctl.population.imp_run.synth import run_schedule_plant  # noqa: E402
from impctl.population.realism import sample_params  # noqa: E402

T_OUT_MAX_C = NightConfig().t_out_max_c
CFG = CampaignConfig()


def constrained_nights(sim, sp, sched) -> dict[str, np.ndarray]:
    """Per constrained window (n_constrained, n_houses): too short (the gateway's rule), first
    outdoor-sensor reading [°C] (what the gateway checks at the start) and the window's mean
    outdoor temperature [°C]."""
    t_out = np.atleast_2d(np.asarray(sim.t_out_c).T).T
    wins = [(w0, w1) for _, kind, w0, w1, _ in sched.windows if kind == "constrained"]
    before = []   # what the night before each constrained night was
    for j, (_, kind, *_rest) in enumerate(sched.windows):
        if kind == "constrained":
            prev = sched.windows[j - 1] if j else None
            before.append(f"{j + 1} (after " + ("the owner's 21 °C" if prev is None else
                                                f"{prev[1][0]}{prev[4]:g}") + ")")
    return {"short": short_constrained(sp, sched), "before": before,
            "first_t_out": np.array([t_out[w0] for w0, _ in wins]),
            "mean_t_out": np.array([t_out[w0:w1].mean(axis=0) for w0, w1 in wins])}


def no_valid(short: np.ndarray, first_t_out: np.ndarray | None = None) -> np.ndarray:
    """Per house: no valid constrained night among those the gateway's rule runs (in order,
    until 2 valid or 3 invalid); with ``first_t_out`` a night starting above the band is
    invalid too."""
    valid = ~short
    if first_t_out is not None:
        valid &= first_t_out <= T_OUT_MAX_C
    run = campaign_runs(valid, CFG.constrained_nights, CFG.max_invalid_nights)
    return ~(run & valid).any(axis=0)


def fit_bench(houses, params, n: int) -> dict:
    """bench/fit.py's constrained nights (its 2 + 6 plan and 3 spares, the gateway's stops)."""
    sched = val_schedule(n, SimpleNamespace(stop_at_t_min=True, band_k=DEFAULT_BAND_K))
    sim, sp = run_schedule_plant(houses, sched, params, seed=VAL_SEED, stop_at_t_min=True)
    out = constrained_nights(sim, sp, sched)
    gate = gateway_campaign(sp, sched)
    out["no_valid_bench"] = ~gate["used"].any(axis=0)   # what bench/fit.py reports
    out["order"] = "nights 2, 6 (plan), 9, 10, 11 (spares)"
    return out


def campaign_bench(houses, params, n: int, k: int) -> dict:
    """bench/campaign.py's constrained nights (a schedule of k constrained nights)."""
    sched = variant_schedule(n, k, "constrained", DEFAULT_CONSTRAINED_SETPOINT_C, VAL_SEED)
    sim, sp = run_schedule_plant(houses, sched, params, seed=VAL_SEED, stop_at_t_min=True)
    out = constrained_nights(sim, sp, sched)
    out["order"] = f"nights 1 … {k}"
    return out


def pct(x) -> str:
    return f"{100.0 * np.mean(x):.0f} %"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit-households", type=int, default=50, help="0: skip")
    ap.add_argument("--campaign-households", type=int, default=150)
    ap.add_argument("--nights", type=int, default=7,
                    help="the campaign bench's simulated nights (max_nights + 2)")
    args = ap.parse_args()
    print("command: " + " ".join(["python"] + sys.argv))
    t0 = time.perf_counter()
    pops = {f"fit bench's {args.fit_households}": args.fit_households,
            f"campaign bench's {args.campaign_households}": args.campaign_households}
    pops = {k: v for k, v in pops.items() if v > 0}   # 0: skip that population
    rows, taus = [], {}
    for name, n in pops.items():
        houses, params = sample_households(n, seed=VAL_SEED), sample_params(n, VAL_SEED)
        taus[name] = np.asarray(houses.tau_h, float)
        for proto, res in (("fit bench", fit_bench(houses, params, n)),
                           ("campaign bench", campaign_bench(houses, params, n, args.nights))):
            rows.append((name, proto, res))
            print(f"  [{time.perf_counter() - t0:5.0f} s] {name} households, {proto}'s nights "
                  "simulated", file=sys.stderr, flush=True)
    print("\nτ of the households [h]: " + "; ".join(
        f"{k}: median {np.median(v):.1f}, P10 {np.percentile(v, 10):.1f}, P90 "
        f"{np.percentile(v, 90):.1f}, share < 30 h {pct(v < 30)}" for k, v in taus.items()))
    print("\nConstrained nights as each bench simulates them, on each bench's households "
          f"(ΔT {DEFAULT_BAND_K:g} K, realistic plant, seed {VAL_SEED}); 'no valid': households "
          "with no valid constrained night among the tries the gateway's rule runs (until "
          f"{CFG.constrained_nights} valid or {CFG.max_invalid_nights} invalid)\n")
    print("| households | nights of | which nights | too short, first 3 / all simulated | "
          f"first T_out > {T_OUT_MAX_C:g} °C | mean T_out of the nights, median °C | "
          "no valid (short only) | no valid (short or above the band) |")
    print("|---|---|---|---|---|---|---|---|")
    for name, proto, r in rows:
        n = r["short"].shape[1]
        nv = no_valid(r["short"])
        nvb = no_valid(r["short"], r["first_t_out"])
        print(f"| {name} | {proto} | {r['order']} | {pct(r['short'][:3])} / {pct(r['short'])} | "
              f"{pct(r['first_t_out'] > T_OUT_MAX_C)} | {np.median(r['mean_t_out']):.1f} | "
              f"{nv.sum()} of {n} ({pct(nv)}) | {nvb.sum()} of {n} ({pct(nvb)}) |")
    print("\nToo short by night (night number in the bench's schedule, what ran the night "
          "before), per population:")
    for name, proto, r in rows:
        print(f"  {name}, {proto}'s nights: " + "; ".join(
            f"{b} {pct(x)}" for b, x in zip(r["before"], r["short"], strict=True)))
    print("\nThe same nights tried in another order (no valid constrained night among the tries "
          "the gateway's rule runs, short only): consecutive nights against nights three "
          "days apart; and the outdoor temperature of short and valid nights:")
    orders = {"campaign bench": {"consecutive 1, 2, 3, …": [0, 1, 2, 3, 4, 5, 6],
                                 "three days apart 1, 4, 7": [0, 3, 6]},
              "fit bench": {"plan then spares 2, 6, 9, 10, 11": [0, 1, 2, 3, 4],
                            "spares only, consecutive 9, 10, 11": [2, 3, 4]}}
    for name, proto, r in rows:
        short, t_mean = r["short"], r["mean_t_out"]
        lag1 = np.corrcoef(t_mean[:-1].ravel(), t_mean[1:].ravel())[0, 1]
        print(f"  {name}, {proto}'s nights: " + "; ".join(
            f"{label} {no_valid(short[idx]).sum()}" for label, idx in orders[proto].items())
              + f"; mean T_out of short nights {np.median(t_mean[short]):.1f} °C, of valid "
              f"{np.median(t_mean[~short]):.1f} °C (median); correlation of one constrained "
              f"night's mean T_out with the next's {lag1:.2f}")
    print("\nPer τ band, both populations pooled (no valid, short only):")
    print("| τ band | fit bench's nights | campaign bench's nights |")
    print("|---|---|---|")
    edges = (0, 20, 30, 40, 60, 1e9)
    pooled_tau = np.concatenate(list(taus.values()))
    by = {proto: np.concatenate([no_valid(r["short"]) for _, p, r in rows if p == proto])
          for proto in ("fit bench", "campaign bench")}
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (pooled_tau >= lo) & (pooled_tau < hi)
        label = f"{lo:g}–{hi:g} h" if hi < 1e9 else f"≥ {lo:g} h"
        print(f"| {label} ({m.sum()}) | " + " | ".join(
            f"{by[p][m].sum()} ({pct(by[p][m]) if m.any() else '–'})" for p in by) + " |")
    fb = [r for _, p, r in rows if p == "fit bench"]
    print("\nbench/fit.py's own count (gateway_campaign): "
          + ", ".join(f"{r['no_valid_bench'].sum()} of {r['short'].shape[1]}" for r in fb))
    print(f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
