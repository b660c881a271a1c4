"""Adaptive IMP campaign (issue 18) against the fixed 2 + 3 campaign, on the realistic plant.

Run:  nice .venv/bin/python bench/campaign.py [--households 100] [--plant realistic|iso]
          [--targets 0.05/0.08,0.25/0.25] [--max-nights 5] [--step-s 300] [--processes 2]
          [--strategies adaptive,unreachable,fixed]

Households: ``sample_households(N, seed=20260)`` with realism ``sample_params(N, 20260)`` (the
validation population of ``bench/fit.py``), class ranges the true classes (as the realistic
rows of the README's fit table). Each household gets its own winter weather. For every night
index j (K = max_nights + 2, spares for skipped nights) every candidate night — constrained at
21 °C (pre-heat 4 h to 22.5 °C) and normal at 21, 22 and 23 °C — is pre-simulated on the same
weather and gains (the four variants as four schedules of the same houses, every night of a
schedule of one variant, days at 21 °C in between); a campaign then replays, night by night,
the variant it chooses. Logged: room and outdoor sensors, heat meter, 5-minute samples.

Strategies, each on every household (``--strategies``; fits of identical night sets are shared
between strategies and targets):

* **adaptive** — :func:`impctl.campaign.decide` with the candidates and the 2-night outlook of
  :func:`impctl.campaign.design.predict` (the fit after every valid night);
* **unreachable** — adaptive with ``floor_dominance = 0``: stops as soon as the floor alone
  (sensor offsets, meter, night gains, structure/model-error shares) misses the target, however
  wide the statistical part still is;
* **order** — fixed order, adaptive stop: the same stop/skip rules, the default order, no
  predictions (the floor rule on the fit's own floor): separates stopping from choosing;
* **fixed** — today's 2 + 3 plan: constrained, constrained, normal 21, 22, 23 °C; an invalid
  night is repeated; one fit at the end.

Forecast of a night: the mean outdoor temperature of the previous night (persistence: the
daemon's own history); a night whose forecast is outside the band −25…8 °C is skipped, one
whose first outdoor reading is outside it is run but invalid. The plant is simulated once in
the parent; the campaigns run in ``--processes`` forked workers (households interleaved), one
torch thread each. Reported per strategy and target: nights run (median, P90), share whose
final fit meets the target, final-interval coverage of the true HLC and τ, median |error|,
median final half-widths, stop reasons.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import platform
import sys
import time
from dataclasses import replace

os.environ.setdefault("OMP_NUM_THREADS", "1")   # one thread per process, before numpy/torch

import numpy as np  # noqa: E402

from impctl.campaign import Candidate, FitSummary, NightRecord, Outlook, Target, decide  # noqa: E402
from impctl.campaign.design import Protocol, predict  # noqa: E402
from impctl.fit.optim.batch import fit_households  # noqa: E402
from impctl.fit.report import fit_to_dict  # noqa: E402
from impctl.population.households import sample_households  # noqa: E402
from impctl.population.realism import sample_params  # noqa: E402
from impctl.population.synth_nights import (  # noqa: E402
    imp_schedule,
    run_schedule,
    run_schedule_plant,
    sample_nights,
)

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from fit import ACH, true_ranges  # noqa: E402  (bench/fit.py: the same validation setup)

SEED = 20260
VARIANTS = (("constrained", 21.0), ("normal", 21.0), ("normal", 22.0), ("normal", 23.0))
BAND_C = (-25.0, 8.0)
PREHEAT_H = 4.0       # imp_schedule's constrained pre-heat
FIXED = (0, 0, 1, 2, 3)   # today's plan: constrained first, then 21, 22, 23 °C
STRATEGIES = {"adaptive": "adaptive", "unreachable": "adaptive, stop when unreachable",
              "order": "fixed order, adaptive stop", "fixed": "fixed 2 + 3"}
AHEAD = 2             # the outlook's nights


class Progress:
    def __init__(self, every_s: float = 5.0, prefix: str = ""):
        self.every_s, self.t0, self.last, self.prefix = every_s, time.monotonic(), 0.0, prefix

    def __call__(self, text: str, force: bool = False) -> None:
        now = time.monotonic()
        if force or now - self.last >= self.every_s:
            self.last = now
            print(f"  [{now - self.t0:6.0f} s]{self.prefix} {text}", flush=True)


def simulate_variants(n: int, k: int, plant: str, step_s: float, progress: Progress):
    """nights[v][i][j], forecast[i][j] [°C], first outdoor reading[v][i][j] [°C]."""
    houses = sample_households(n, seed=SEED)
    params = sample_params(n, SEED) if plant == "realistic" else None
    nights, first_t_out = [], []
    forecast = None
    for kind, sp in VARIANTS:
        sched = imp_schedule(n, n_constrained=k if kind == "constrained" else 0,
                             n_normal=0 if kind == "constrained" else k, setpoints_c=(sp,),
                             seed=SEED)
        if plant == "realistic":
            sim, spc = run_schedule_plant(houses, sched, params, seed=SEED)
            t_out, noise = sim.t_out_c, 0.0
        else:
            sim, spc = run_schedule(houses, sched)
            t_out, noise = sched.t_out_c, 0.05
        per_day = int(round(86400 / sched.dt_s))
        if forecast is None:   # persistence: last night's mean outdoor temperature
            forecast = np.array([[float(np.mean(t_out[w0 - per_day:w1 - per_day, i]))
                                  for _, _, w0, w1, _ in sched.windows] for i in range(n)])
        first_t_out.append(np.array([[float(t_out[w0, i]) for _, _, w0, _, _ in sched.windows]
                                     for i in range(n)]))
        nights.append([sample_nights(sim, spc, sched, i, sample_step_s=step_s, quantise_k=0.1,
                                     power_noise=noise, seed=SEED + i) for i in range(n)])
        progress(f"simulated variant {kind} {sp:g} °C for {n} households", force=True)
    return houses, nights, forecast, first_t_out


class Fits:
    """Fits by (household, chosen (night, variant) pairs), computed in batches, shared."""

    def __init__(self, houses, nights, protocol: Protocol, step_s: float, progress: Progress):
        self.houses, self.nights, self.protocol, self.step_s = houses, nights, protocol, step_s
        self.progress = progress
        self.cache: dict[tuple, dict | None] = {}
        self.predictions: dict[tuple, tuple[list[Candidate], Outlook | None]] = {}
        self.count, self.seconds = 0, 0.0

    def ensure(self, keys: list[tuple], batch: int = 16) -> None:
        todo = sorted({k for k in keys if k not in self.cache})
        for b in range(0, len(todo), batch):
            chunk = todo[b:b + batch]
            t0 = time.perf_counter()
            fits, _ = fit_households(
                [[self.nights[v][i][j] for j, v in plan] for i, plan in chunk],
                [true_ranges(self.houses.take(i)) for i, _ in chunk],
                ach_vent=ACH[0], ach_infl=ACH[1])
            for key, f in zip(chunk, fits, strict=True):
                self.cache[key] = None if isinstance(f, BaseException) else fit_to_dict(f)
            self.count += len(chunk)
            self.seconds += time.perf_counter() - t0
            self.progress(f"fits: {self.count} done ({self.seconds / self.count:.2f} s each), "
                          f"{len(todo) - b - len(chunk)} to go in this round")

    def candidates(self, key: tuple, forecast_c: float) -> tuple[list[Candidate],
                                                                 Outlook | None]:
        result = self.cache.get(key)
        if result is None:
            return [], None
        memo = (key, round(forecast_c, 3))
        if memo not in self.predictions:
            try:
                self.predictions[memo] = predict(
                    result, forecast_c, constrained_setpoint_c=21.0,
                    normal_setpoints_c=(21.0, 22.0, 23.0), step_s=self.step_s,
                    protocol=self.protocol, ahead=AHEAD)
            except (KeyError, TypeError, ValueError):
                self.predictions[memo] = ([], None)
        return self.predictions[memo]


class Campaign:
    """One strategy on one household."""

    def __init__(self, i: int, strategy: str, target: Target):
        self.i, self.strategy, self.target = i, strategy, target
        self.history: list[NightRecord] = []
        self.chosen: list[tuple[int, int]] = []     # (night index, variant) of valid nights
        self.fits: list[FitSummary] = []
        self.key: tuple | None = None
        self.done, self.reached, self.reason = False, False, ""
        self.predicted: tuple[float, float] | None = None   # of the night just run
        self.checks: list[tuple[float, float]] = []   # refit / predicted half-width, HLC τ

    def fit_key(self) -> tuple | None:
        kinds = {VARIANTS[v][0] for _, v in self.chosen}
        return (self.i, tuple(self.chosen)) if len(kinds) == 2 else None


def step(c: Campaign, j: int, fits: Fits, forecast: float, first_t_out: list) -> int | None:
    """Decide night j for campaign c; returns the variant run or None."""
    if c.done:
        return None
    if c.strategy == "fixed":
        n_valid = len(c.chosen)
        if n_valid >= len(FIXED):
            c.done, c.reason = True, "plan complete"
            return None
        v = FIXED[n_valid]
    else:
        cands, outlook = [], None
        if c.strategy in ("adaptive", "unreachable") and c.key is not None:
            cands, outlook = fits.candidates(c.key, forecast)
        target = (replace(c.target, floor_dominance=0.0) if c.strategy == "unreachable"
                  else c.target)
        d = decide(c.history, c.fits, cands, target, forecast_t_out_c=forecast,
                   t_out_band_c=BAND_C, constrained_setpoint_c=21.0,
                   normal_setpoints_c=(21.0, 22.0, 23.0), outlook=outlook)
        if d.action == "stop":
            c.done, c.reached, c.reason = True, d.reached, d.reason
            return None
        if d.action == "skip":
            return None
        v = VARIANTS.index((d.kind, d.setpoint_c))
        c.predicted = next(((x.hlc_rel_pred, x.tau_rel_pred) for x in cands
                            if (x.kind, x.setpoint_c) == (d.kind, d.setpoint_c)), None)
    valid = BAND_C[0] <= first_t_out[v][c.i][j] <= BAND_C[1]
    if not valid:
        c.predicted = None
    c.history.append(NightRecord(*VARIANTS[v], valid))
    if valid:
        c.chosen.append((j, v))
    return v


def run(target: Target, fits: Fits, forecast, first_t_out, k: int, households: list[int],
        strategies: list[str]) -> list:
    camps = [Campaign(i, s, target) for s in strategies for i in households]
    for j in range(k):
        ran = [c for c in camps if step(c, j, fits, float(forecast[c.i][j]), first_t_out)
               is not None]
        keys = [c.fit_key() for c in ran]
        need = [key for c, key in zip(ran, keys, strict=True)
                if key is not None and c.chosen and c.chosen[-1][0] == j
                and (c.strategy != "fixed" or len(c.chosen) == len(FIXED))]
        fits.ensure(need)
        for c in ran:
            key = c.fit_key()
            if key is None or key not in fits.cache or c.key == key:
                continue
            c.key = key
            result = fits.cache[key]
            if result is not None:
                c.fits.append(FitSummary.from_fit_json(result, len(c.chosen)))
                if c.predicted is not None:
                    c.checks.append((c.fits[-1].hlc_rel / c.predicted[0],
                                     c.fits[-1].tau_rel / c.predicted[1]))
            c.predicted = None
        fits.progress(f"target {target.hlc_rel:.0%}/{target.tau_rel:.0%}: night {j + 1}/{k}, "
                      f"{sum(not c.done for c in camps)} campaigns running", force=True)
    for c in camps:
        if not c.done:
            c.reason = ("plan complete" if c.strategy == "fixed" and len(c.chosen) >= len(FIXED)
                        else "ran out of simulated nights")
    return camps


def _label(c: Campaign) -> str:
    if c.reached:
        return "target reached"
    for text, label in (("most this", "max nights"), ("precision limited", "precision limited"),
                        ("would not help", "no gain"), ("cannot be", "cannot be identified")):
        if text in c.reason:
            return label
    return c.reason


def _record(c: Campaign) -> tuple:
    """What the parent needs of a finished campaign (picklable)."""
    final = c.fits[-1] if c.key is not None and c.fits else None
    return (c.strategy, c.i, len(c.history), final, _label(c), c.fits, c.reason, c.checks)


def _trajectories(records: list, houses, strategy: str) -> None:
    """Per household: each fit's ±HLC/±τ [%] (floor in brackets), errors, and why it stopped."""
    print(f"\n{STRATEGIES[strategy]}: per household, each fit ±HLC/±τ % [floor] (error %)")
    for r in sorted((r for r in records if r[0] == strategy), key=lambda r: r[1]):
        h = houses.take(r[1])
        steps = " → ".join(
            f"{f.nights}: {100 * f.hlc_rel:.0f}/{100 * f.tau_rel:.0f} "
            f"[{100 * f.hlc_floor_rel:.0f}/{100 * f.tau_floor_rel:.0f}] "
            f"({100 * (f.hlc_w_per_k / h.hlc_w_per_k - 1):+.0f}/"
            f"{100 * (f.tau_h / h.tau_h - 1):+.0f})" for f in r[5])
        print(f"  {r[1]:3d} {r[2]} nights: {steps} — {r[6][:90]}")


