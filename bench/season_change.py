"""Change detection on simulated winters: is a step in the HLC found, how late, how often falsely?

The same held-out households, seed and plant as bench/season.py (realistic plant, the IMP
campaign every other night, the owner's nights between, cold and mild spells, setback, hot
water, defrosts, owner changes, the gains wandering). Half of them get a step in the HLC from
noon before a night drawn in [``--first``, nights − ``--last``): half of those −14 W/K (loft
insulation added) and half ``--window-w-k`` (a window left open; default +20 W/K, a tilted
window's ≈ 60 m³/h at 0.34 Wh/(m³K)); the other half nothing. Each household's export
(population.season_run.nights.household_nights, as the gateway writes it) is read by
``impctl.season.change`` night after night as the gateway would run it: the first night it says
"changed" is the alarm.

Figures: detection rate per kind of step (an alarm on a night after the step), the delay in
nights from the step to the alarm (median, P90), false alarms per house-season (every
household's season simulated again without its step — the same weather, owner and campaign —
that alarms at all: twice the seasons of the half without a step, which is printed too; and
alarms before the step in the others), the error of the
step's night and size, the coverage of the size's 95 % interval — each with a 95 % bootstrap
interval over households (bench/season_change_alternatives.py has the alternatives).
``--method cusum`` runs the alternative measured before choosing: a
two-sided CUSUM on the residuals of the same night model fitted to a reference window.
Two more alternatives were measured and not adopted (decision record 0036): ``--method
glr-level``, the same GLR with a free step in the gains level at the step's night, the statistic
the slope step's |t| given it, at its own thresholds (``LEVEL_THRESHOLDS``, set by
``--calibrate --method glr-level``); and ``--min-side BEFORE,AFTER``, the fewest usable nights
on each side of the step, with the thresholds its calibration sets (``--thresholds
WITH,WITHOUT``).

``--calibrate`` sets the thresholds instead: households without a step (``--seeds``, by
default 9001–9006, never a held-out seed: 4242 … 4747; every household has its own
weather), the test run night after night through the whole season without stopping at an
alarm, the season's largest statistic per household — once on the nights as exported, with the
household electricity, and once without it (most gateways record none), the two designs
:func:`impctl.season.change.threshold_for` tells apart. Each threshold is the one-sided 95 %
upper confidence bound of the 95th percentile of its statistics (an order statistic, free of any
distribution: at most one house-season in 20 alarms, with 95 % confidence — the percentile itself
would let half of all calibrations promise it and miss it) rounded up to 0.05, printed with the
false alarms at the current one and where they come from. ``--no-house-electricity``
drops the household electricity from every night of the bench's households.

    python bench/season_change.py --households 200
    python bench/season_change.py --households 200 --no-house-electricity
    python bench/season_change.py --households 200 --method cusum
    python bench/season_change.py --households 200 --seed 4343
    python bench/season_change.py --households 200 --method glr-level
    python bench/season_change.py --calibrate --households 320
    python bench/season_change.py --calibrate --households 320 --seeds 9001,9002 --method glr-level
    python bench/season_change.py --calibrate --households 320 --seeds 9001,9002 --min-side 12,12
    python bench/season_change.py --households 200 --min-side 12,12 --thresholds 3.35,3.50
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import multiprocessing as mp
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one BLAS thread per worker: 2 cores
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy.stats import binom  # noqa: E402
from season_change_alternatives import (  # noqa: E402  (bench/: the alternatives measured)
    LEVEL_THRESHOLDS,
    Variant,
    cusum_sequence,
    glr_variant,
    variant_sequence,
)

from impctl import change  # noqa: E402
from impctl.plant.params import RADIATORS, UNDERFLOOR  # noqa: E402
from impctl.population.households import sample_households  # noqa: E402
from impctl.population.realism import sample_params  # noqa: E402
from impctl.population.season_run.nights import household_nights  # noqa: E402
from impctl.population.season_run.season import SeasonConfig, simulate_season  # noqa: E402

_SEASON = None
#: The bench's held-out households' seed, the calibration's (never the same), and the other
#: held-out seeds that measured the false alarms again (never calibrated on either).
BENCH_SEED, CALIBRATION_SEEDS = 4242, (9001, 9002, 9003, 9004, 9005, 9006)
HELD_OUT_SEEDS = (BENCH_SEED, 4343, 4444, 4545, 4646, 4747)
#: The false alarms per house-season the threshold is set for [-], and the step the threshold
#: is rounded up to [-].
FALSE_ALARM_TARGET, THRESHOLD_STEP = 0.05, 0.05



def steps(n: int, nights: int, seed: int, window_w_k: float, first: int,
          last: int) -> tuple[np.ndarray, np.ndarray]:
    """(step [W/K], step night) per household: a quarter −14, a quarter ``window_w_k``, half 0."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0xC4A6]))
    kind = rng.permutation(np.arange(n) % 4)
    size = np.where(kind == 0, -14.0, np.where(kind == 1, window_w_k, 0.0))
    return size, rng.integers(first, nights - last, n)


