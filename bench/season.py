"""The season model against the energy signature, on simulated winters of realistic households.

Each household runs a season on the realistic plant (impctl.population.season_run.season: the IMP
campaign every other night, the owner's own nights between, cold and mild spells, night
setback, hot water, defrosts, owner changes). For every N in ``--owner-nights`` the household's
record is cut when its N-th plain owner night is over, exported as the gateway would
(population.season_run.nights.household_nights: owner records noon to noon, IMP nights, the
pre-heats not recorded) and fitted by ``impctl.season`` — the same path as ``impctl fit``.
Beside it, the energy signature of the same owner nights (00:00–05:00 means). Errors against
the true house; medians and P90 with 95 % bootstrap intervals; coverage and median
half-width of the 95 % intervals, and that half-width as a multiple of the median error with
its bootstrap interval (the households resampled); the fit's wall time. The row ``HLCm`` is
the HLC against the heat meter's own scale (the true HLC × (1 + the house's meter gain
error), class 2/3 meters ±5 %): what no method reading that meter can do better than — the
rest of the error is the model's.

    python bench/season.py --households 200 --owner-nights 14,28
    python bench/season.py --households 40 --variant signed
    python bench/season.py --households 100 --imp constrained   # a campaign without normal nights
    python bench/season.py --households 100 --constrained-hours 3   # shorter constrained nights
    python bench/season.py --households 200 --declared-emitter   # the installer declares it
    python bench/season.py --households 200 --owner-nights 28 --nights 90 --ideal drift
        # the error budget: one group of realism at its ideal limit, the rest as drawn
    python bench/season.py --calibrate --households 150 --seed 31 --owner-nights 7,14,28,56 \
        --nights 90   # the intervals' scale and floor
    python bench/season.py --households 10 --owner-nights 0,7,14 --figure curve.png
    python bench/season.py --from-json saved.json --figure curve.png   # redraw, no fits
    python bench/season.py --pool a.json,b.json   # saved runs of several seeds as one

``--owner-nights`` may hold 0: the household's IMP nights alone (the whole campaign, no owner
record) fitted on ``impctl fit``'s path with the true class ranges (benchlib/season_imp.py),
the same households as the other counts. ``--figure`` draws the error against the owner nights
(benchlib/season_figure.py) after the run or, with ``--from-json``, from a saved ``--json``
without refitting; a run without its own 0-night point draws bench/fit.py's figure of record
there, marked as other households. A saved JSON the figure cannot use is refused in one line
naming the file and the key, exit status 2, nothing written.

``--pool A.json,B.json`` prints the table of saved ``--json`` runs (other seeds, the same
settings) pooled as one population: the medians, P90, their bootstrap intervals and the
coverage over all their households; each run saves its households' true values for it.

``--calibrate`` fits households of another seed with the raw intervals and prints, per
quantity, the sandwich scale and model-error floor (benchlib/season_calibration.py: at least
92 % coverage at every owner-night count, the narrowest median interval);
``--calibrate-from A.json,B.json`` pools saved ``--calibrate --json`` runs (the constants of
``impctl.season.fit``).
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import os
import sys
import time
from dataclasses import replace

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one BLAS thread per worker: 2 cores
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from benchlib.realism_groups import GAIN_PARTS, GROUPS, ablate  # noqa: E402
from benchlib.season_figure import (  # noqa: E402
    SavedError,
    check_target,
    draw,
    format_published,
    load_saved,
)

# The simulation's and the fits' modules (seconds to import) load in run() and the fit
# functions only: --from-json redraws a saved run without them. The workers are forked after
# run() loaded them.

_SEASON = None
_HOUSES = None
#: per household the emitter its installer declares (``--declared-emitter``), else None
_DECLARED: list | None = None
_RAW = False
_P_HOUSE = False
_IMP = "all"
_CONSTRAINED_H = None
#: Groups ``--ideal`` takes: the IMP budget's, the gains split into their walk and the sun.
IDEAL_GROUPS = [g for g in GROUPS if g != "gains"] + list(GAIN_PARTS)
QUANTITIES = {"hlc_w_per_k": "HLC", "tau_h": "tau", "c_m_j_per_k": "C_m"}


def cutoff(s, h: int, n_owner: int) -> int | None:
    """The sample after the noon that follows household ``h``'s ``n_owner``-th plain owner
    night (None when the season has fewer)."""
    seen = 0
    for j, (_, kinds, _a, b) in enumerate(s.nights):
        if kinds[h] == "owner" and not s.labels[j, h]:
            seen += 1
            if seen == n_owner:
                return b + int(round(7 * 3600 / s.sample_s))
    return None


def _fit(job: tuple[int, int]) -> dict:
    from impctl.population.season_run.nights import household_nights
    from impctl.season.fit import LUMPED, Z95, fit_nights, fit_season
    from impctl.season.nights import record_from_nights

    h, n_owner = job
    s = _SEASON
    # 0: the whole season, whose IMP nights alone are fitted (the campaign ends in its first weeks)
    end = cutoff(s, h, n_owner) if n_owner else s.t_air_c.shape[0]
    row = {"household": h, "owner_nights": n_owner}
    if end is None:
        return {**row, "status": "season too short"}
    t0 = time.perf_counter()
    nights = household_nights(s, h, upto_sample=end)
    if not _P_HOUSE:   # most gateways do not read the household electricity
        nights = [replace(n, p_house_w=math.nan, p_house_series_w=None) for n in nights]
    if _IMP != "all" and n_owner:  # the campaign shrunk: which IMP nights the model reads
        keep = ("constrained",) if _IMP == "constrained" else ()
        nights = [n for n in nights if n.kind == "owner" or n.kind in keep]
    if _CONSTRAINED_H is not None:
        nights = [shorten(n, _CONSTRAINED_H) if n.kind == "constrained" and not n.phase else n
                  for n in nights]
    if n_owner == 0:
        return _fit_imp(row, h, nights, t0)
    if _RAW:
        try:
            fit = fit_season(record_from_nights(nights), calibrated=False)
        except (ValueError, np.linalg.LinAlgError) as exc:
            return {**row, "status": str(exc)}
        row["se"] = {k: math.log(fit.high[k] / fit.values[k]) / Z95 for k in LUMPED}
    else:
        fit, note = fit_nights(nights, emitter=None if _DECLARED is None else _DECLARED[h])
    row["fit_s"] = time.perf_counter() - t0
    if fit is None:
        return {**row, "status": note or "no fit"}
    row.update(status="ok", imp_nights=fit.imp_nights, emitter=fit.emitter,
               owner_nights_used=fit.owner_nights,
               signature_hlc_w_per_k=fit.signature_hlc_w_per_k,
               **{f"{k}": fit.values[k] for k in LUMPED},
               **{f"{k}_low": fit.low[k] for k in LUMPED},
               **{f"{k}_high": fit.high[k] for k in LUMPED})
    return row


def shorten(night, hours: float):
    """The constrained night ended ``hours`` after its switch-off: the rows after it left
    out (as if the heat pump had been given back then; the season model bridges the gap)."""
    from dataclasses import fields

    keep = night.time_s - night.time_s[0] <= hours * 3600.0
    n = len(night.time_s)
    cut = {f.name: getattr(night, f.name)[keep] for f in fields(night)
           if isinstance(getattr(night, f.name), np.ndarray)
           and len(getattr(night, f.name)) == n}
    return replace(night, **cut)


def _fit_imp(row: dict, h: int, nights: list, t0: float) -> dict:
    """The 0-owner-night row: household ``h``'s IMP nights alone (benchlib/season_imp.py)."""
    from benchlib.season_imp import fit_imp_nights

    out, note = fit_imp_nights(nights, _HOUSES.take(h))
    row["fit_s"] = time.perf_counter() - t0
    if out is None:
        return {**row, "status": note or "no fit"}
    return {**row, "status": "ok", "signature_hlc_w_per_k": math.nan, **out}


