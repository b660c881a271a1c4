"""The printed form of a fit summary (:func:`.report.fit_to_dict`; no torch).

* :func:`format_table` — what ``impctl fit`` prints: the lumped quantities with their 95 %
  intervals, the seven parameters with what determines each, the validation, the nuisance
  terms, night quality, model adequacy and the flexibility;
* :func:`quality_rows`, :data:`QUALITY_HEADERS` — the night-quality table (also the HTML
  report's).
"""

from __future__ import annotations

from .report import PARAM_NAMES, PARAM_UNITS, probability_kind

_WHY_NOT = {
    "floor_area": "enters only through C_m = c_f·A_f and the large internal couplings",
    "wall_height": "enters only the tiny ventilation conductance (ach fixed)",
    "walls_area": "enters only as H_op = u_walls·walls_area",
    "windows_area": "enters only as H_w = u_windows·windows_area",
    "c_f": "enters only through C_m = c_f·A_f",
    "u_walls": "enters only as H_op = u_walls·walls_area",
    "u_windows": "enters only as H_w = u_windows·windows_area",
}


_CAVEAT = {
    "floor_area": "the data — via the mass-charging transient and ISO's fixed h_is, h_ms; "
                  "C_m is the robust quantity",
    "c_f": "the data — via C_m and the Table 12 mass-area factor; C_m is the robust quantity",
}


def _fmt(v: float | None, digits: int = 3) -> str:
    if v is None:
        return "–"
    return f"{v:.{digits}g}" if abs(v) < 1e4 else f"{v:.4g}"