def without_house_electricity(rows: change.NightRows) -> change.NightRows:
    """``rows`` as a gateway without a household electricity meter exports them."""
    return change.NightRows(rows.dates, rows.q_w, rows.dt_k, rows.fall_k, rows.defrost,
                            rows.memory_k, np.full(len(rows), np.nan))


#: The variant the workers run (set before they fork); None: the product's test itself.
_VARIANT: Variant | None = None


def _statistic(rows: change.NightRows) -> tuple[float, int, float, float]:
    return change.glr(rows) if _VARIANT is None else glr_variant(rows, _VARIANT)


def _threshold(rows: change.NightRows) -> float:
    return change.threshold_for(rows) if _VARIANT is None else _VARIANT.threshold(rows)


def season_max(rows: change.NightRows) -> dict:
    """The largest statistic over a whole season run night after night (no stop at an alarm):
    its value [-], the nights read then, the step's night index k, and the first nights read
    at which the statistic passed the rows' threshold (:func:`impctl.season.change.threshold_for`,
    or the variant's; None if never)."""
    best: dict = {"max_stat": 0.0, "at_nights": None, "k": None, "first_alarm_nights": None}
    threshold = _threshold(rows)
    for m in range(max(change.MIN_NIGHTS, 2 * change.MIN_SIDE), len(rows) + 1):
        stat, k, _, _ = _statistic(rows.head(m))
        if not math.isfinite(stat):
            continue
        if stat >= threshold and best["first_alarm_nights"] is None:
            best["first_alarm_nights"] = m
        if stat > best["max_stat"]:
            best.update(max_stat=float(stat), at_nights=m, k=int(k))
    return best


def _run(job: tuple[int, str, bool, bool]) -> dict:
    h, method, no_house, calibrating = job
    s = _SEASON
    t0 = time.perf_counter()
    rows = change.night_rows(household_nights(s, h))
    if no_house:
        rows = without_house_electricity(rows)
    row: dict = {"household": h, "nights": len(rows)}
    if calibrating:
        row.update(season_max(rows))
        row["no_house"] = season_max(without_house_electricity(rows))
    elif method in ("glr", "glr-level") and _VARIANT is not None:
        at, k, delta, se = variant_sequence(rows, _VARIANT)
        half = change.Z95 * change.SIZE_SCALE * se
        row.update(alarm_date=rows.dates[at - 1] if at > 0 else None,
                   since_date=rows.dates[k] if at > 0 else None,
                   delta_w_k=delta if at > 0 else None,
                   low_w_k=delta - half if at > 0 else None,
                   high_w_k=delta + half if at > 0 else None)
    elif method == "glr":
        at, c = change.detect_sequence(rows)
        row.update(alarm_date=rows.dates[at - 1] if at > 0 else None,
                   since_date=c.since_date if at > 0 else None,
                   delta_w_k=c.delta_hlc_w_k if at > 0 else None,
                   low_w_k=c.low_w_k if at > 0 else None,
                   high_w_k=c.high_w_k if at > 0 else None)
    else:
        at, k = cusum_sequence(rows)
        row.update(alarm_date=rows.dates[at - 1] if at > 0 else None,
                   since_date=rows.dates[k] if at > 0 else None,
                   delta_w_k=None, low_w_k=None, high_w_k=None)
    row["test_s"] = time.perf_counter() - t0
    return row