def _boot_ci(x: np.ndarray, q: float, rng: np.random.Generator, n: int = 2000) -> tuple:
    idx = rng.integers(0, len(x), (n, len(x)))
    qs = np.percentile(x[idx], q, axis=1)
    return float(np.percentile(qs, 2.5)), float(np.percentile(qs, 97.5))


def _ratio_ci(half: np.ndarray, err: np.ndarray, rng: np.random.Generator,
              n: int = 2000) -> tuple:
    """95 % bootstrap interval of median(half-width) / median(|error|), the households
    resampled with both their numbers (the two medians share them)."""
    idx = rng.integers(0, len(err), (n, len(err)))
    r = np.median(half[idx], axis=1) / np.maximum(np.median(err[idx], axis=1), 1e-12)
    return float(np.percentile(r, 2.5)), float(np.percentile(r, 97.5))


def summarize(rows: list[dict], truth: dict[str, np.ndarray], n_owner: int) -> dict:
    """Per quantity: median and P90 of |error| [%] with bootstrap CIs, coverage, half-width
    and its ratio to the median error (with its bootstrap CI)."""
    rng = np.random.default_rng(0)
    ok = [r for r in rows if r["owner_nights"] == n_owner and r["status"] == "ok"]
    out: dict = {"owner_nights": n_owner, "households": sum(r["owner_nights"] == n_owner
                                                           for r in rows),
                 "fitted": len(ok),
                 "fit_s_median": float(np.median([r["fit_s"] for r in ok])) if ok else math.nan,
                 # the IMP fit alone: households without a valid constrained night
                 "unidentified": sum(r.get("identified") is False for r in ok)}
    h = np.array([r["household"] for r in ok], int)
    scales = [(k, name, truth[k]) for k, name in QUANTITIES.items()]
    if "meter_gain" in truth:   # HLC on the heat meter's own scale (module docstring)
        scales.append(("hlc_w_per_k", "HLC_meter",
                       truth["hlc_w_per_k"] * (1.0 + truth["meter_gain"])))
    for k, name, truth_k in scales:
        est = np.array([r[k] if r[k] is not None else np.nan for r in ok], float)
        given = np.isfinite(est)
        if name in QUANTITIES.values():
            out[f"{name}_missing"] = int((~given).sum())
        est, hk = est[given], h[given]
        true = truth_k[hk]
        err = 100 * np.abs(est / true - 1)
        lo = np.array([r[f"{k}_low"] for r in ok], float)[given]
        hi = np.array([r[f"{k}_high"] for r in ok], float)[given]
        cover = (lo <= true) & (true <= hi)
        half = 100 * (hi - lo) / 2 / est
        if not len(err):   # not given for any household (e.g. τ and C_m without a normal night)
            nan = math.nan
            out[name] = {"median_pct": nan, "median_ci": (nan, nan), "p90_pct": nan,
                         "p90_ci": (nan, nan), "coverage": nan, "half_width_pct": nan,
                         "width_ratio": nan, "width_ratio_ci": (nan, nan)}
            continue
        out[name] = {"median_pct": float(np.median(err)), "median_ci": _boot_ci(err, 50, rng),
                     "p90_pct": float(np.percentile(err, 90)), "p90_ci": _boot_ci(err, 90, rng),
                     "coverage": float(cover.mean()), "half_width_pct": float(np.median(half)),
                     "width_ratio": float(np.median(half) / max(np.median(err), 1e-12)),
                     "width_ratio_ci": _ratio_ci(half, err, rng)}
    sig = np.array([r["signature_hlc_w_per_k"] for r in ok])
    good = np.isfinite(sig)
    if not good.any():   # no owner night: the IMP fit alone
        out["signature"] = None
        return out
    err = 100 * np.abs(sig[good] / truth["hlc_w_per_k"][h[good]] - 1)
    out["signature"] = {"median_pct": float(np.median(err)), "median_ci": _boot_ci(err, 50, rng),
                        "p90_pct": float(np.percentile(err, 90)), "n": int(good.sum())}
    return out