def summarise(records: list, houses, target: Target, strategies: list[str]) -> None:
    print(f"\nTarget: HLC ±{target.hlc_rel:.0%}, τ ±{target.tau_rel:.0%} (95 % half-width / "
          f"estimate), max {target.max_nights} nights, stall {target.stall_nights} nights")
    print(f"{'strategy':<28} {'nights med/P90':>14} {'reached':>8} {'no fit':>7} "
          f"{'cover HLC/τ':>12} {'|err| HLC/τ %':>14} {'±HLC/τ % med':>13}  stopped by")
    rows = []
    for s in strategies:
        sub = [r for r in records if r[0] == s]
        nights = np.array([r[2] for r in sub])
        got = [r for r in sub if r[3] is not None]
        cov_h, cov_t, err_h, err_t, w_h, w_t = [], [], [], [], [], []
        for _, i, _, f, *_ in got:
            h = houses.take(i)
            cov_h.append(f.hlc_low <= h.hlc_w_per_k <= f.hlc_high)
            cov_t.append(f.tau_low <= h.tau_h <= f.tau_high)
            err_h.append(abs(f.hlc_w_per_k / h.hlc_w_per_k - 1) * 100)
            err_t.append(abs(f.tau_h / h.tau_h - 1) * 100)
            w_h.append(f.hlc_rel * 100)
            w_t.append(f.tau_rel * 100)
        why: dict[str, int] = {}
        for r in sub:
            why[r[4]] = why.get(r[4], 0) + 1

        def pct(x):
            return 100.0 * np.mean(x) if len(x) else float("nan")

        def med(x):
            return float(np.median(x)) if len(x) else float("nan")

        # "reached": the final fit meets the target — also for the fixed plan, which does not
        # stop on it
        met = [r[3] is not None and target.ratio(r[3].hlc_rel, r[3].tau_rel) <= 1 for r in sub]
        reasons = ", ".join(f"{k} {v}" for k, v in sorted(why.items()))
        print(f"{STRATEGIES[s]:<28} {np.median(nights):>6.1f} / {np.percentile(nights, 90):<5.1f} "
              f"{pct(met):>7.0f}% {len(sub) - len(got):>7d} "
              f"{pct(cov_h):>5.0f}/{pct(cov_t):<4.0f}% {med(err_h):>6.1f} / {med(err_t):<5.1f} "
              f"{med(w_h):>5.1f} / {med(w_t):<5.1f}  {reasons}")
        rows.append(f"| {target.hlc_rel:.0%} / {target.tau_rel:.0%} | {STRATEGIES[s]} | "
                    f"{np.median(nights):g} / {np.percentile(nights, 90):g} | {pct(met):.0f} % | "
                    f"{pct(cov_h):.0f} / {pct(cov_t):.0f} % | {med(err_h):.1f} / "
                    f"{med(err_t):.1f} % | {med(w_h):.1f} / {med(w_t):.1f} % | {reasons} |")
    print("markdown:\n" + "\n".join(rows))
    checks = np.array([x for r in records if r[0] == "adaptive" for x in r[7]])
    if len(checks):
        q = np.percentile(checks, [10, 50, 90], axis=0)
        print(f"prediction check (adaptive, {len(checks)} nights): refitted / predicted "
              f"half-width after the chosen night, median (P10–P90): HLC {q[1, 0]:.2f} "
              f"({q[0, 0]:.2f}–{q[2, 0]:.2f}), τ {q[1, 1]:.2f} ({q[0, 1]:.2f}–{q[2, 1]:.2f})")


