"""The campaign report: PNG figures and one self-contained HTML page.

Inputs are the store (nights, samples, validity) and a fit result (the ``impctl fit`` JSON,
whose ``predictions`` carry the fitted curves). Nothing here imports torch.
"""

from __future__ import annotations

import html
import json
import os
import shutil
import tempfile
from pathlib import Path
from zoneinfo import ZoneInfo

from ..errors import InputError
from ..model import HouseParameters
from ..store import Store
from . import figures
from .fit_json import fit_problem
from .household import household_html, household_summary, night_comfort
from .page import img as _img
from .page import table as _table
from .summary import demo_summary, format_summary

__all__ = ["demo_summary", "format_summary", "write_report"]




def _list(x) -> list:
    return x if isinstance(x, list) else []


def _fmt(x, spec=".3g") -> str:
    return "—" if x is None else format(x, spec)


def _nights_table(store: Store, tz: str) -> str:
    zone = ZoneInfo(tz)
    rows = []
    for n in store.nights():
        rows.append([n.id, n.kind, f"{n.setpoint_c:g}",
                     f"{n.window_start.astimezone(zone):%Y-%m-%d %H:%M}",
                     f"{(n.window_end - n.window_start).total_seconds() / 3600:.1f}",
                     n.state, "yes" if n.valid else "no", store.sample_count(n.id),
                     "; ".join(n.reasons)])
    return _table(["id", "kind", "T_set °C", "window start (local)", "window h", "state",
                   "valid", "samples", "data quality / reasons"], rows)


def _lumped_table(fit: dict) -> str:
    rows = []
    for key, label, unit, scale in (("hlc", "HLC", "W/K", 1.0), ("c_m", "C_m", "MJ/K", 1e6),
                                    ("tau", "τ", "h", 1.0)):
        e = fit["lumped"][key]
        v, lo, hi = (None if e.get(k) is None else e[k] / scale for k in ("value", "low", "high"))
        rows.append([label, unit, _fmt(v, ".4g"), f"{_fmt(lo, '.4g')} … {_fmt(hi, '.4g')}",
                     "data" if e.get("determined", True) else "not determined"])
    return _table(["quantity", "unit", "estimate", "95 % interval", "determined by"], rows)


def _param_table(fit: dict, truth: HouseParameters | None) -> str:
    rows = []
    true = truth.as_dict() if truth is not None else {}
    for name, value in fit["parameters"].items():
        rng = fit.get("bounds", {}).get(name)
        # a parameter the data do not determine is shown as its prior (the range centre)
        shown = (fit.get("table_iv") or {}).get(name) if isinstance(
            fit.get("table_iv"), dict) else None
        value = shown.get("value", value) if isinstance(shown, dict) else value
        row = [name, fit.get("units", {}).get(name, ""), _fmt(value),
               "—" if not rng else f"{rng[0]:.3g} – {rng[1]:.3g}",
               "data" if fit.get("determined", {}).get(name) else
               f"prior: {fit.get('basis', {}).get(name, 'prior')} centre"]
        if truth is not None:
            row.insert(3, _fmt(float(true[name])))
        rows.append(row)
    headers = ["parameter", "unit", "estimate", "search range", "determined by"]
    if truth is not None:
        headers.insert(3, "true")
    return _table(headers, rows)


def _flexibility_section(fit: dict) -> list[str]:
    """What the house offers an aggregator (:mod:`impctl.flex`), from the fit's block."""
    from ..fit.result.report import flexibility_block

    flex = fit.get("flexibility") or flexibility_block(fit)
    if flex.get("coast_h") is None:
        return []
    rows = [["coast: heating off until T_air has fallen "
             f"{flex['drop_k']:g} K", "h", _fmt(flex["coast_h"], ".2f"),
             f"{_fmt(flex['coast_h_low'], '.2f')} … {_fmt(flex['coast_h_high'], '.2f')}"],
            [f"rebound: heat beyond steady demand in the {flex['rebound_h']:g} h after",
             "kWh", _fmt(flex["rebound_kwh"], ".2f"), "—"],
            ["steady-state heat demand", "W", _fmt(flex["steady_state_w"], ".0f"), "—"]]
    return [f"<h2>Flexibility (at {flex['t_set_c']:g} °C indoors, {flex['t_out_c']:g} °C "
            "outdoors)</h2>",
            _table(["quantity", "unit", "estimate", "95 % interval"], rows),
            f"<p>Coast computed with: {html.escape(str(flex.get('coast_method') or '5R1C'))}"
            f"; internal gain during the coast {_fmt(flex.get('coast_gain_w') or 0.0, '.0f')} "
            "W. Without fitted switch-off terms the 5R1C model's instantaneous air-temperature "
            f"drop at switch-off ({_fmt(flex.get('switch_off_drop_k'), '.1f')} K here, a "
            "massless air node) is not counted; see <code>impctl flex</code>.</p>"]


