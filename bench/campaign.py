"""Adaptive IMP campaign (issue 18) against the fixed 2 + 3 campaign, on the realistic plant.

Run:  nice .venv/bin/python bench/campaign.py [--households 100] [--plant realistic|iso]
          [--targets 0.05/0.08,0.15/0.15] [--max-nights 8] [--step-s 300]

Households: ``sample_households(N, seed=20260)`` with realism ``sample_params(N, 20260)`` (the
validation population of ``bench/fit.py``), class ranges the true classes (as the realistic
rows of the README's fit table). Each household gets its own winter weather. For every night
index j (K = max_nights + 2, spares for skipped nights) every candidate night — constrained at
21 °C (pre-heat 4 h to 22.5 °C) and normal at 21, 22 and 23 °C — is pre-simulated on the same
weather and gains (the four variants as four schedules of the same houses, every night of a
schedule of one variant, days at 21 °C in between); a campaign then replays, night by night,
the variant it chooses. Logged: room and outdoor sensors, heat meter, 5-minute samples.

Strategies, each on every household, sharing fits where their nights coincide:

* **adaptive** — :func:`impctl.campaign.decide` with the candidates of
  :func:`impctl.campaign.design.predict_candidates` (the fit after every valid night);
* **fixed order, adaptive stop** — the same stop/skip rules, the default order (no
  predictions): separates stopping early from choosing the night;
* **fixed 2 + 3** — today's plan: constrained, constrained, normal 21, 22, 23 °C; an invalid
  night is repeated; one fit at the end.

Forecast of a night: the mean outdoor temperature of the previous night (persistence: the
daemon's own history); a night whose forecast is outside the band −25…8 °C is skipped, one
whose first outdoor reading is outside it is run but invalid. Reported per strategy and target:
nights run (median, P90), share reaching the target, final-interval coverage of the true HLC
and τ, median |error|, median final half-widths.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import numpy as np

from impctl.campaign import Candidate, FitSummary, NightRecord, Target, decide
from impctl.campaign.design import Protocol, predict_candidates
from impctl.fit.batch import fit_households
from impctl.fit.report import fit_to_dict
from impctl.population.households import sample_households
from impctl.population.realism import sample_params
from impctl.population.synth_nights import (
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
STRATEGIES = ("adaptive", "fixed order, adaptive stop", "fixed 2 + 3")


class Progress:
    def __init__(self, every_s: float = 5.0):
        self.every_s, self.t0, self.last = every_s, time.monotonic(), 0.0

    def __call__(self, text: str, force: bool = False) -> None:
        now = time.monotonic()
        if force or now - self.last >= self.every_s:
            self.last = now
            print(f"  [{now - self.t0:6.0f} s] {text}", flush=True)


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
        self.count, self.seconds = 0, 0.0

    def ensure(self, keys: list[tuple], batch: int = 12) -> None:
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

    def candidates(self, key: tuple, forecast_c: float) -> list[Candidate]:
        result = self.cache.get(key)
        if result is None:
            return []
        try:
            return predict_candidates(result, forecast_c, constrained_setpoint_c=21.0,
                                      normal_setpoints_c=(21.0, 22.0, 23.0), step_s=self.step_s,
                                      protocol=self.protocol)
        except (KeyError, TypeError, ValueError):
            return []


class Campaign:
    """One strategy on one household."""

    def __init__(self, i: int, strategy: str, target: Target):
        self.i, self.strategy, self.target = i, strategy, target
        self.history: list[NightRecord] = []
        self.chosen: list[tuple[int, int]] = []     # (night index, variant) of valid nights
        self.fits: list[FitSummary] = []
        self.key: tuple | None = None
        self.done, self.reached, self.reason = False, False, ""

    def fit_key(self) -> tuple | None:
        kinds = {VARIANTS[v][0] for _, v in self.chosen}
        return (self.i, tuple(self.chosen)) if len(kinds) == 2 else None


def step(c: Campaign, j: int, fits: Fits, forecast: float, first_t_out: list) -> int | None:
    """Decide night j for campaign c; returns the variant run or None."""
    if c.done:
        return None
    if c.strategy == "fixed 2 + 3":
        n_valid = len(c.chosen)
        if n_valid >= len(FIXED):
            c.done, c.reason = True, "plan complete"
            return None
        v = FIXED[n_valid]
    else:
        cands = []
        if c.strategy == "adaptive" and c.key is not None:
            cands = fits.candidates(c.key, forecast)
        d = decide(c.history, c.fits, cands, c.target, forecast_t_out_c=forecast,
                   t_out_band_c=BAND_C, constrained_setpoint_c=21.0,
                   normal_setpoints_c=(21.0, 22.0, 23.0))
        if d.action == "stop":
            c.done, c.reached, c.reason = True, d.reached, d.reason
            return None
        if d.action == "skip":
            return None
        v = VARIANTS.index((d.kind, d.setpoint_c))
    valid = BAND_C[0] <= first_t_out[v][c.i][j] <= BAND_C[1]
    c.history.append(NightRecord(*VARIANTS[v], valid))
    if valid:
        c.chosen.append((j, v))
    return v


def run(args, target: Target, fits: Fits, forecast, first_t_out, k: int, n: int) -> list:
    camps = [Campaign(i, s, target) for s in STRATEGIES for i in range(n)]
    for j in range(k):
        ran = [c for c in camps if step(c, j, fits, float(forecast[c.i][j]), first_t_out)
               is not None]
        keys = [c.fit_key() for c in ran]
        need = [key for c, key in zip(ran, keys, strict=True)
                if key is not None and c.chosen and c.chosen[-1][0] == j
                and (c.strategy != "fixed 2 + 3" or len(c.chosen) == len(FIXED))]
        fits.ensure(need)
        for c in ran:
            key = c.fit_key()
            if key is None or key not in fits.cache or c.key == key:
                continue
            c.key = key
            result = fits.cache[key]
            if result is not None:
                c.fits.append(FitSummary.from_fit_json(result, len(c.chosen)))
        fits.progress(f"target {target.hlc_rel:.0%}/{target.tau_rel:.0%}: night {j + 1}/{k}, "
                      f"{sum(not c.done for c in camps)} campaigns running", force=True)
    for c in camps:
        if not c.done:
            c.reason = "ran out of simulated nights"
    return camps


def summarise(camps: list, houses, target: Target) -> None:
    print(f"\nTarget: HLC ±{target.hlc_rel:.0%}, τ ±{target.tau_rel:.0%} (95 % half-width / "
          f"estimate), max {target.max_nights} nights, stall {target.stall_nights} nights")
    print(f"{'strategy':<28} {'nights med/P90':>14} {'reached':>8} {'no fit':>7} "
          f"{'cover HLC/τ':>12} {'|err| HLC/τ %':>14} {'±HLC/τ % med':>13}  stopped by")
    for s in STRATEGIES:
        sub = [c for c in camps if c.strategy == s]
        nights = np.array([len(c.history) for c in sub])
        got = [c for c in sub if c.key is not None and c.fits]
        cov_h, cov_t, err_h, err_t, w_h, w_t = [], [], [], [], [], []
        for c in got:
            h = houses.take(c.i)
            f = c.fits[-1]
            cov_h.append(f.hlc_low <= h.hlc_w_per_k <= f.hlc_high)
            cov_t.append(f.tau_low <= h.tau_h <= f.tau_high)
            err_h.append(abs(f.hlc_w_per_k / h.hlc_w_per_k - 1) * 100)
            err_t.append(abs(f.tau_h / h.tau_h - 1) * 100)
            w_h.append(f.hlc_rel * 100)
            w_t.append(f.tau_rel * 100)
        why: dict[str, int] = {}
        for c in sub:
            label = ("target reached" if c.reached else "max nights" if "most this" in c.reason
                     else "cannot be identified" if "cannot be" in c.reason else c.reason)
            why[label] = why.get(label, 0) + 1

        def pct(x):
            return 100.0 * np.mean(x) if len(x) else float("nan")

        def med(x):
            return float(np.median(x)) if len(x) else float("nan")

        # "reached": the final fit meets the target — also for the fixed plan, which does not
        # stop on it
        met = [bool(c.fits) and target.ratio(c.fits[-1].hlc_rel, c.fits[-1].tau_rel) <= 1
               for c in sub]
        print(f"{s:<28} {np.median(nights):>6.1f} / {np.percentile(nights, 90):<5.1f} "
              f"{pct(met):>7.0f}% {len(sub) - len(got):>7d} "
              f"{pct(cov_h):>5.0f}/{pct(cov_t):<4.0f}% {med(err_h):>6.1f} / {med(err_t):<5.1f} "
              f"{med(w_h):>5.1f} / {med(w_t):<5.1f}  "
              + ", ".join(f"{k} {v}" for k, v in sorted(why.items())))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=100)
    ap.add_argument("--plant", choices=("realistic", "iso"), default="realistic")
    ap.add_argument("--targets", default="0.05/0.08",
                    help="HLC/τ relative 95 %% half-widths, comma-separated pairs")
    ap.add_argument("--max-nights", type=int, default=8)
    ap.add_argument("--step-s", type=float, default=300.0)
    args = ap.parse_args()
    n, k = args.households, args.max_nights + 2
    progress = Progress()
    t0 = time.perf_counter()
    print(f"bench/campaign.py: {n} households, {args.plant} plant, {args.step_s:g} s samples, "
          f"{platform.processor() or platform.machine()}", flush=True)
    houses, nights, forecast, first_t_out = simulate_variants(n, k, args.plant, args.step_s,
                                                              progress)
    protocol = Protocol(preheat_h=PREHEAT_H)
    fits = Fits(houses, nights, protocol, args.step_s, progress)
    for pair in args.targets.split(","):
        hlc, tau = (float(x) for x in pair.split("/"))
        target = Target(hlc_rel=hlc, tau_rel=tau, max_nights=args.max_nights)
        camps = run(args, target, fits, forecast, first_t_out, k, n)
        summarise(camps, houses, target)
    print(f"\n{fits.count} fits, {fits.seconds:.0f} s fitting, {time.perf_counter() - t0:.0f} s "
          f"in all")
    print("command: " + " ".join(["python"] + sys.argv))


if __name__ == "__main__":
    main()