def _fmt(ci: tuple) -> str:
    return f"[{ci[0]:.1f}, {ci[1]:.1f}]"


def _fmt2(ci: tuple) -> str:
    return f"[{ci[0]:.2f}, {ci[1]:.2f}]"


def _refuse(exc: SavedError) -> None:
    """One line on stderr, exit status 2 (nothing has been written)."""
    print(f"bench/season.py: {exc}", file=sys.stderr)
    raise SystemExit(2)


def _owner_nights(text: str) -> list[int]:
    try:
        ns = [int(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give counts of nights, e.g. 0,7,14") from None
    if any(n < 0 for n in ns) or len(set(ns)) != len(ns):
        raise argparse.ArgumentTypeError(f"{text!r}: give distinct counts of 0 or more nights")
    return ns


def _ideal_groups(text: str) -> list[str]:
    out = [g for g in text.split(",") if g]
    bad = [g for g in out if g not in IDEAL_GROUPS]
    if bad:
        raise argparse.ArgumentTypeError(f"{bad[0]!r} is not a group of realism: use "
                                         + ", ".join(IDEAL_GROUPS))
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=200)
    ap.add_argument("--owner-nights", type=_owner_nights, default=[14, 28],
                    help="counts of owner nights to fit at (comma-separated; 0: the IMP "
                         "nights alone on impctl fit's path)")
    ap.add_argument("--nights", type=int, default=80, help="nights simulated per household")
    ap.add_argument("--seed", type=int, default=4242)
    ap.add_argument("--variant", choices=("realistic", "signed", "p_house", "ideal"),
                    default="realistic",
                    help="signed: the heat meter reads a defrost's draw as negative heat; "
                         "p_house: the household electricity is measured ([inputs]); "
                         "ideal: the ideal 5R1C (no emitter, furniture, sensor faults)")
    ap.add_argument("--imp", choices=("all", "constrained", "none"), default="all",
                    help="the IMP nights the season model reads: all of them, the constrained "
                         "ones only (a campaign without normal nights), none")
    ap.add_argument("--constrained-hours", type=float, default=None, metavar="H",
                    help="end every constrained night H hours after its switch-off (the rows "
                         "after it left out): does a shorter night still give τ?")
    ap.add_argument("--declared-emitter", action="store_true",
                    help="every house's emitter declared, as an installer declares it "
                         "([fit] emitter): the plant's own kind")
    ap.add_argument("--ideal", type=_ideal_groups, default=[], metavar="G[,G…]",
                    help="these groups of realism at their ideal limit (the error budget; "
                         f"{', '.join(IDEAL_GROUPS)}): benchlib/realism_groups.py")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", default=None, help="write the rows and the summary here")
    ap.add_argument("--figure", default=None,
                    help="draw the error against the owner nights into this PNG")
    ap.add_argument("--from-json", default=None, metavar="SAVED",
                    help="draw --figure from a saved --json run, without fitting")
    ap.add_argument("--pool", default=None, metavar="RUNS",
                    help="the table of saved --json runs (comma-separated) pooled as one "
                         "population; no fits")
    ap.add_argument("--calibrate", action="store_true",
                    help="raw intervals: print the scale and floor of the intervals")
    ap.add_argument("--calibrate-from", default=None, metavar="RUNS",
                    help="the scale and floor from saved --calibrate --json runs "
                         "(comma-separated), pooled; no fits")
    args = ap.parse_args(argv)
    if args.calibrate_from is not None:
        from benchlib.season_calibration import from_saved

        from_saved(args.calibrate_from.split(","))
        return
    if args.pool is not None:
        try:
            _pool(args.pool.split(","))
        except SavedError as exc:
            _refuse(exc)
        return
    if args.from_json is not None and args.figure is None:
        ap.error("--from-json draws a figure: give --figure FILE.png")
    if args.calibrate and (args.figure is not None or 0 in args.owner_nights):
        ap.error("--calibrate fits the season model only: no --figure, no 0 owner nights")
    try:
        if args.figure is not None:
            check_target(args.figure)
        if args.from_json is not None:
            saved = load_saved(args.from_json)
            _draw(saved["summary"], saved["args"], args.figure)
            return
    except SavedError as exc:
        _refuse(exc)
    run(args, argv)


def _draw(summary: list[dict], run_args: dict, path: str) -> None:
    if draw(summary, run_args, path):
        print(format_published())
    print(f"figure written to {path}")


def run(args: argparse.Namespace, argv: list[str] | None) -> None:
    """Simulate, fit, print the table; the JSON and the figure when asked."""
    global _SEASON, _HOUSES, _RAW, _P_HOUSE, _IMP, _CONSTRAINED_H, _DECLARED
    import impctl.season.fit  # noqa: F401  (loaded once, before the workers fork)
    from impctl.population.households import sample_households
    from impctl.population.realism import sample_params
    from impctl.population.season_run.season import SeasonConfig, simulate_season

    if 0 in args.owner_nights:
        import benchlib.season_imp  # noqa: F401
    _RAW, _P_HOUSE, _IMP = args.calibrate, args.variant == "p_house", args.imp
    _CONSTRAINED_H = args.constrained_hours
    n = args.households
    houses, params = sample_households(n, seed=args.seed), sample_params(n, args.seed)
    _HOUSES = houses
    if args.declared_emitter:
        from impctl.plant.params import RADIATORS

        _DECLARED = ["radiators" if int(k) == RADIATORS else "underfloor"
                     for k in np.broadcast_to(np.asarray(params.emitter.kind), (n,))]
    if args.variant == "signed":
        params = params.with_section("sensors", meter_positive_only=0)
    elif args.variant == "ideal":     # ISO 13790's 5R1C itself, the gains as on every plant
        from impctl.plant.params import PlantParams

        params = PlantParams.ideal().with_section("gains", **vars(params.gains))
    if args.ideal:
        params, _ = ablate(params, set(args.ideal))
    t0 = time.perf_counter()
    print(f"simulating {n} households × {args.nights} nights …", file=sys.stderr, flush=True)
    # the season's own sensors (the flow and return pair) go with the plant's
    water = ({"water_offset_k": 0.0, "flow_wander": 0.0, "water_lag_s": 0.0}
             if "sensors" in args.ideal else {})
    _SEASON = simulate_season(houses, params, SeasonConfig(nights=args.nights, **water),
                              seed=args.seed)
    sim_s = time.perf_counter() - t0
    truth = {"hlc_w_per_k": np.asarray(houses.hlc_w_per_k, float),
             "tau_h": np.asarray(houses.tau_h, float),
             "c_m_j_per_k": np.asarray(houses.c_m_j_per_k, float),
             "meter_gain": np.broadcast_to(np.asarray(params.sensors.meter_gain_error, float),
                                           (n,))}
    ns = sorted(args.owner_nights)
    jobs = [(h, k) for k in ns for h in range(n)]
    rows: list[dict] = []
    with mp.get_context("fork").Pool(args.workers) as pool:
        for i, row in enumerate(pool.imap_unordered(_fit, jobs, chunksize=2), 1):
            rows.append(row)
            if i % 20 == 0 or i == len(jobs):
                print(f"  {i}/{len(jobs)} fits, {time.perf_counter() - t0:.0f} s",
                      file=sys.stderr, flush=True)
    command = f"$ python bench/season.py {' '.join(argv if argv is not None else sys.argv[1:])}"
    saved_args = {**vars(args), "owner_nights": ",".join(str(k) for k in ns),
                  "ideal": ",".join(args.ideal)}
    if args.calibrate:
        from benchlib.season_calibration import arrays, calibrate

        print(command)
        calibrate(arrays(rows, truth, args.variant))
        if args.json:
            with open(args.json, "w") as fh:
                json.dump({"rows": rows, "args": saved_args}, fh, indent=1)
        return
    summaries = [summarize(rows, truth, k) for k in ns]
    print(command)
    ideal = f", ideal: {', '.join(args.ideal)}" if args.ideal else ""
    print(f"{n} households ({args.variant} plant{ideal}, seed {args.seed}), season simulated "
          f"in {sim_s:.0f} s; the fits: {args.workers} processes; IMP nights read: {args.imp}")
    _print_table(summaries)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"rows": rows, "summary": summaries, "args": saved_args,
                       "truth": {k: np.asarray(v).tolist() for k, v in truth.items()}},
                      fh, indent=1)
    if args.figure:
        _draw(summaries, saved_args, args.figure)