_CSS = """body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:1em 0;font-size:14px}td,th{border:1px solid #ccc;
padding:3px 8px;text-align:left}th{background:#f3f3f3}img{max-width:100%;margin:.5em 0}
.note{background:#fff8e0;border-left:4px solid #e0b000;padding:.5em 1em}
.household{background:#eef6ee;border-left:4px solid #3a8a3a;padding:.2em 1.2em;margin:1em 0}
.lead{font-size:1.2em}pre{background:#f6f6f6;
padding:1em;overflow-x:auto}"""


def write_report(db_path: str | Path, out: str | Path, *, fit: dict | None = None,
                 truth: HouseParameters | None = None, summary: dict | None = None,
                 demand: dict | None = None, tz: str = "Europe/Ljubljana",
                 curve: dict | None = None) -> Path:
    """Write OUT/report.html and OUT/fig_*.png; returns the HTML path.

    Parameters
    ----------
    db_path : the impctl store
    out : output directory
    fit : a fit result (``impctl fit`` JSON); default: the newest fit in the store
    truth : the true house (demo, simulations) for the comparison columns
    summary : the demo summary (:func:`demo_summary`), printed on the page
    demand : an out-of-sample heat-demand check (:mod:`impctl.report.demand`); default: the
        fit's own validation
    curve : an ``impctl curve`` result (``impctl-curve/1``); default: the one the daemon
        keeps beside the store (``curve.json``), if any
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError("--out must be a directory", out)
    with Store(db_path, create=False) as store:
        source = None
        if fit is None:
            source = db_path
            last = store.last_fit()
            if last is None:
                raise InputError("no fit stored yet: run a campaign (or impctl fit) first",
                                 db_path)
            fit = last[2]
        why = fit_problem(fit)
        if why is not None:
            raise InputError(f"not a fit result: {why}", source)
        nights_html = _nights_table(store, tz)
        campaign = _campaign_rows(store, tz)
        zone = ZoneInfo(tz)
        comfort = [night_comfort(n, store.samples(n.id),
                                 f"{n.window_start.astimezone(zone):%Y-%m-%d}")
                   for n in store.nights()]
    # Drawn into a temporary directory beside OUT and moved in only when everything is
    # written: a failure leaves no half report (and no stray PNGs).
    if not out.parent.is_dir():
        raise InputError(f"the folder {out.parent} does not exist", out)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    umask = os.umask(0)
    os.umask(umask)
    tmp.chmod(0o777 & ~umask)  # mkdtemp makes it 0700; OUT gets the usual permissions
    try:
        if curve is None and (Path(db_path).parent / "curve.json").is_file():
            from .curve import read_curve_json

            try:
                curve = read_curve_json(Path(db_path).parent / "curve.json")
            except InputError:
                curve = None  # a kept curve that does not read is no reason to lose the report
        _render(tmp, fit, truth, summary, demand, nights_html, campaign,
                household_html(household_summary(fit, comfort)), curve)
        if out.exists():
            for item in tmp.iterdir():
                os.replace(item, out / item.name)
            tmp.rmdir()
        else:
            os.replace(tmp, out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out / "report.html"


def _curve_parts(curve: dict, out: Path) -> list[str]:
    from .curve import curve_section

    return curve_section(curve, out, _img)


def _campaign_rows(store: Store, tz: str) -> tuple[list[dict], list[list[str]]]:
    """The intervals after each stored fit, and the adaptive campaign's decisions."""
    from ..campaign import FitSummary

    def rel_pct(x: float) -> float | None:
        return round(100 * x, 1) if x != float("inf") else None

    rows = []
    for f in store.fits():
        try:
            fs = FitSummary.from_fit_json(f.result, f.night_count)
        except ValueError:
            continue
        rows.append({"valid_nights": f.night_count, "hlc_w_per_k": fs.hlc_w_per_k,
                     "hlc_rel_pct": rel_pct(fs.hlc_rel), "tau_h": fs.tau_h,
                     "tau_rel_pct": rel_pct(fs.tau_rel)})
    zone = ZoneInfo(tz)
    decisions = [[("—" if d.act is None else f"{d.act.astimezone(zone):%Y-%m-%d %H:%M}"),
                  d.action, d.reason] for d in reversed(store.decisions(200))]
    return rows, decisions


