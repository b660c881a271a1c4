"""The fleet report: one HTML page with PNG figures from a FLEET dataset.

Distributions of HLC, τ and coast time over the fitted households, the widths of their 95 %
intervals, the households that need more nights, and the failures grouped by reason.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from .page import img as _img
from .page import table as _table

_CSS = """body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:1em 0;font-size:14px}td,th{border:1px solid #ccc;
padding:3px 8px;text-align:left}th{background:#f3f3f3}img{max-width:100%;margin:.5em 0}"""
_LIST_MAX = 200




def _hist(ax, values, label: str) -> None:
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if len(v):
        ax.hist(v, bins=min(40, max(5, len(v) // 5)), color="#4a7ab5")
        ax.axvline(np.median(v), color="k", lw=1, ls="--", label=f"median {np.median(v):.3g}")
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "no fitted household", ha="center", transform=ax.transAxes)
    ax.set_xlabel(label, fontsize=8)
    ax.tick_params(labelsize=7)


def _figures(ok, out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dist = out / "fig_fleet_distributions.png"
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.2))
    for ax, col, label in zip(axes, ("hlc_w_per_k", "tau_h", "coast_h"),
                              ("HLC [W/K]", "τ [h]", "coast time [h]"), strict=True):
        _hist(ax, ok[col], label)
    axes[0].set_ylabel("households")
    fig.tight_layout()
    fig.savefig(dist, dpi=100)
    plt.close(fig)

    widths = out / "fig_fleet_intervals.png"
    fig, axes = plt.subplots(1, 4, figsize=(12, 3.0))
    for ax, col, label in zip(axes, ("hlc_w_per_k", "c_m_j_per_k", "tau_h", "coast_h"),
                              ("HLC", "C_m", "τ", "coast time"), strict=True):
        rel = 100.0 * (ok[f"{col}_high"] - ok[f"{col}_low"]) / ok[col]
        _hist(ax, rel, f"{label}: 95 % interval width [% of value]")
    axes[0].set_ylabel("households")
    fig.tight_layout()
    fig.savefig(widths, dpi=100)
    plt.close(fig)
    return [dist, widths]


def write_fleet_report(fleet: str | Path, out: str | Path) -> Path:
    """Write OUT/fleet_report.html and its PNG figures from the FLEET dataset ``fleet``."""
    from ..fleet.results.manifest import completeness
    from ..fleet.results.table import read_fleet

    table = read_fleet(fleet)
    # an interrupted run's distributions are those of the households it reached: said first
    partial = completeness(fleet)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ok = table[table["status"] == "ok"]
    figs = _figures(ok, out)
    counts = table["status"].value_counts()
    status_rows = [[s, int(counts.get(s, 0)),
                    f"{100.0 * counts.get(s, 0) / max(1, len(table)):.1f} %"]
                   for s in ("ok", "insufficient", "error")]
    failed = table[table["status"] != "ok"]
    reasons = []
    for (status, reason), group in failed.groupby(["status", "reason"], dropna=False):
        reasons.append([status, reason, len(group), ", ".join(group["household"].head(5)),
                        str(group["error"].iloc[0])[:200]])
    reasons.sort(key=lambda r: -r[2])
    more = table[(table["status"] == "insufficient") | table["needs_more_nights"].fillna(False)
                 .astype(bool)]
    more_rows = []
    for _, r in more.head(_LIST_MAX).iterrows():
        if r["status"] == "insufficient":
            what = r["reason"]
        else:
            what = "not determined: " + ", ".join(
                q for q, c in (("HLC", "hlc_w_per_k"), ("C_m", "c_m_j_per_k"), ("τ", "tau_h"))
                if not bool(r.get(f"{c}_determined")))
        more_rows.append([r["household"], r["status"], r["nights_constrained"],
                          r["nights_normal"], what])

    changed = (table[table["season_changed"].fillna(False).astype(bool)]
               if "season_changed" in table else table.iloc[:0])
    changed_rows = [[r["household"], str(r["season_changed_since"]),
                     f"{r['season_change_w_per_k']:+.0f} (95 % "
                     f"{r['season_change_w_per_k_low']:+.0f} – "
                     f"{r['season_change_w_per_k_high']:+.0f})",
                     int(r["season_change_nights_after"])]
                    for _, r in changed.head(_LIST_MAX).iterrows()]

    def q(col, scale=1.0):
        v = ok[col].to_numpy(float) / scale
        v = v[np.isfinite(v)]
        return [f"{np.percentile(v, p):.3g}" if len(v) else "—" for p in (10, 50, 90)]

    summary = [["HLC", "W/K", *q("hlc_w_per_k")], ["C_m", "MJ/K", *q("c_m_j_per_k", 1e6)],
               ["τ", "h", *q("tau_h")], ["coast time", "h", *q("coast_h")],
               ["rebound", "kWh", *q("rebound_kwh")]]
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>impctl fleet report</title>",
        f"<style>{_CSS}</style></head><body>",
        f"<h1>impctl: fleet report ({len(table)} households)</h1>",
        f"<p><strong>{html.escape(partial)}</strong></p>" if partial else "",
        _table(["status", "households", "share"], status_rows),
        "<h2>Distributions over the fitted households</h2>",
        _table(["quantity", "unit", "P10", "median", "P90"], summary), _img(figs[0]),
        "<p>Coast time: hours with the heating off, from steady state at 21 °C indoors and "
        "0 °C outdoors, until the indoor air has fallen 1 K (impctl flex).</p>",
        "<h2>Interval widths</h2>", _img(figs[1]),
        f"<h2>Households needing more nights ({len(more)})</h2>",
        "<p>Too few usable nights, or nights that leave HLC, C_m or τ undetermined.</p>",
        _table(["household", "status", "constrained nights", "normal nights", "what is missing"],
               more_rows)
        + (f"<p>… and {len(more) - _LIST_MAX} more.</p>" if len(more) > _LIST_MAX else ""),
        f"<h2>Households whose heat loss changed ({len(changed)})</h2>",
        "<p>The change test on each household's owner nights found a step in its heat loss — "
        "a window left open for days, insulation added. The season values still read the "
        "nights before it.</p>",
        _table(["household", "since", "change [W/K]", "owner nights since"], changed_rows)
        + (f"<p>… and {len(changed) - _LIST_MAX} more.</p>" if len(changed) > _LIST_MAX
           else ""),
        f"<h2>Failures by reason ({len(failed)})</h2>",
        _table(["status", "reason", "households", "examples", "first message"], reasons),
        "</body></html>",
    ]
    page = out / "fleet_report.html"
    page.write_text("\n".join(parts), encoding="utf-8")
    return page
