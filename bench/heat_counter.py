"""An interval's heat from the thermal energy counter (2363/2364) or from the mean of 2329.

Run:  .venv/bin/python bench/heat_counter.py [--days 3] [--t-out -2] [--seed 0]

The extended Kronoterm controller reports the heat output twice: 2329, the thermal power of
this instant [W], and 2363/2364, the lifetime thermal energy of heating and hot water [0.1 kWh,
uint32]. The owner recording averages 2329 over a row's snapshots (one a minute). Would the
counter's difference over the row give a better mean? Both are taken from the realistic
simulator's plant (the demo's realism: a cycling inverter heat pump, hot water charged on a
schedule), stepped every 10 s for ``--days`` days at a constant outdoor temperature; each is
compared with the exact mean of what it measures over the row (the 10-s integral: 2329's
own metered heat for the snapshot means, the counted heat for the counter). Printed per row
length (5 min, 15 min, 1 h): the RMS and largest error [W] and the RMS relative to the mean
heat. Rows in which hot water was charged are left out (the counter counts both, 2329 too).
"""

from __future__ import annotations

import argparse
import math

import numpy as np


def _run(days: float, t_out_c: float, seed: int) -> dict[str, np.ndarray]:
    from impctl_sim.config import default_realism
    from impctl_sim.plant import PlantParams
    from impctl_sim.realistic import RealisticPlant

    from impctl.demo.options import demo_house

    plant = RealisticPlant(demo_house(), default_realism(), PlantParams(), setpoint_c=21.0,
                           t_out_c=t_out_c, seed=seed)
    dt = 10.0
    n = int(days * 86400 / dt)
    out = {k: np.empty(n) for k in ("p_th", "counter", "heat", "dhw")}
    heat_j = 0.0
    for i in range(n):
        out["p_th"][i] = plant.p_th_w  # what 2329 reads at this instant
        out["counter"][i] = math.floor(plant.e_th_kwh * 10)  # what 2363 reads [0.1 kWh]
        out["heat"][i] = heat_j
        out["dhw"][i] = plant.dhw_active
        before = plant.e_th_kwh
        plant.step(dt, t_out_c)
        heat_j += (plant.e_th_kwh - before) * 3.6e6
    out["dt"] = np.array([dt])
    return out


def _compare(d: dict[str, np.ndarray], row_s: float, snapshot_s: float = 60.0) -> dict:
    dt = float(d["dt"][0])
    per_row, per_snap = int(row_s / dt), int(snapshot_s / dt)
    rows = len(d["p_th"]) // per_row - 1
    err_snap, err_counter, means = [], [], []
    for r in range(rows):
        a, b = r * per_row, (r + 1) * per_row
        if d["dhw"][a:b + 1].any():
            continue
        exact_meter = float(d["p_th"][a:b].mean())  # 2329's own mean over the row
        snaps = float(d["p_th"][a:b:per_snap].mean())  # a snapshot a minute
        exact_heat = (d["heat"][b] - d["heat"][a]) / row_s  # the counted heat's mean
        counted = (d["counter"][b] - d["counter"][a]) * 0.1 * 3.6e6 / row_s
        err_snap.append(snaps - exact_meter)
        err_counter.append(counted - exact_heat)
        means.append(exact_meter)
    e1, e2, m = np.array(err_snap), np.array(err_counter), float(np.mean(means))
    return {"rows": len(e1), "mean_w": m,
            "snap_rms_w": float(np.sqrt(np.mean(e1 ** 2))), "snap_max_w": float(abs(e1).max()),
            "counter_rms_w": float(np.sqrt(np.mean(e2 ** 2))),
            "counter_max_w": float(abs(e2).max())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--days", type=float, default=3.0)
    parser.add_argument("--t-out", type=float, default=-2.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    d = _run(args.days, args.t_out, args.seed)
    print(f"demo house, realistic plant, {args.days:g} days at {args.t_out:g} °C "
          "(rows with hot water left out)")
    print(f"{'row':>6} {'rows':>5} {'mean heat':>10}   {'2329, mean of 1-min snapshots':>30}"
          f"   {'2363 counter difference':>26}")
    for row_s in (300.0, 900.0, 3600.0):
        c = _compare(d, row_s)
        print(f"{row_s / 60:4.0f} min {c['rows']:5d} {c['mean_w']:8.0f} W   RMS "
              f"{c['snap_rms_w']:5.0f} W ({100 * c['snap_rms_w'] / c['mean_w']:4.1f} %), max "
              f"{c['snap_max_w']:5.0f} W   RMS {c['counter_rms_w']:5.0f} W "
              f"({100 * c['counter_rms_w'] / c['mean_w']:4.1f} %), max "
              f"{c['counter_max_w']:5.0f} W")


if __name__ == "__main__":
    main()
