"""Error budget of the night fit on the realistic plant: one realism factor at a time.

Run:  .venv/bin/python bench/fit_budget.py [--households 20] [--factors ideal,air,...]
          [--step 300] [--night-gain] [--no-offset-allowance] [--fit smooth_out_h=1,...]

The validation houses of ``bench/fit.py`` (``sample_households(seed=20260)``, its IMP schedule and
weather) run on the realistic plant with everything ideal (``PlantParams.ideal()``, no gains)
except the named factor, which takes the value ``impctl.population.realism.sample_params`` drew
for that house (seed 20260, as in ``bench/fit.py --plant realistic``):

* ``ideal``: nothing (checks that the plant reproduces the 5R1C the fit assumes);
* ``air``: air and furniture capacity (``capacities``);
* ``emitter``: radiators / underfloor screed, buffer (``emitter``), ideal control;
* ``control``: the emitter plus the heat pump's control (weather curve / thermostat, on/off or
  modulating, cycling, defrost) — control without an emitter is not a physical plant;
* ``gains``: internal (night 100–400 W) and solar gains;
* ``noise``: sensor noise, quantisation and lag, meter noise and positive-only integration;
* ``offsets``: sensor offsets (T_air ±1 K, T_out ±2 K) and the meter's gain error (±5 %);
* ``all``: every factor (the ``bench/fit.py --plant realistic`` houses).

Per factor: median absolute error (and signed median) of HLC, τ, C_m, 95 % coverage, and two
heat-demand errors: ``ε plant`` is ``bench/fit.py``'s (the fitted house replayed on the Annex C
model holding the setpoints exactly, against the plant's true heat-pump output), ``ε 5R1C`` is
against the true house replayed the same way; ``ε truth`` is ``ε plant`` of the true parameters
themselves — the floor of ``ε plant`` that no parameter estimate can go below.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

import numpy as np
import torch

sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))

from fit import (  # noqa: E402  (the bench's own helpers)
    ACH,
    VAL_SEED,
    _safe_house,
    demand_eps,
    rel,
    true_ranges,
    window_energy,
)

from impctl.fit.estimator import NightFit  # noqa: E402
from impctl.plant import PlantParams, simulate_plant  # noqa: E402
from impctl.plant.building.gains import internal_gains_w, solar_gains_w  # noqa: E402
from impctl.population.households import sample_households  # noqa: E402
from impctl.population.realism import sample_params  # noqa: E402
from impctl.population.synth_nights import (  # noqa: E402
    PlantSchedule,
    imp_schedule,
    run_schedule,
    sample_nights,
)

FACTORS = ("ideal", "air", "emitter", "control", "gains", "noise", "offsets", "all")
#: The parts of ``noise``, one at a time (``--factors lag,t_air_noise,...``).
NOISE_PARTS = {
    "lag": ("t_air_lag_s",),
    "t_air_noise": ("t_air_noise_k", "t_air_quantum_k"),
    "t_out_noise": ("t_out_noise_k",),
    "meter": ("meter_noise", "meter_positive_only"),
}


def factor_params(name: str, full: PlantParams) -> tuple[PlantParams, bool]:
    """(realism options, gains on) with only factor ``name`` taken from ``full``."""
    ideal = PlantParams.ideal()
    s = full.sensors
    if name == "ideal":
        return ideal, False
    if name == "air":
        return replace(ideal, capacities=full.capacities), False
    if name == "emitter":
        return replace(ideal, emitter=full.emitter), False
    if name == "control":
        return replace(ideal, emitter=full.emitter, heat_pump=full.heat_pump), False
    if name == "gains":
        return replace(ideal, gains=full.gains), True
    if name == "noise":
        return replace(ideal, sensors=replace(s, t_air_offset_k=0.0, t_out_offset_k=0.0,
                                              meter_gain_error=0.0)), False
    if name == "offsets":
        return replace(ideal, sensors=replace(
            ideal.sensors, t_air_offset_k=s.t_air_offset_k, t_out_offset_k=s.t_out_offset_k,
            meter_gain_error=s.meter_gain_error)), False
    if name == "all":
        return full, True
    if name in NOISE_PARTS:
        return replace(ideal, sensors=replace(ideal.sensors, **{
            f: getattr(s, f) for f in NOISE_PARTS[name]})), False
    raise SystemExit(f"unknown factor {name!r}; choose from {', '.join(FACTORS)}")


class _TrueHeat:
    def __init__(self, run):
        self.phi_hc_w = run["heat_pump_w"]


def run_plant(houses, sched, params: PlantParams, gains: bool):
    """``run_schedule_plant`` with the gains switchable (their ranges exclude zero)."""
    n = sched.t_out_c.shape[1]
    rng = np.random.default_rng(np.random.SeedSequence([VAL_SEED, 0x6A1]))
    local = sched.index.tz_convert(sched.index.tz) if sched.index.tz else sched.index
    hours = (local.hour + local.minute / 60.0).to_numpy()
    day = (local.normalize().tz_localize(None).asi8 // 86_400_000_000_000)
    g_int = internal_gains_w(hours, params.gains, n, rng, sched.dt_s)
    g_sol = solar_gains_w(hours, day, params.gains, n, rng)
    if not gains:
        g_int, g_sol = 0.0, 0.0
    run = simulate_plant(houses, params, sched.t_out_c, sched.dt_s, setpoint_c=sched.setpoint_c,
                         internal_gains_w=g_int, solar_gains_w=g_sol,
                         t_init_c=sched.t_m_init_c, seed=int(rng.integers(2**31)),
                         outputs=("t_air_sensed_c", "t_out_sensed_c", "heat_meter_w",
                                  "heat_pump_w", "t_air_c"))
    return PlantSchedule(run["t_air_sensed_c"], run["heat_meter_w"], run["t_out_sensed_c"], run)


def med(v) -> float:
    v = np.asarray(v, float)
    return float(np.nanmedian(np.abs(v)))


def one_factor(name: str, houses, sched, full, args, ideal_e) -> dict:
    params, gains = factor_params(name, full)
    logged = run_plant(houses, sched, params, gains)
    truth_e = window_energy(_TrueHeat(logged.run), sched)
    n = houses.n_houses
    err = {k: [] for k in ("hlc", "tau", "c_m")}
    cov = {k: [] for k in err}
    fitted, times = [], []
    for i in range(n):
        house = houses.take(i)
        nights = sample_nights(logged, sched.setpoint_c, sched, i, sample_step_s=args.step,
                               quantise_k=0.1, power_noise=0.0, seed=VAL_SEED + i)
        kw = {"night_gain": args.night_gain} if args.night_gain else {}
        if args.no_offset_allowance:
            kw["sensor_offsets_k"] = (0.0, 0.0)
        fit = NightFit(ach_vent=ACH[0], ach_infl=ACH[1], per_night=False, **kw,
                       **args.fit_kw).fit(nights, true_ranges(house))
        for k, t in (("hlc", house.hlc_w_per_k), ("tau", house.tau_h),
                     ("c_m", house.c_m_j_per_k)):
            e = fit.lumped_[k]
            err[k].append(rel(e.value, t))
            cov[k].append(e.low <= t <= e.high)
        fitted.append(_safe_house(fit.parameters_))
        times.append(fit.fit_time_s_)
        if args.verbose:
            print(f"  {name} house {i}: HLC {err['hlc'][-1]:+.1f} τ {err['tau'][-1]:+.1f} "
                  f"C_m {err['c_m'][-1]:+.1f} %", flush=True)
    eps_plant = demand_eps(fitted, sched, truth_e)
    eps_truth = 100.0 * np.mean(np.abs(ideal_e - truth_e) / truth_e, axis=0)
    e_fit = np.full_like(ideal_e, np.nan)
    ok = [h is not None for h in fitted]
    if any(ok):
        from impctl.model import HouseParameters

        idx = np.flatnonzero(ok)
        sub = HouseParameters.stack([fitted[j] for j in idx])
        from fit import _sub_schedule

        s2 = _sub_schedule(sched, idx)
        sim, _ = run_schedule(sub, s2)
        e_fit[:, idx] = window_energy(sim, s2)
    eps_5r1c = 100.0 * np.mean(np.abs(e_fit - ideal_e) / ideal_e, axis=0)
    return {"err": err, "cov": cov, "eps_plant": eps_plant, "eps_truth": eps_truth,
            "eps_5r1c": eps_5r1c, "time": np.median(times)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=20)
    ap.add_argument("--factors", default=",".join(FACTORS))
    ap.add_argument("--step", type=float, default=300.0, help="sample step [s]")
    ap.add_argument("--night-gain", action="store_true", help="fit with the night-gain term")
    ap.add_argument("--no-offset-allowance", action="store_true")
    ap.add_argument("--fit", default="", metavar="NAME=VALUE,...",
                    help="NightFit options, e.g. smooth_out_h=1 (numbers)")
    ap.add_argument("--verbose", action="store_true")
    args = ap.parse_args()
    args.fit_kw = {k: float(v) for k, v in (x.split("=") for x in args.fit.split(",") if x)}
    torch.set_num_threads(1)
    print("command: " + " ".join(["python"] + sys.argv))
    n = args.households
    houses = sample_households(n, seed=VAL_SEED)
    sched = imp_schedule(n, seed=VAL_SEED)
    full = sample_params(n, VAL_SEED)
    sim, _ = run_schedule(houses, sched)
    ideal_e = window_energy(sim, sched)   # the true house on the 5R1C, setpoints held exactly
    print(f"{n} households, {args.step:g} s rows, true class ranges; errors: median |·| "
          "(signed median); coverage of the 95 % intervals")
    print("| factor | HLC % | τ % | C_m % | coverage HLC/τ/C_m % | ε plant % | ε 5R1C % "
          "| ε truth % | fit s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.factors.split(","):
        t0 = time.perf_counter()
        r = one_factor(name, houses, sched, full, args, ideal_e)
        cells = [f"{med(r['err'][k]):.1f} ({np.nanmedian(r['err'][k]):+.1f})"
                 for k in ("hlc", "tau", "c_m")]
        cov = " / ".join(f"{100 * np.mean(r['cov'][k]):.0f}" for k in ("hlc", "tau", "c_m"))
        print(f"| {name} | " + " | ".join(cells) + f" | {cov} | {med(r['eps_plant']):.1f} | "
              f"{med(r['eps_5r1c']):.1f} | {med(r['eps_truth']):.1f} | {r['time']:.2f} |",
              flush=True)
        if args.verbose:
            print(f"  ({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