def _print_table(summaries: list[dict]) -> None:
    """The run's table: per owner-night count and quantity, the |error| and the intervals."""
    print(f"{'owner nights':>12} {'qty':>4} {'median % [95 % CI]':>22} {'P90 % [95 % CI]':>22} "
          f"{'coverage':>8} {'half-width %':>12} {'× median [95 % CI]':>20}")
    for sm in summaries:
        label = sm["owner_nights"] or "0 (IMP)"
        for name in QUANTITIES.values():
            q = sm[name]
            if not math.isfinite(q["median_pct"]):
                print(f"{label:>12} {name:>4} {'—':>6}   not given ({sm[name + '_missing']} "
                      "without)")
                continue
            print(f"{label:>12} {name:>4} {q['median_pct']:6.1f} "
                  f"{_fmt(q['median_ci']):>15} {q['p90_pct']:6.1f} {_fmt(q['p90_ci']):>15} "
                  f"{100 * q['coverage']:7.1f}% {q['half_width_pct']:12.1f} "
                  f"{q['width_ratio']:6.2f} {_fmt2(q['width_ratio_ci']):>13}"
                  + (f"  ({sm[name + '_missing']} without)" if sm[name + "_missing"] else ""))
        mq = sm.get("HLC_meter")
        if mq is not None:
            print(f"{label:>12} {'HLCm':>4} {mq['median_pct']:6.1f} "
                  f"{_fmt(mq['median_ci']):>15} {mq['p90_pct']:6.1f} {_fmt(mq['p90_ci']):>15} "
                  f"{100 * mq['coverage']:7.1f}%   (HLC on the heat meter's scale)")
        sg = sm["signature"]
        if sg is not None:
            print(f"{label:>12} {'sig':>4} {sg['median_pct']:6.1f} "
                  f"{_fmt(sg['median_ci']):>15} {sg['p90_pct']:6.1f} {'':>15}   (energy "
                  f"signature HLC, {sg['n']} households)")
        print(f"{'':>12} fitted {sm['fitted']}/{sm['households']}, median fit "
              f"{sm['fit_s_median']:.1f} s"
              + (f"; {sm['unidentified']} without a valid constrained night (their normal "
                 "nights fitted, τ and C_m from the class ranges)" if sm["unidentified"] else ""))