def _boot(x: np.ndarray, stat, rng: np.random.Generator, n: int = 2000) -> tuple:
    if len(x) == 0:
        return (math.nan, math.nan)
    idx = rng.integers(0, len(x), (n, len(x)))
    vals = np.array([stat(x[i]) for i in idx])
    return float(np.percentile(vals, 2.5)), float(np.percentile(vals, 97.5))


def _day(d: str) -> int:
    return dt.date.fromisoformat(d).toordinal()


def _false_alarms(null: list[dict], rng: np.random.Generator) -> dict:
    fa = np.array([r["alarm_date"] is not None for r in null], float)
    return {"rate": float(fa.mean()), "ci": _boot(fa, np.mean, rng), "households": len(null),
            "tested": int(sum(r["nights"] >= change.MIN_NIGHTS for r in null))}


def summarize(rows: list[dict], size: np.ndarray, night: np.ndarray, dates: list[str],
              null_rows: list[dict]) -> dict:
    """Detection, delay, false alarms and the step's estimate (module docstring);
    ``null_rows``: every household's season simulated again without a step."""
    rng = np.random.default_rng(0)
    out: dict = {}
    by_h = {r["household"]: r for r in rows}
    out["false_alarms"] = _false_alarms(null_rows, rng)
    out["false_alarms_stepless_half"] = _false_alarms(
        [by_h[h] for h in np.flatnonzero(size == 0)], rng)
    for kind in sorted({float(x) for x in size[size != 0]}):
        hs = np.flatnonzero(size == kind)
        det, delay, early, since_err, d_err, cover = [], [], [], [], [], []
        for h in hs:
            r, step_date = by_h[h], dates[night[h]]
            alarm = r["alarm_date"]
            if alarm is not None and alarm < step_date:
                early.append(1.0)
                det.append(0.0)
                continue
            early.append(0.0)
            det.append(float(alarm is not None))
            if alarm is None:
                continue
            delay.append(_day(alarm) - _day(step_date))
            since_err.append(_day(r["since_date"]) - _day(step_date))
            if r["delta_w_k"] is not None:
                d_err.append(r["delta_w_k"] - kind)
                cover.append(float(r["low_w_k"] <= kind <= r["high_w_k"]))
        det_a, delay_a = np.array(det), np.array(delay, float)
        out[f"{kind:+g}"] = {
            "households": len(hs), "detected": float(det_a.mean()),
            "detected_ci": _boot(det_a, np.mean, rng),
            "delay_median": float(np.median(delay_a)) if len(delay_a) else math.nan,
            "delay_median_ci": _boot(delay_a, np.median, rng),
            "delay_p90": float(np.percentile(delay_a, 90)) if len(delay_a) else math.nan,
            "delay_p90_ci": _boot(delay_a, lambda x: np.percentile(x, 90), rng),
            "early_alarms": float(np.mean(early)),
            "since_abs_err_median": (float(np.median(np.abs(since_err))) if since_err
                                     else math.nan),
            "size_err_median": float(np.median(d_err)) if d_err else math.nan,
            "size_coverage": float(np.mean(cover)) if cover else math.nan,
        }
    # False alarms per house-season: the no-step houses, and the step houses before the step.
    early_all = [1.0 if (by_h[h]["alarm_date"] is not None
                         and by_h[h]["alarm_date"] < dates[night[h]]) else 0.0
                 for h in np.flatnonzero(size != 0)]
    out["early_alarms"] = float(np.mean(early_all)) if early_all else math.nan
    return out


def upper_quantile(x: np.ndarray, q: float, confidence: float = 0.95) -> float:
    """The one-sided ``confidence`` upper bound of ``x``'s ``q`` quantile: the smallest order
    statistic X₍ₖ₎ with P(Bin(n, q) < k) ≥ ``confidence`` (no distribution assumed)."""
    xs = np.sort(np.asarray(x, float))
    k = int(binom.ppf(confidence, len(xs), q)) + 1
    return float(xs[min(k, len(xs)) - 1])


