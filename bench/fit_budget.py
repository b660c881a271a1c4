"""Error budget of the night fit on the realistic plant: what each group of realism costs.

Run:  .venv/bin/python bench/fit_budget.py [--households 50] [--rows none,only:air,...]
          [--stops recorded|own] [--no-stop-at-t-min] [--night-gain-w W] [--gain-prior-w W]
          [--signed-meter]

An ablation on exactly the households, weather, schedule, nights and seeds of
``bench/fit.py --households 50 --ranges true --plant realistic --steps 300 --no-lsq`` (the
protocol is imported from it: ``fit.run_step`` with the fit, ε and coverage it uses). Each
group of realism is either as ``impctl.population.realism.sample_params`` drew it for the
house (seed 20260) or at its ideal limit:

* ``meter_gain``: the heat meter's systematic gain error (±5 %) → 0;
* ``offsets``: the sensors' offsets (T_air ±1 K, T_out ±2 K) → 0;
* ``gains``: internal (night 100–400 W, drift) and solar gains → none (still drawn, so the
  sensor noise stays the same);
* ``noise``: the room and outdoor sensors' random noise → 0;
* ``sensors``: T_air quantisation and lag, the meter's noise and positive-only integration →
  perfect readings (the bench still rounds the logged T_air to 0.1 K, as ``bench/fit.py``
  does on both plants);
* ``air``: air and furniture capacity → 0 (all of C_m in the 5R1C mass);
* ``emitter``: radiator water and steel / underfloor screed and the buffer → a massless
  radiator (kind radiators, 0 J/K; underfloor houses keep their exponent and water
  temperature). The screed's range (130–250 kJ/(m²K)) has no zero: a massless underfloor
  emitter is a massless radiator;
* ``control``: the heat pump's control (weather curve / room thermostat, on/off cycling,
  modulation limits, ramp) → ``CONTROL_IDEAL`` (the Annex C demand at the air node);
* ``defrost``: the heat pump's defrosts → none. They act through the control only (the ideal
  control delivers the demand as it is), so ``only:defrost`` is ``none``; ``but:defrost``
  is what they cost.

The first three are what IMP nights cannot see: a gain error scales the metered power, an
offset shifts ΔT, a constant night gain looks like a lower HLC (README "Limits"). The row
``unseen`` (only those three on, each over its documented range) is the floor below which no
fit of these nights can go.

Rows (``--rows``, comma-separated, run in that order): ``all`` (bench/fit.py's houses), ``none``
(every group ideal), ``only:G[+G…]`` (those groups on, the rest ideal), ``but:G[+G…]`` (every
group on but those), ``unseen`` (= ``only:meter_gain+offsets+gains``). Per row: median / P90 of
|error| and the signed median of HLC, τ, C_m; heat-demand ε (median / P90, against the true
house replayed like the estimate, ``bench/fit.py --eps-truth house``); coverage of the 95 %
intervals (calibrated model-error share included, as the bench's default); fit time per house.

``--signed-meter``: every house's heat meter reads the negative heat of a defrost instead of 0
(the realistic population's meters count positive heat only; the ``sensors`` group off means
a perfect, signed meter too).

``--gain-prior-w W`` adds W to the metered power of every night before the fit: what a known
constant night gain (e.g. the documented range's midpoint, 250 W) would buy.

Nights (branch hfloor): the gateway's, as ``bench/fit.py``'s default since h14w — constrained
nights at ΔT ``night_protocol.DEFAULT_BAND_K`` ended at T_min or the gateway's anticipated end,
invalid with < ``night_protocol.MIN_NIGHT_H`` after the 1 h lag and repeated on spare nights
(``population.imp_run.gateway`` through ``bench/fit.py``'s ``run_step``); the fit gets the valid
ones. ``--stops recorded`` (default): every row's constrained nights end where the gateway ends
them on the **full** realistic house (all groups on: the nights the gateway records on these
houses), so the rows differ in the realism only, not in which nights are kept or how long they
are; ``--stops own``: the gateway's rule on each row's own plant (with the air and furniture
capacity off the room's air node is massless, drops 1–5 K at switch-off and the anticipated
end cuts most nights at the lag, as on the ideal 5R1C: the rows then also differ in their
nights). ``--no-stop-at-t-min``: the nights before (cooling to 05:00, all fitted; the floor of
README before hfloor). Households with no valid constrained night (not identified: τ and C_m
from the class ranges) are counted in every figure and printed apart. A row without gains
tells the fit 0 W of night gain (as ``bench/fit.py`` tells the ideal 5R1C) unless
``--night-gain-w`` is given; rows with gains use the fit's assumed 250 W.
"""

from __future__ import annotations

import argparse
import sys
import time
from contextlib import contextmanager, nullcontext
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import torch

sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))