#: Set in the parent before the workers fork (copy-on-write: the simulated nights are not
#: pickled).
_SHARED: dict = {}


def _worker(w: int) -> tuple[list, int, float]:
    import torch

    torch.set_num_threads(1)
    sh = _SHARED
    households = list(range(w, sh["n"], sh["processes"]))
    progress = Progress(prefix=f" worker {w + 1}/{sh['processes']}:")
    fits = Fits(sh["houses"], sh["nights"], Protocol(preheat_h=PREHEAT_H), sh["step_s"],
                progress)
    out = []
    for target in sh["targets"]:
        camps = run(target, fits, sh["forecast"], sh["first_t_out"], sh["k"], households,
                    sh["strategies"])
        out.append([_record(c) for c in camps])
    return out, fits.count, fits.seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=100)
    ap.add_argument("--plant", choices=("realistic", "iso"), default="realistic")
    ap.add_argument("--targets", default="0.05/0.08,0.25/0.25",
                    help="HLC/τ relative 95 %% half-widths, comma-separated pairs")
    ap.add_argument("--max-nights", type=int, default=5)
    ap.add_argument("--step-s", type=float, default=300.0)
    ap.add_argument("--processes", type=int, default=2)
    ap.add_argument("--strategies", default="adaptive,unreachable,fixed",
                    help="comma-separated, of: " + ", ".join(STRATEGIES))
    ap.add_argument("--trajectories", action="store_true",
                    help="print every campaign's fits, floors, errors and stop reason")
    args = ap.parse_args()
    strategies = [x.strip() for x in args.strategies.split(",")]
    unknown = [x for x in strategies if x not in STRATEGIES]
    if unknown:
        ap.error(f"--strategies: unknown {', '.join(unknown)} (known: {', '.join(STRATEGIES)})")
    n, k = args.households, args.max_nights + 2
    progress = Progress()
    t0 = time.perf_counter()
    print(f"bench/campaign.py: {n} households, {args.plant} plant, {args.step_s:g} s samples, "
          f"{args.processes} processes, {platform.processor() or platform.machine()}, load "
          f"{os.getloadavg()[0]:.1f}", flush=True)
    houses, nights, forecast, first_t_out = simulate_variants(n, k, args.plant, args.step_s,
                                                              progress)
    t_sim = time.perf_counter() - t0
    targets = []
    for pair in args.targets.split(","):
        hlc, tau = (float(x) for x in pair.split("/"))
        targets.append(Target(hlc_rel=hlc, tau_rel=tau, max_nights=args.max_nights))
    _SHARED.update(n=n, k=k, houses=houses, nights=nights, forecast=forecast,
                   first_t_out=first_t_out, step_s=args.step_s, targets=targets,
                   strategies=strategies, processes=max(1, args.processes))
    if args.processes > 1:
        with multiprocessing.get_context("fork").Pool(args.processes) as pool:
            parts = pool.map(_worker, range(args.processes))
    else:
        parts = [_worker(0)]
    for t, target in enumerate(targets):
        records = [r for part, _, _ in parts for r in part[t]]
        summarise(records, houses, target, strategies)
        if args.trajectories:
            for s in strategies:
                _trajectories(records, houses, s)
    count, seconds = sum(p[1] for p in parts), sum(p[2] for p in parts)
    print(f"\n{count} fits, {seconds:.0f} s fitting (summed over processes), simulation "
          f"{t_sim:.0f} s, {time.perf_counter() - t0:.0f} s in all, load at the end "
          f"{os.getloadavg()[0]:.1f}")
    print("command: " + " ".join(["python"] + sys.argv))


if __name__ == "__main__":
    main()