def calibrate_summary(rows: list[dict], hlc_w_k: np.ndarray, emitter: np.ndarray,
                      threshold_now: float) -> dict:
    """The threshold for :data:`FALSE_ALARM_TARGET` false alarms per house-season (the
    season's largest statistic's 95th percentile, with a bootstrap interval), the false alarms
    at ``threshold_now``, and where they come from: emitter, house size, when in the season,
    how many nights on the short side of the step. ``rows`` in the order of ``hlc_w_k``."""
    rng = np.random.default_rng(0)
    by_h = rows
    mx = np.array([r["max_stat"] for r in by_h])
    alarm = np.array([r["first_alarm_nights"] is not None for r in by_h], float)
    q = 1.0 - FALSE_ALARM_TARGET
    out: dict = {"households": len(mx), "threshold_now": threshold_now,
                 "threshold_q95": float(np.quantile(mx, q)),
                 "threshold_q95_upper": upper_quantile(mx, q),
                 # the constant: the bound rounded up to THRESHOLD_STEP (never above target)
                 "threshold_set": math.ceil(upper_quantile(mx, q) / THRESHOLD_STEP - 1e-9)
                 * THRESHOLD_STEP,
                 "threshold_q95_ci": _boot(mx, lambda x: np.quantile(x, q), rng),
                 "false_alarms_now": float(alarm.mean()),
                 "false_alarms_now_ci": _boot(alarm, np.mean, rng)}
    thirds = np.quantile(hlc_w_k, [1 / 3, 2 / 3])
    groups = {"radiators": emitter == RADIATORS, "underfloor": emitter == UNDERFLOOR,
              f"HLC < {thirds[0]:.0f} W/K": hlc_w_k < thirds[0],
              f"HLC {thirds[0]:.0f}–{thirds[1]:.0f} W/K": (hlc_w_k >= thirds[0])
              & (hlc_w_k < thirds[1]),
              f"HLC ≥ {thirds[1]:.0f} W/K": hlc_w_k >= thirds[1]}
    out["by_group"] = {k: {"households": int(g.sum()), "false_alarms": float(alarm[g].mean()),
                           "q95": float(np.quantile(mx[g], q))} for k, g in groups.items()}
    first = [r["first_alarm_nights"] for r in by_h if r["first_alarm_nights"] is not None]
    out["first_alarm_nights"] = sorted(first)
    short = [min(r["k"], r["at_nights"] - r["k"]) for r in by_h
             if r["first_alarm_nights"] is not None]
    out["short_side_nights_at_max"] = sorted(short)
    return out


def print_calibration(sm: dict, design: str) -> None:
    """The calibration's figures for one design (:func:`calibrate_summary`)."""
    print(f"{design}:")
    print(f"threshold for ≤ {100 * FALSE_ALARM_TARGET:.0f} % false alarms per house-season: "
          f"95th percentile {sm['threshold_q95']:.2f} {_fmt(sm['threshold_q95_ci'], 2)}, "
          f"its one-sided 95 % upper bound {sm['threshold_q95_upper']:.2f}, rounded up "
          f"{sm['threshold_set']:.2f} (now "
          f"{sm['threshold_now']:.2f}: {100 * sm['false_alarms_now']:.1f} % "
          f"{_fmt(sm['false_alarms_now_ci'], 1, 100)} false alarms)")
    for k, g in sm["by_group"].items():
        print(f"  {k:>22}: {g['households']:4d} households, false alarms "
              f"{100 * g['false_alarms']:5.1f} %, 95th percentile {g['q95']:.2f}")
    print(f"  nights read at the first false alarm: {sm['first_alarm_nights']}")
    print(f"  nights on the short side of the step then: {sm['short_side_nights_at_max']}")


def _fmt(ci: tuple, digits: int = 0, scale: float = 1.0) -> str:
    return f"[{ci[0] * scale:.{digits}f}, {ci[1] * scale:.{digits}f}]"


def _pair(kind: type):
    def parse(text: str) -> tuple:
        try:
            a, b = (kind(x) for x in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r}: give two numbers, e.g. 12,12") from None
        return a, b
    return parse