def format_table(summary: dict) -> str:
    """The printed form of a :func:`.report.fit_to_dict` summary."""
    lines = []
    pn = summary["per_night"]
    n_c = sum(p["kind"] == "constrained" for p in pn)
    fit = summary["fit"]
    lines.append(f"Fitted {len(pn)} nights ({n_c} constrained, {len(pn) - n_c} normal) in "
                 f"{fit['time_s']:.2f} s — joint fit, normal nights as '{fit['normal_model']}'")
    for g in summary.get("gaps", []):
        lines.append(f"  gap in {g['kind']} night {g['night_id']}: no samples for "
                     f"{g['hours']:.1f} h; cut to {g['kept_from_s'] / 3600:.1f}–"
                     f"{g['kept_to_s'] / 3600:.1f} h after the window start")
    for s in summary["skipped"]:
        lines.append(f"  skipped {s['night_id']}: {s['reason']}")
    lines.append("")
    lines.append("Classes")
    for name, c in summary["classes"].items():
        p = c["probability"]
        ptxt = (f"p = {p:.2f} ({probability_kind(c)})" if p is not None
                else c["source"] or "")
        rng = f"{c['range'][0]:g}–{c['range'][1]:g}"
        flag = "  contradicted by the nights" if c.get("contradicted") else ""
        wide = c.get("search_range")
        if wide is not None and list(wide) != list(c["range"]):
            flag += f"  (searched {wide[0]:g}–{wide[1]:g}: classes not ruled out)"
        lines.append(f"  {name:<11} {rng:<10} {PARAM_UNITS[name]:<12} {ptxt}{flag}")
    lines.append("")
    lines.append("What the data determines                value       95 % interval")
    labels = {"hlc": ("HLC, heat loss coefficient", "W/K", 1.0),
              "c_m": ("C_m, heat capacity", "MJ/K", 1e-6),
              "tau": ("τ, time constant", "h", 1.0)}
    for key, (label, unit, k) in labels.items():
        q = summary["lumped"][key]
        flag = "" if q["determined"] else "   NOT determined by these nights"
        lines.append(f"  {label:<28} {unit:<5} {q['value'] * k:>9.4g}   "
                     f"{q['low'] * k:.4g} – {q['high'] * k:.4g}{flag}")
    fit_block = summary.get("fit", {})
    for term in fit_block.get("nuisance_at_bound") or []:
        lines.append(f"  {term['statement']} (the bound, not the nights, set it)")
    basis = fit_block.get("interval_basis") or ""
    if basis.startswith("too few nights"):
        lines.append(f"  intervals: {basis}")
    gain = fit_block.get("night_gain")
    if gain:
        why = (" (declare it: impctl fit --night-gain-w, or log p_house_w; ≈ 75 W per "
               "sleeper + base load): it moves HLC by its error / mean ΔT"
               if gain.get("assumed") else "")
        lines.append(f"  {gain['statement']}{why} [source: {gain.get('source', 'assumed')}]")
        if gain.get("detail") and gain["detail"] not in gain["statement"]:
            lines.append(f"  ({gain['detail']})")
    allowance = fit_block.get("offset_allowance") or {}
    sources = allowance.get("sources")
    if sources:
        s_in, s_out = allowance["sensor_offsets_k"]
        said = [f"T_air sensor offset SD {s_in:g} K ({sources['t_air_offset']})",
                f"T_out sensor {s_out:g} K ({sources['t_out_offset']})",
                f"heat meter ±{100 * allowance['meter_error']:g} % ({sources['meter_error']})"]
        hint = ("; declare what you know: impctl fit --t-air-offset-sd-k, --t-out-offset-sd-k, "
                "--meter-error" if "assumed" in sources.values() else "")
        lines.append("  type B in the intervals: " + ", ".join(said) + hint)
    for key, check in (summary.get("cross_checks") or {}).items():
        if key == "t_air_minus_rooms_k":
            lines.append(f"  T_air from the room sensors (t_rooms_c) on {check['nights']} "
                         f"nights; the controller's T_air reads {check['mean']:+.2f} K from it")
        elif key == "t_out_minus_ref_k":
            lines.append(check.get("statement") or (
                f"  T_out − reference outdoor temperature {check['mean']:+.2f} K on "
                f"{check['nights']} nights"))
        elif key == "defrost" and check["defrost_h"] > 0:
            lines.append("  " + (check.get("statement") or (
                f"defrosts on the held nights: {60 * check['defrost_h']:.0f} min, read as "
                "negative heat and compared with their recovery")))
    me = fit_block.get("model_error")
    if me:
        sizes = ", ".join(f"{n} {100 * me['share'][k]:.1f} %" for k, n in
                          (("hlc", "HLC"), ("c_m", "C_m"), ("tau", "τ")))
        lines.append(f"  intervals: {me['method']} (log SD {sizes})")
    for name, p in ((summary.get("prior") or {}).get("parameters") or {}).items():
        scale = 1e6 if p["unit"] == "J/K" else 1.0
        lines.append(
            f"  prior on {name}: population inside the class ranges, {p['centre'] / scale:.3g} "
            f"{'MJ/K' if scale > 1 else p['unit']} ± {100 * p['prior_sd_log']:.0f} % (log SD); "
            f"posterior/prior SD {p['posterior_to_prior_sd']:.2f} — "
            + ("prior-dominated, not measured" if p["prior_dominated"] else "mostly the nights"))
    lines.append("")
    lines.append("Physical parameters (Table IV)       joint  per-night   search range "
                 "value comes from")
    avg = summary.get("per_night_average", {}).get("parameters", {})
    for name in PARAM_NAMES:
        lo, hi = summary["bounds"][name]
        basis = summary["basis"][name]
        if basis == "data":
            src = _CAVEAT.get(name, "the data")
        else:
            src = f"{basis} only — {_WHY_NOT[name]}"
        rng = f"{_fmt(lo)}–{_fmt(hi)}"
        # a parameter the data do not determine is shown as its prior, not as a fitted value
        shown = ((summary.get("table_iv") or {}).get(name) or {}).get(
            "value", summary["parameters"][name])
        if basis != "data" and summary.get("table_iv"):
            src = f"prior (range centre) — {basis} only; {_WHY_NOT[name]}"
        lines.append(f"  {name:<12} {PARAM_UNITS[name]:<12} {_fmt(shown):>8}"
                     f"  {_fmt(avg.get(name)):>9}   {rng:<12} {src}")
    val = summary["validation"]
    lines.append("")
    lines.append("Validation (in-sample: each night's initial mass temperature is fitted)")
    if val["normal"]:
        lines.append("  normal night     Q measured kWh  Q model kWh  ΔQ_total kWh  ΔQ_power kW"
                     "   ε %")
        for r in val["normal"]:
            lines.append(f"  {r['night_id']:<16} {r['q_measured_kwh']:>14.2f} "
                         f"{r['q_model_kwh']:>12.2f} {r['dq_total_kwh']:>13.2f} "
                         f"{r['dq_power_kw']:>12.3f} {r['eps_pct']:>6.1f}")
    for r in val["constrained"]:
        lines.append(f"  constrained {r['night_id']}: T_air RMSE {r['rmse_k']:.3f} K")
    nuis = summary.get("nuisance") or {}
    if any(nuis.values()):
        lines += ["", "Nuisance terms (fitted so that the numbers above stay right; not products)"]
        for name, v in nuis.items():
            if v:
                how = ("assumed, not measured" if v.get("assumed")
                       else f"{v['source']}, not fitted" if v.get("pinned")
                       else f"{v['source']} under its prior, bounds {v['bounds'][0]:g}–"
                            f"{v['bounds'][1]:g}" if v.get("source")
                       else f"bounds {v['bounds'][0]:g}–{v['bounds'][1]:g}")
                lines.append(f"  {name:<14} {v['value']:>9.4g}   {v['low']:.4g} – {v['high']:.4g}"
                             f"   ({how})")
    lines += _quality_lines(summary)
    flex = summary.get("flexibility") or {}
    if flex.get("coast_h") is not None:
        lines.append("")
        lines.append(f"Flexibility at {flex['t_set_c']:g} °C indoors, {flex['t_out_c']:g} °C "
                     f"outdoors: heating off for {flex['coast_h']:.1f} h "
                     f"[{flex['coast_h_low']:.1f}–{flex['coast_h_high']:.1f}] until T_air has "
                     f"fallen {flex['drop_k']:g} K; then {flex['rebound_kwh']:.2f} kWh beyond "
                     f"steady demand in {flex['rebound_h']:g} h (impctl flex)")
        if flex.get("coast_method"):
            lines.append(f"  coast computed with: {flex['coast_method']}; internal gain during "
                         f"the coast {flex.get('coast_gain_w') or 0:.0f} W")
    for note in summary["notes"]:
        lines.append(f"note: {note}")
    return "\n".join(lines)