import fit  # noqa: E402  (bench/fit.py's protocol)
from benchlib.fit_tables import rel, stats  # noqa: E402
from benchlib.realism_groups import GROUPS, ablate  # noqa: E402
from fit import VAL_SEED, run_step  # noqa: E402

from impctl.imp.protocol import DEFAULT_BAND_K, MIN_NIGHT_H  # noqa: E402
from impctl.plant.params import PlantParams  # noqa: E402
from impctl.population.households import sample_households  # noqa: E402
from impctl.population.realism import sample_params  # noqa: E402

#: What the nights cannot see (the floor row).
UNSEEN = ("meter_gain", "offsets", "gains")
DEFAULT_ROWS = (["none"] + [f"only:{g}" for g in GROUPS if g != "defrost"] + ["unseen", "all"]
                + [f"but:{g}" for g in GROUPS])


def groups_on(row: str) -> set[str]:
    """The groups a row spec switches on (module docstring)."""
    if row == "all":
        return set(GROUPS)
    if row == "none":
        return set()
    if row == "unseen":
        return set(UNSEEN)
    kind, _, names = row.partition(":")
    chosen = set(names.split("+"))
    if kind not in ("only", "but") or not chosen or not chosen <= set(GROUPS):
        raise SystemExit(f"--rows: {row!r}: use all, none, unseen, only:G[+G…] or but:G[+G…] "
                         f"with G in {', '.join(GROUPS)}")
    return chosen if kind == "only" else set(GROUPS) - chosen


def fit_args(realism, night_gain_w: float | None = None,
             night_gain_sd_w: float | None = None, stop_at_t_min: bool = True) -> SimpleNamespace:
    """``bench/fit.py``'s options for ``--ranges true --plant realistic --no-lsq`` (its
    defaults otherwise: the gateway's nights unless ``stop_at_t_min`` is False), with the
    ablated realism."""
    return SimpleNamespace(plant="realistic", normal_model="demand", starts=4, nuisance=True,
                           model_error=True, lsq=False, eps_truth="house", verbose=False,
                           model_dir=None, realism=realism, night_gain_w=night_gain_w,
                           night_gain_sd_w=night_gain_sd_w, stop_at_t_min=stop_at_t_min,
                           band_k=DEFAULT_BAND_K, valid_h=MIN_NIGHT_H, anticipate=True,
                           prior="default", prior_weight=1.0,
                           sensor_offsets_k=None, meter_error=None)


@contextmanager
def recorded_stops(full: PlantParams):
    """``bench/fit.py``'s simulation with every constrained night ended where the gateway ends
    it on the full realistic house (``full``: all groups on), whatever the row's realism: the
    row's plant replays those setpoints open loop (module docstring, ``--stops recorded``)."""
    simulate = fit.simulate_schedule

    def replay(houses_arr, sched, plant, realism=None, stop_at_t_min=False, anticipate=True):
        if not stop_at_t_min:
            return simulate(houses_arr, sched, plant, realism, False, anticipate)
        _, sp, _ = simulate(houses_arr, sched, plant, ("all", full, True), True, anticipate)
        logged, _, heat = simulate(houses_arr, replace(sched, setpoint_c=sp), plant, realism,
                                   False, anticipate)
        return logged, sp, heat

    fit.simulate_schedule = replay
    try:
        yield
    finally:
        fit.simulate_schedule = simulate


@contextmanager
def gain_prior(watts: float):
    """``bench/fit.py``'s nights with ``watts`` added to the metered power of every night: the
    fit told that the house has a constant night gain of that size (heat into the room either
    way), as a prior could tell it. 0: the nights unchanged."""
    sample = fit.sample_nights
    if watts:
        fit.sample_nights = lambda *a, **k: [replace(x, q_hc_w=x.q_hc_w + watts)
                                             for x in sample(*a, **k)]
    try:
        yield
    finally:
        fit.sample_nights = sample


