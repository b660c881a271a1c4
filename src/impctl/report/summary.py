"""The demo's closing table: true vs estimated parameters, lumped errors, heat demand."""

from __future__ import annotations

from ..model import PARAMETER_UNITS, TABLE_IV, HouseParameters

PARAMS = TABLE_IV
UNITS = {**PARAMETER_UNITS, "hlc": "W/K", "c_m": "J/K", "tau": "h"}
#: The paper's Table V: mean heat-demand error of its fitted model on normal nights.
PAPER_EPS_PCT = (18.65, 20.17, 19.22)


def _err_pct(est: float | None, true: float) -> float | None:
    return None if est is None else 100.0 * (est - true) / true


def demo_summary(house: HouseParameters, fit: dict, demand: dict | None = None, *,
                 wall_s: float, train_state: str, plant: dict | None = None) -> dict:
    """Compare a fit result (``impctl fit`` JSON) with the demo house's true parameters.

    ``demand`` is the out-of-sample heat-demand check (:mod:`impctl.report.demand`); without
    it the fit's own (in-sample) validation is shown. ``plant`` says which simulated plant
    produced the nights (``kind``, ``description``, the realism options).
    """
    truth = house.as_dict()
    params = []
    for name in PARAMS:
        # what the fit reports: the fitted value where the data determine it, else its prior
        shown = (fit.get("table_iv") or {}).get(name)
        est = shown["value"] if shown else fit["parameters"].get(name)
        cls = fit.get("classes", {}).get(name, {})
        params.append({
            "name": name, "unit": UNITS[name], "true": float(truth[name]), "estimate": est,
            "error_pct": _err_pct(est, float(truth[name])),
            "range": fit.get("bounds", {}).get(name) or cls.get("range"),
            "basis": fit.get("basis", {}).get(name, "?"),
            "determined": bool(fit.get("determined", {}).get(name, False)),
        })
    true_lumped = {"hlc": float(house.hlc_w_per_k), "c_m": float(house.c_m_j_per_k),
                   "tau": float(house.tau_h)}
    lumped = []
    for key, true in true_lumped.items():
        entry = fit["lumped"][key]
        low, high = entry.get("low"), entry.get("high")
        lumped.append({
            "name": key, "unit": UNITS[key], "true": true, "estimate": entry.get("value"),
            "low": low, "high": high, "error_pct": _err_pct(entry.get("value"), true),
            "covered": None if low is None or high is None else bool(low <= true <= high),
            "determined": bool(entry.get("determined", True)),
        })
    source = demand if demand and demand.get("mean") else fit.get("validation", {})
    mean = dict(source.get("mean", {}) or {})
    mean.setdefault("rmse_k", (fit.get("validation", {}).get("mean") or {}).get("rmse_k"))
    return {
        "parameters": params, "lumped": lumped,
        "heat_demand": {"eps_pct": mean.get("eps_pct"), "dq_total_kwh": mean.get("dq_total_kwh"),
                        "dq_power_kw": mean.get("dq_power_kw"),
                        "rmse_k": mean.get("rmse_k"), "paper_eps_pct": PAPER_EPS_PCT,
                        "out_of_sample": bool(demand and demand.get("mean"))},
        "wall_s": wall_s, "classifiers": train_state,
        "plant": plant or {"kind": "unknown", "description": ""},
    }


def _num(x: float | None, spec: str = ".3g") -> str:
    return "—" if x is None else format(x, spec)


def format_summary(s: dict) -> str:
    """The summary as a plain-text table (what the demo prints last)."""
    plant = s.get("plant") or {}
    lines = ["", f"Plant: {plant.get('kind', '?')} ({plant.get('description', '')})",
             "", "Parameters (the paper's Table IV): true vs estimated",
             f"  {'parameter':<13}{'unit':<13}{'true':>9}{'estimate':>10}{'error':>9}  "
             f"{'search range':<18} determined by"]
    for p in s["parameters"]:
        rng = p["range"]
        rng_s = "—" if not rng else f"{rng[0]:.3g}–{rng[1]:.3g}"
        basis = "data" if p["determined"] else f"prior: {p['basis']} (not the data)"
        err = "—" if p["error_pct"] is None else f"{p['error_pct']:+.1f} %"
        lines.append(f"  {p['name']:<13}{p['unit']:<13}{p['true']:>9.3g}"
                     f"{_num(p['estimate']):>10}{err:>9}  {rng_s:<18} {basis}")
    lines += ["", "What the nights determine: lumped quantities with 95 % intervals",
              f"  {'quantity':<10}{'unit':<6}{'true':>11}{'estimate':>11}{'error':>9}  "
              f"{'95 % interval':<24} covers truth"]
    for q in s["lumped"]:
        scale = 1e6 if q["name"] == "c_m" else 1.0
        unit = "MJ/K" if q["name"] == "c_m" else q["unit"]
        est = None if q["estimate"] is None else q["estimate"] / scale
        iv = ("—" if q["low"] is None else
              f"{q['low'] / scale:.4g} … {q['high'] / scale:.4g}")
        err = "—" if q["error_pct"] is None else f"{q['error_pct']:+.1f} %"
        cov = "—" if q["covered"] is None else ("yes" if q["covered"] else "no")
        lines.append(f"  {q['name']:<10}{unit:<6}{q['true'] / scale:>11.4g}{_num(est, '.4g'):>11}"
                     f"{err:>9}  {iv:<24} {cov}")
    hd = s["heat_demand"]
    paper = "/".join(f"{x:.1f}" for x in hd["paper_eps_pct"])
    how = ("fitted house re-simulated over the campaign vs measured heat" if
           hd.get("out_of_sample") else "in-sample")
    lines += ["", f"Heat demand on the normal nights (the paper's Table V; {how})",
              f"  ε = {_num(hd['eps_pct'], '.1f')} %  (paper: {paper} %), "
              f"ΔQ_total = {_num(hd['dq_total_kwh'], '.2f')} kWh, "
              f"ΔQ_power = {_num(hd['dq_power_kw'], '.3f')} kW",
              "", f"Wall time {s['wall_s']:.0f} s (classifiers: {s['classifiers']})"]
    return "\n".join(lines)