def _seeds(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give seeds, e.g. 9001,9002") from None


def _test_all(n: int, method: str, no_house: bool, workers: int, t0: float,
              calibrating: bool = False) -> list[dict]:
    """The test on every household of :data:`_SEASON` (forked workers), in household order."""
    print(f"testing {n} households …", file=sys.stderr, flush=True)
    rows: list[dict] = []
    jobs = [(h, method, no_house, calibrating) for h in range(n)]
    with mp.get_context("fork").Pool(workers) as pool:
        for i, row in enumerate(pool.imap_unordered(_run, jobs, chunksize=2), 1):
            rows.append(row)
            if i % 20 == 0 or i == n:
                print(f"  {i}/{n} households, {time.perf_counter() - t0:.0f} s",
                      file=sys.stderr, flush=True)
    return sorted(rows, key=lambda r: r["household"])


def calibrate(args: argparse.Namespace, argv: list[str] | None) -> None:
    """Households without a step of every seed of ``args.seeds``, both designs (module
    docstring): the thresholds and where the false alarms come from."""
    global _SEASON
    n, rows, hlc, emitter = args.households, [], [], []
    t0 = time.perf_counter()
    for seed in args.seeds:
        houses, params = sample_households(n, seed=seed), sample_params(n, seed)
        print(f"seed {seed}: simulating {n} households × {args.nights} nights …",
              file=sys.stderr, flush=True)
        _SEASON = simulate_season(houses, params, SeasonConfig(nights=args.nights), seed=seed,
                                  hlc_step_w_k=np.zeros(n), step_night=np.zeros(n, int))
        rows += [{**r, "seed": seed} for r in _test_all(n, args.method, False, args.workers, t0,
                                                      calibrating=True)]
        hlc.append(np.asarray(houses.hlc_w_per_k, float))
        emitter.append(np.asarray(params.emitter.kind))
    hlc_a, em_a = np.concatenate(hlc), np.concatenate(emitter)
    print(f"$ python bench/season_change.py {' '.join(argv if argv is not None else sys.argv[1:])}")
    print(f"{len(rows)} households without a step (realistic plant, seeds "
          f"{', '.join(map(str, args.seeds))}, {args.nights} nights, each its own weather); "
          f"{time.perf_counter() - t0:.0f} s")
    with_house = [{k: v for k, v in r.items() if k != "no_house"} for r in rows]
    no_house = [r["no_house"] for r in rows]
    summary = {}
    now = (_VARIANT.thresholds if _VARIANT is not None
           else (change.THRESHOLD, change.THRESHOLD_NO_HOUSE))
    for design, rs, now_d in (("with household electricity", with_house, now[0]),
                              ("without household electricity", no_house, now[1])):
        summary[design] = calibrate_summary(rs, hlc_a, em_a, now_d)
        print_calibration(summary[design], design)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"rows": rows, "summary": summary, "args": vars(args)}, fh, indent=1)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=200)
    ap.add_argument("--nights", type=int, default=80, help="nights simulated per household")
    ap.add_argument("--seed", type=int, default=BENCH_SEED, help="the bench's households")
    ap.add_argument("--seeds", type=_seeds, default=CALIBRATION_SEEDS,
                    help="with --calibrate: the seeds of the households, --households each "
                         f"(default {','.join(map(str, CALIBRATION_SEEDS))})")
    ap.add_argument("--window-w-k", type=float, default=20.0,
                    help="the open window's step in HLC [W/K]")
    ap.add_argument("--first", type=int, default=25, help="earliest step night")
    ap.add_argument("--last", type=int, default=20, help="nights kept after the latest step")
    ap.add_argument("--method", choices=("glr", "glr-level", "cusum"), default="glr",
                    help="the product's statistic, the alternative with a free step in the "
                         "gains level at the same night, or a CUSUM (module docstring)")
    ap.add_argument("--min-side", type=_pair(int), default=None, metavar="BEFORE,AFTER",
                    help="a variant: the fewest usable nights before and after the step "
                         f"(the product: {change.MIN_SIDE},{change.MIN_SIDE})")
    ap.add_argument("--thresholds", type=_pair(float), default=None, metavar="WITH,WITHOUT",
                    help="the variant's thresholds with and without the household electricity "
                         f"(the product: {change.THRESHOLD},{change.THRESHOLD_NO_HOUSE}; "
                         f"glr-level: {LEVEL_THRESHOLDS[0]},{LEVEL_THRESHOLDS[1]})")
    ap.add_argument("--calibrate", action="store_true",
                    help="set the thresholds on households without a step (module docstring)")
    ap.add_argument("--no-house-electricity", action="store_true",
                    help="drop the household electricity from every night (the calibration "
                         "runs both designs)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", default=None, help="write the rows and the summary here")
    args = ap.parse_args(argv)
    global _VARIANT
    if args.method == "glr-level" or args.min_side or args.thresholds:
        if args.method == "cusum":
            ap.exit(2, "season_change.py: --min-side and --thresholds are the GLR's\n")
        level = args.method == "glr-level"
        before, after = args.min_side or (change.MIN_SIDE, change.MIN_SIDE)
        _VARIANT = Variant(level, before, after, args.thresholds or (
            LEVEL_THRESHOLDS if level else (change.THRESHOLD, change.THRESHOLD_NO_HOUSE)))
    if args.calibrate:
        if args.method == "cusum":
            ap.exit(2, "season_change.py: --calibrate sets the GLR's thresholds: --method glr "
                       "or glr-level\n")
        held = sorted(set(args.seeds) & set(HELD_OUT_SEEDS))
        if held:
            ap.exit(2, f"season_change.py: --seeds: {held[0]} is a held-out seed "
                       f"({', '.join(map(str, HELD_OUT_SEEDS))}); calibrate on others\n")
        calibrate(args, argv)
        return
    global _SEASON
    n = args.households
    houses, params = sample_households(n, seed=args.seed), sample_params(n, args.seed)
    size, night = steps(n, args.nights, args.seed, args.window_w_k, args.first, args.last)
    t0 = time.perf_counter()
    print(f"simulating {n} households × {args.nights} nights …", file=sys.stderr, flush=True)
    _SEASON = simulate_season(houses, params, SeasonConfig(nights=args.nights), seed=args.seed,
                              hlc_step_w_k=size, step_night=night)
    sim_s = time.perf_counter() - t0
    dates = [d for d, *_ in _SEASON.nights]
    rows = _test_all(n, args.method, args.no_house_electricity, args.workers, t0)
    # The false alarms on every household's season without its step (the same weather, owner
    # and campaign: a household without a step has the same season in both runs), twice the
    # seasons the stepless half alone gives.
    print(f"simulating the {n} households again without a step …", file=sys.stderr, flush=True)
    _SEASON = simulate_season(houses, params, SeasonConfig(nights=args.nights), seed=args.seed,
                              hlc_step_w_k=np.zeros(n), step_night=np.zeros(n, int))
    null_rows = _test_all(n, args.method, args.no_house_electricity, args.workers, t0)
    print(f"$ python bench/season_change.py {' '.join(argv if argv is not None else sys.argv[1:])}")
    sm = summarize(rows, size, night, dates, null_rows)
    print(f"{n} households (realistic plant, seed {args.seed}, {args.nights} nights"
          f"{', no household electricity' if args.no_house_electricity else ''}), "
          f"method {args.method}; season simulated in {sim_s:.0f} s, the test "
          f"{np.median([r['test_s'] for r in rows]):.1f} s per household-season (median)")
    fa, half = sm["false_alarms"], sm["false_alarms_stepless_half"]
    print(f"false alarms per house-season (every household without its step): "
          f"{100 * fa['rate']:.1f} % {_fmt(fa['ci'], 1, 100)} of {fa['households']} "
          f"({fa['tested']} with enough nights to test); of the {half['households']} without a "
          f"step in this run: {100 * half['rate']:.1f} %; before the step in the others: "
          f"{100 * sm['early_alarms']:.1f} %")
    print(f"{'step W/K':>9} {'houses':>6} {'detected % [95 % CI]':>22} "
          f"{'delay nights median [CI]':>26} {'P90 [CI]':>16} {'since ±nights':>13} "
          f"{'size err W/K':>12} {'coverage':>8}")
    for key, q in sm.items():
        if not isinstance(q, dict) or "detected" not in q:
            continue
        print(f"{key:>9} {q['households']:>6} {100 * q['detected']:7.0f} "
              f"{_fmt(q['detected_ci'], 0, 100):>14} {q['delay_median']:8.0f} "
              f"{_fmt(q['delay_median_ci']):>17} {q['delay_p90']:5.0f} "
              f"{_fmt(q['delay_p90_ci']):>10} {q['since_abs_err_median']:13.0f} "
              f"{q['size_err_median']:12.1f} {100 * q['size_coverage']:7.0f}%")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"rows": rows, "null_rows": null_rows, "summary": sm, "args": vars(args),
                       "size_w_k": size.tolist(), "step_night": night.tolist()}, fh, indent=1)


if __name__ == "__main__":
    main()
