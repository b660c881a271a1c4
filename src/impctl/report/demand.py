"""Out-of-sample heat-demand check: the fitted house, re-simulated, against the measured heat.

The fit's own validation uses each night's fitted initial mass temperature, so its ε is
in-sample (near zero by construction). Here the fitted house runs through the whole campaign
from a cold start — the same outdoor temperatures and the same setpoint schedule the heat pump
followed (21 °C by day; per night T_max or T_set from the preheat, heating off in a constrained
night's window) — with the Annex C demand method, and its heat over each normal night's window
is compared with the heat the heat pump measured. This is the paper's Table V comparison.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..model import TABLE_IV, HouseParameters, simulate
from ..store import Store


def fitted_house(fit: dict) -> HouseParameters:
    """The house of a fit result (its seven parameters and the fixed air changes)."""
    fixed = fit.get("fixed", {})
    return HouseParameters(**{k: float(fit["parameters"][k]) for k in TABLE_IV},
                           ach_vent=float(fixed.get("ach_vent", 0.0)),
                           ach_infl=float(fixed.get("ach_infl", 0.01)))


def heat_demand_check(house: HouseParameters, store: Store, weather: pd.Series, *,
                      day_setpoint_c: float = 21.0, step_s: float = 300.0,
                      spinup_days: float = 4.0) -> dict:
    """Per valid normal night: measured vs predicted heat [kWh] and the errors.

    Returns ``{"normal": [{night_id, q_measured_kwh, q_model_kwh, dq_total_kwh, dq_power_kw,
    eps_pct}], "mean": {...}}`` with ε = |Q_model − Q_measured| / Q_measured.
    """
    nights = [n for n in store.nights() if n.started is not None]
    if not nights:
        return {"normal": [], "mean": {}}
    t0 = min(n.started for n in nights) - pd.Timedelta(days=spinup_days)
    t1 = max(n.window_end for n in nights)
    index = pd.date_range(pd.Timestamp(t0).floor("h"), pd.Timestamp(t1).ceil("h"),
                          freq=f"{int(step_s)}s")
    w = weather.sort_index()
    t_out = np.interp(index.asi8.astype(float), pd.DatetimeIndex(w.index).as_unit("ns")
                      .asi8.astype(float), w.to_numpy())
    sp = np.full(len(index), day_setpoint_c)
    for n in nights:
        end = n.ended or n.window_end
        pre = (index >= n.started) & (index < n.window_start)
        win = (index >= n.window_start) & (index < end)
        if n.kind == "constrained":
            sp[pre] = n.t_max_c if n.t_max_c is not None else n.setpoint_c
            sp[win] = np.nan
        else:
            sp[pre | win] = n.setpoint_c
    sim = simulate(house, t_out, step_s, setpoint_c=sp, t_m_init_c=day_setpoint_c)
    rows = []
    for n in nights:
        if n.kind != "normal" or not n.valid:
            continue
        samples = [s for s in store.samples(n.id)
                   if n.window_start <= s.ts <= n.window_end and s.q_hc_w is not None]
        if len(samples) < 2:
            continue
        hours = (n.window_end - n.window_start).total_seconds() / 3600.0
        q_meas = float(np.mean([s.q_hc_w for s in samples])) * hours / 1e3
        win = (index >= n.window_start) & (index < n.window_end)
        q_model = float(sim.phi_hc_w[win].sum()) * step_s / 3.6e6
        rows.append({"night_id": n.id, "q_measured_kwh": q_meas, "q_model_kwh": q_model,
                     "dq_total_kwh": abs(q_model - q_meas),
                     "dq_power_kw": abs(q_model - q_meas) / hours,
                     "eps_pct": 100.0 * abs(q_model - q_meas) / q_meas})
    mean = {k: float(np.mean([r[k] for r in rows])) for k in
            ("dq_total_kwh", "dq_power_kw", "eps_pct")} if rows else {}
    return {"normal": rows, "mean": mean,
            "note": "out of sample: the fitted house re-simulated over the whole campaign"}
