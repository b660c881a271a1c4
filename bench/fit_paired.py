"""Paired comparison of two ``bench/fit.py --dump`` runs on the same households.

Run:  python bench/fit_paired.py A.json B.json [--only identified-in-both|all] [--resamples 2000]
          [--a-per-night]

For each of HLC, τ, C_m and ε: median |error| [%] in A and B and the difference B − A of the
medians with a 95 % bootstrap interval over households (resampled together, so the pairing is
kept); coverage of the 95 % intervals in each; on the gateway's nights also the households
identified, the constrained nights paid and the comfort cost in each. ``--a-per-night`` takes
A's per-night average (the paper's way, ``pn_*`` in dumps since branch h14y) instead of A's
joint fit (no coverage: the average has no interval).
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def _load(path: str) -> dict:
    with open(path) as fh:
        return {k: np.asarray(v) for k, v in json.load(fh).items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--only", choices=("all", "identified-in-both"), default="all")
    ap.add_argument("--resamples", type=int, default=2000)
    ap.add_argument("--a-per-night", action="store_true")
    args = ap.parse_args()
    a, b = _load(args.a), _load(args.b)
    if args.a_per_night:
        a = {k: v for k, v in a.items() if not k.endswith("_covered")}
        a.update({k[3:]: v for k, v in a.items() if k.startswith("pn_")},
                 eps_pct=a["eps_pn_pct"])
    n = len(a["hlc_err_pct"])
    sel = np.ones(n, bool)
    if args.only == "identified-in-both":
        sel = (a.get("n_used", np.ones(n)) > 0) & (b.get("n_used", np.ones(n)) > 0)
    idx = np.flatnonzero(sel)
    rng = np.random.default_rng(0)
    boot = rng.integers(0, len(idx), (args.resamples, len(idx)))
    print(f"A = {args.a}, B = {args.b}; {len(idx)} of {n} households ({args.only})")
    print("| quantity | A median / P90 % | B median / P90 % | B − A median, pp (95 % CI) "
          "| coverage A / B % |")
    print("|---|---|---|---|---|")
    for q, key in (("HLC", "hlc"), ("τ", "tau"), ("C_m", "c_m"), ("ε", None)):
        ea = np.abs(a[f"{key}_err_pct"] if key else a["eps_pct"])[idx]
        eb = np.abs(b[f"{key}_err_pct"] if key else b["eps_pct"])[idx]
        d = np.nanmedian(eb[boot], axis=1) - np.nanmedian(ea[boot], axis=1)
        lo, hi = np.percentile(d, [2.5, 97.5])
        cov = (f"{100 * a[f'{key}_covered'][idx].mean():.0f} / "
               f"{100 * b[f'{key}_covered'][idx].mean():.0f}") if key and \
            f"{key}_covered" in a else "–"
        print(f"| {q} | {np.nanmedian(ea):.1f} / {np.nanpercentile(ea, 90):.1f} | "
              f"{np.nanmedian(eb):.1f} / {np.nanpercentile(eb, 90):.1f} | "
              f"{np.nanmedian(eb) - np.nanmedian(ea):+.1f} ({lo:+.1f} … {hi:+.1f}) | {cov} |")
    if "n_used" in a and "n_used" in b:
        for name, r in (("A", a), ("B", b)):
            print(f"{name}: identified {int((r['n_used'][idx] > 0).sum())}, constrained nights "
                  f"paid mean {r['paid'][idx].mean():.2f}, coldest T_air median "
                  f"{np.median(r['coldest_c'][idx]):.1f} °C, below the day setpoint per night "
                  f"median {np.median(r['kh_per_night'][idx]):.1f} K·h")


if __name__ == "__main__":
    main()