def row_figures(res: dict) -> dict:
    truth = res["truth"]
    true = {"hlc": [h.hlc_w_per_k for h in truth], "tau": [h.tau_h for h in truth],
            "c_m": [h.c_m_j_per_k for h in truth]}
    out = {}
    for k, t in true.items():
        est = [f.lumped_[k] for f in res["fit"]]
        err = rel([e.value for e in est], t)
        out[k] = (*stats(err), float(np.nanmedian(err)))
        out[f"cov_{k}"] = 100.0 * np.mean([e.low <= v <= e.high
                                           for e, v in zip(est, t, strict=True)])
    out["eps"] = stats(res["eps_fit"])
    out["time"] = float(np.median(res["time"]))
    gate = res.get("gateway")
    ident = (np.ones(len(truth), bool) if gate is None
             else gate["used"][:, :len(truth)].any(axis=0))
    out["n_ident"] = int(ident.sum())
    for k, t in true.items():
        est = [f.lumped_[k] for f, keep in zip(res["fit"], ident, strict=True) if keep]
        err = rel([e.value for e in est], np.asarray(t)[ident])
        out[f"ident_{k}"] = (*stats(err), float(np.nanmedian(err)) if len(err) else np.nan)
    out["ident_eps"] = stats(np.asarray(res["eps_fit"])[ident])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=50)
    ap.add_argument("--rows", default=",".join(DEFAULT_ROWS),
                    help="row specs, comma-separated (module docstring)")
    ap.add_argument("--gain-prior-w", type=float, default=0.0, metavar="W",
                    help="add W to the metered power of every night (a known constant night "
                         "gain; the realism's night gains are drawn over 100–400 W)")
    ap.add_argument("--night-gain-w", type=float, default=None, metavar="W",
                    help="the fit's assumed night gain [W] (default the fit's, 250 W, and 0 W "
                         "on rows without gains)")
    ap.add_argument("--night-gain-sd-w", type=float, default=None, metavar="W",
                    help="SD of that assumption [W] (default the fit's, ≈ 87 W)")
    ap.add_argument("--no-stop-at-t-min", dest="stop_at_t_min", action="store_false",
                    help="constrained nights cool to 05:00 and are all fitted (the nights "
                         "before branch hfloor), not the gateway's")
    ap.add_argument("--signed-meter", action="store_true",
                    help="every house's heat meter reads negative heat (defrosts) instead of "
                         "0 (the realistic plant's meters count positive heat only)")
    ap.add_argument("--stops", choices=("recorded", "own"), default="recorded",
                    help="where the gateway's constrained nights end: as on the full realistic "
                         "house, every row (default), or by the rule on each row's own plant")
    args = ap.parse_args()
    torch.set_num_threads(1)
    rows = args.rows.split(",")
    for row in rows:
        groups_on(row)   # fail on a bad spec before any simulation
    print("command: " + " ".join(["python"] + sys.argv))
    n = args.households
    houses = sample_households(n, seed=VAL_SEED)
    full = sample_params(n, VAL_SEED)
    if args.signed_meter:
        full = full.with_section("sensors", meter_positive_only=0)
    nights = (f"the gateway's nights (ΔT {DEFAULT_BAND_K:g} K, stopped at T_min or its "
              f"anticipated end, valid ≥ {MIN_NIGHT_H:g} h after the lag; stops: {args.stops})"
              if args.stop_at_t_min else "constrained nights cooling to 05:00, all fitted")
    print(f"{n} households of bench/fit.py --ranges true --plant realistic, 5-min rows, "
          f"{nights}; median / P90 of |error| (signed median) %; ε against the true house; "
          "95 % coverage; identified: households with ≥ 1 valid constrained night, their "
          "median |error| HLC / τ / C_m / ε % apart")
    print("groups: " + "; ".join(f"{g} = {d}" for g, d in GROUPS.items()))
    print("| row | groups on | HLC % | τ % | C_m % | ε % | coverage HLC/τ/C_m % | identified | "
          "identified: HLC / τ / C_m / ε % | fit s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    recorded = args.stop_at_t_min and args.stops == "recorded"
    for row in rows:
        on = groups_on(row)
        t0 = time.perf_counter()
        params, gains = ablate(full, set(GROUPS) - on)
        # A row without gains tells the fit so (0 W), as bench/fit.py tells the ideal 5R1C:
        # else every such row carries the assumed 250 W's error (HLC +4 %, τ −6 % on "none").
        gain_w = args.night_gain_w if args.night_gain_w is not None or gains else 0.0
        with gain_prior(args.gain_prior_w), (recorded_stops(full) if recorded
                                             else nullcontext()):
            res = run_step(houses, 300.0, "true", fit_args((row, params, gains), gain_w,
                                                         args.night_gain_sd_w,
                                                         args.stop_at_t_min))
        f = row_figures(res)
        cells = [f"{f[k][0]:.1f} / {f[k][1]:.1f} ({f[k][2]:+.1f})" for k in ("hlc", "tau", "c_m")]
        names = "+".join(g for g in GROUPS if g in on) or "–"
        print(f"| {row} | {names} | " + " | ".join(cells)
              + f" | {f['eps'][0]:.1f} / {f['eps'][1]:.1f} | {f['cov_hlc']:.0f} / "
              f"{f['cov_tau']:.0f} / {f['cov_c_m']:.0f} | {f['n_ident']} of {n} | "
              + " / ".join(f"{f['ident_' + k][0]:.1f}" for k in ("hlc", "tau", "c_m", "eps"))
              + f" | {f['time']:.2f} |", flush=True)
        print(f"  ({row}: {time.perf_counter() - t0:.0f} s wall)", file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