def quality_rows(summary: dict) -> list[list[str]]:
    """Night-quality rows (also the HTML report's table): one per given night."""
    def num(v, spec):
        return "–" if v is None else format(v, spec)

    rows = []
    for q in summary.get("night_quality", []):
        stops = ", ".join(f"{i['kind']} {i['minutes']:.0f} min at {i['start_h']:.1f} h"
                          for i in q["interruptions"]) or "none"
        rows.append([str(q["night_id"]), q["kind"], num(q["usable_h"], ".1f"),
                     num(q["cycles_per_h"], ".1f"), num(q["emitter_discharge_h"], ".1f"),
                     num(q.get("night_gain_w"), ".0f"), num(q["t_air_resolution_k"], ".3g"),
                     stops, "used" if q["used"] else f"not used: {q['reason']}"])
    return rows


QUALITY_HEADERS = ["night", "kind", "usable h", "cycles/h", "emitter discharge h",
                   "night gain W", "T_air resolution K", "DHW/defrost interruptions", "use"]


def _quality_lines(summary: dict) -> list[str]:
    lines = []
    rows = quality_rows(summary)
    if rows:
        widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(QUALITY_HEADERS)]
        lines += ["", "Night quality"]
        for r in [QUALITY_HEADERS, *rows]:
            lines.append("  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)))
    adequacy = summary.get("adequacy")
    if adequacy:
        lines += ["", "Model adequacy (residuals of the joint fit)"]
        for group, g in adequacy["groups"].items():
            line = f"  {group:<13} RMSE {g['rmse']:.3g} {g['unit']}"
            if g.get("hour_scale_residual") is not None:
                noise = g["reading_noise"]
                line += (f" (reading noise {noise:.2g} {g['unit']}); hour means "
                         f"{g['hour_scale_residual']:.2g} {g['unit']}, "
                         f"{g['low_frequency_ratio']:.1f}× white noise "
                         f"(p = {g['whiteness_p']:.2g})")
                if g.get("tolerance") is not None:
                    tol = (f"{g['tolerance']:.2f}" if g["unit"] == "K"
                           else f"{g['tolerance']:.0f}")
                    line += f", tolerance {tol} {g['unit']}"
            lines.append(line)
        lines.append(f"  {adequacy['statement']}")
    return lines