def _pool(paths: list[str]) -> None:
    """Saved ``--json`` runs of the same settings (other seeds) as one population: their rows
    and true values concatenated, the households numbered on, and the table printed."""
    rows: list[dict] = []
    truth: dict[str, list] = {}
    counts: set[tuple] = set()
    seeds = []
    for path in paths:
        saved = load_saved(path)
        if "truth" not in saved:
            raise SavedError(path, "truth", "was saved without the true values (run it again "
                             "with this bench)")
        n = len(saved["truth"]["hlc_w_per_k"])
        offset = len(truth.get("hlc_w_per_k", []))
        for r in saved["rows"]:
            rows.append({**r, "household": r["household"] + offset})
        for k, v in saved["truth"].items():
            truth.setdefault(k, []).extend(v[:n])
        a = saved["args"]
        counts.add((a["owner_nights"], a["variant"], a["imp"], a["nights"]))
        seeds.append(str(a["seed"]))
    if len(counts) > 1:
        raise SavedError(paths[-1], "args", "other settings than the first run's (owner "
                         "nights, variant, IMP nights or nights): pool runs of one setting")
    ns = sorted({r["owner_nights"] for r in rows})
    arrays = {k: np.asarray(v, float) for k, v in truth.items()}
    print(f"$ python bench/season.py --pool {','.join(paths)}")
    owner, variant, imp, nights = counts.pop()
    print(f"{len(arrays['hlc_w_per_k'])} households pooled from {len(paths)} runs ({variant} "
          f"plant, seeds {', '.join(seeds)}, {nights} nights, IMP nights read: {imp})")
    _print_table([summarize(rows, arrays, k) for k in ns])


if __name__ == "__main__":
    main()