def _campaign_section(out: Path, campaign: tuple[list[dict], list[list[str]]]) -> list[str]:
    rows, decisions = campaign
    if len(rows) < 2 and not decisions:
        return []
    parts = ["<h2>Campaign: how the intervals shrank</h2>"]
    if rows:
        parts.append(_table(
            ["valid nights", "HLC [W/K]", "HLC ± [%]", "τ [h]", "τ ± [%]"],
            [[str(r["valid_nights"]), _fmt(r["hlc_w_per_k"], ".4g"),
              _fmt(r["hlc_rel_pct"], ".1f"), _fmt(r["tau_h"], ".4g"),
              _fmt(r["tau_rel_pct"], ".1f")] for r in rows]))
    if len(rows) >= 2:
        parts.append(_img(figures.campaign_intervals(rows, out / "fig_campaign.png")))
    if decisions:
        parts += ["<p>Decisions of the adaptive campaign (local time of the night's preheat):"
                  "</p>", _table(["act", "decision", "why"], decisions)]
    return parts


def _render(out: Path, fit: dict, truth: HouseParameters | None, summary: dict | None,
            demand: dict | None, nights_html: str,
            campaign: tuple[list[dict], list[list[str]]] = ([], []),
            household: str = "", curve: dict | None = None) -> None:
    figs = [
        figures.night_fits(fit, out / "fig_nights.png"),
        figures.heat_demand(demand or fit.get("validation", {}), out / "fig_heat_demand.png"),
        figures.class_probabilities(fit, out / "fig_classes.png"),
        figures.parameter_ranges(fit, out / "fig_parameters.png", truth),
    ]
    notes = fit.get("notes", [])
    val = ((demand or {}).get("mean") or fit.get("validation", {}).get("mean", {}) or {})
    how = ("the fitted house re-simulated over the whole campaign, against the measured heat "
           "(out of sample)" if demand and demand.get("mean") else
           "the fit's own validation (in sample: each night's fitted initial mass temperature)")
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>impctl report</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>impctl: house identification report</h1>",
        f"<div class='household'>{household}</div>" if household else "",
        *(_curve_parts(curve, out) if curve is not None else []),
        "<p><i>Below: the engineer's tables and figures.</i></p>" if household else "",
        "<h2>What the nights determine</h2>", _lumped_table(fit),
        f"<p>Intervals: {html.escape(fit.get('interval_method', ''))}</p>",
        *[f"<p>{html.escape(str(g.get('statement')))} — source: "
          f"{html.escape(str(g.get('source', 'assumed')))} (sleepers and base load; its error "
          "moves the HLC by itself over the mean indoor–outdoor difference)</p>"
          for g in [(fit.get("fit") or {}).get("night_gain")] if isinstance(g, dict)],
        *[f"<p class='warn'>{html.escape(str(t.get('statement')))} (the bound, not the "
          "nights, set it)</p>" for t in _list((fit.get("fit") or {}).get("nuisance_at_bound"))
          if isinstance(t, dict)],
        *_flexibility_section(fit),
        "<h2>Measured vs fitted, night by night (T_air with the heating off, heat power "
        "where T_air was held)</h2>", _img(figs[0]),
        "<h2>Heat demand on the normal nights</h2>", _img(figs[1]),
        f"<p>ε = {_fmt(val.get('eps_pct'), '.1f')} %, ΔQ_total = "
        f"{_fmt(val.get('dq_total_kwh'), '.2f')} kWh, ΔQ_power = "
        f"{_fmt(val.get('dq_power_kw'), '.3f')} kW (the paper's Table V: 18.7–20.2 %); "
        f"{html.escape(how)}.</p>",
        "<h2>Parameter classes</h2>", _img(figs[2]),
        "<h2>Physical parameters</h2>", _param_table(fit, truth), _img(figs[3]),
        "<h2>Identifiability</h2><div class='note'><p>Night data determine the lumped "
        "heat-loss coefficient HLC, the heat capacity C_m and the time constant τ. The seven "
        "physical parameters enter the night-time equations only through a few combinations "
        "(u_walls·walls_area, u_windows·windows_area, c_f·floor_area): a parameter marked "
        "'class range only' or 'physical bounds only' is a point inside the search range "
        "consistent with the data, not a measurement.</p>"
        + "".join(f"<p>{html.escape(n)}</p>" for n in notes) + "</div>",
        "<h2>Nights and their data quality</h2>", nights_html,
        *_campaign_section(out, campaign),
    ]
    if fit.get("night_quality"):
        from ..fit.result.table import QUALITY_HEADERS, quality_rows

        parts += ["<h2>Night quality and model adequacy</h2>",
                  _table(QUALITY_HEADERS, quality_rows(fit)),
                  f"<p>{html.escape((fit.get('adequacy') or {}).get('statement', ''))}</p>"]
    if summary is not None:
        parts += ["<h2>Demo: truth vs estimate</h2>",
                  f"<pre>{html.escape(format_summary(summary))}</pre>"]
    parts += ["<h2>Fit settings</h2>",
              f"<pre>{html.escape(json.dumps(fit.get('fit', {}), indent=2))}</pre>",
              "</body></html>"]
    (out / "report.html").write_text("\n".join(parts), encoding="utf-8")
