"""When should the fixed plan retry an invalid constrained night? (issue 18, branch h18g)

Run:  OMP_NUM_THREADS=1 nice .venv/bin/python bench/retry_spacing.py [--households 150]
          [--nights 11]

The campaign bench's households and weather (``bench/campaign.py``: seed 20260, realistic
plant, the gateway's constrained nights: ΔT 2.5 K, 2 h pre-heat, ended at T_min, invalid with
< 3 h after the 1 h lag). Counted per retry pattern: the households with no valid constrained
night among up to 3 tries (until one is valid) at the given nights, on

* the campaign bench's schedule (every night constrained, so a try on night 3 follows a
  constrained night — what ``bench/campaign.py`` replays for every strategy), and
* a schedule in the new fixed plan's order after an invalid first night, c n22 c n23 c n24 c
  (``imp_schedule(order=...)``: the same dates' weather), so that every retry follows a normal
  night as it does on a gateway since h18g.

Also on the first schedule: a persistence-forecast rule (retry only when the night before was
not colder than the failed night, at least one night between), and the outdoor temperature
correlation of consecutive constrained nights.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from _fit_protocol import VAL_SEED, short_constrained  # noqa: E402
from unidentified import no_valid  # noqa: E402

from impctl.imp.protocol import DEFAULT_CONSTRAINED_SETPOINT_C  # noqa: E402
from impctl.population.households import sample_households  # noqa: E402
from impctl.population.imp_run.synth import imp_schedule, run_schedule_plant  # noqa: E402
from impctl.population.realism import sample_params  # noqa: E402

PATTERNS = {"1, 2, 3 (main: the next night)": [0, 1, 2], "1, 3, 5 (h18g's dates)":
            [0, 2, 4], "1, 4, 7": [0, 3, 6], "1, 5, 9": [0, 4, 8]}


def constrained(houses, params, order: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(too short, mean T_out [°C]) per constrained night (rows) and house (columns)."""
    sched = imp_schedule(len(houses.tau_h), n_constrained=order.count("constrained"),
                         n_normal=order.count("normal"), setpoints_c=(22.0, 23.0, 24.0),
                         constrained_setpoint_c=DEFAULT_CONSTRAINED_SETPOINT_C, seed=VAL_SEED,
                         order=order)
    sim, sp = run_schedule_plant(houses, sched, params, seed=VAL_SEED, stop_at_t_min=True)
    t_out = np.asarray(sim.t_out_c)
    mean = np.array([t_out[w0:w1].mean(axis=0) for _, kind, w0, w1, _ in sched.windows
                     if kind == "constrained"])
    return short_constrained(sp, sched), mean


def forecast_rule(short: np.ndarray, mean: np.ndarray) -> int:
    """Households with no valid constrained night when a retry waits at least one night and
    then until the night before was not colder than the failed one (3 tries at most)."""
    k, n = short.shape
    lost = 0
    for i in range(n):
        tries, j, ok, failed_t = 0, 0, False, None
        while tries < 3 and j < k:
            if failed_t is not None and mean[j - 1, i] < failed_t:
                j += 1
                continue
            tries += 1
            if not short[j, i]:
                ok = True
                break
            failed_t, j = mean[j, i], j + 2
        lost += not ok
    return lost


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=150)
    ap.add_argument("--nights", type=int, default=11,
                    help="simulated nights (≥ 5; patterns past them are left out)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    n, k = args.households, max(5, args.nights)
    houses = sample_households(n, seed=VAL_SEED)
    params = sample_params(n, VAL_SEED)
    short, mean = constrained(houses, params, ["constrained"] * k)
    print(f"bench/retry_spacing.py: {n} households, {k} nights; too short: "
          f"{100 * short.mean():.0f} % of all constrained nights")
    print("\n| constrained nights simulated | tries on nights | households with no valid "
          "constrained night |\n|---|---|---|")
    for label, idx in PATTERNS.items():
        if idx[-1] >= k:
            continue
        print(f"| every night constrained | {label} | {no_valid(short[idx]).sum()} of {n} |")
    alt = (["constrained", "normal"] * k)[:k]   # the same length: the same weather
    short_alt, _ = constrained(houses, params, alt)
    print(f"| c n22 c n23 c … (each retry after a normal night) | 1, 3, 5 | "
          f"{no_valid(short_alt[:3]).sum()} of {n} |")
    print(f"| every night constrained | persistence forecast: ≥ 1 night between, then the "
          f"night before not colder than the failed one | {forecast_rule(short, mean)} of {n} |")
    lag1 = np.corrcoef(mean[:-1].ravel(), mean[1:].ravel())[0, 1]
    print("\ntoo short on nights 1, 3, 5: every night constrained "
          + ", ".join(f"{100 * short[j].mean():.0f} %" for j in (0, 2, 4))
          + "; after a normal night " + ", ".join(f"{100 * short_alt[j].mean():.0f} %"
                                                  for j in range(3))
          + f"; consecutive constrained nights' mean T_out correlate {lag1:.2f}")
    tau = houses.tau_h[no_valid(short[[0, 1, 2]])]
    print(f"τ of the households without a valid night (tries 1, 2, 3): median "
          f"{np.median(tau):.0f} h (all: {np.median(houses.tau_h):.0f} h)")
    print(f"{time.perf_counter() - t0:.0f} s; command: python " + " ".join(sys.argv))


if __name__ == "__main__":
    main()
