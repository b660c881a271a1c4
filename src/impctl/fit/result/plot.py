"""The fit's figure (matplotlib): one panel per night in a grid that wraps — measured vs fitted
T_air on the nights whose T_air the model predicts (constrained nights), measured vs predicted
heat power on the nights whose T_air is held and is the model's input (normal nights).

The report's nights figure (:func:`impctl.report.figures.night_fits`) draws the same panels
from a fit JSON.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

#: Most panels side by side: four panels of 3.4 in at 110 dpi are 1,500 px, a laptop screen.
MAX_COLUMNS = 4
_PANEL_IN = (3.4, 2.5)
_COLORS = {"constrained": "tab:blue", "normal": "tab:red"}
_MEASURED = "0.35"


def grid_shape(n_panels: int, max_cols: int = MAX_COLUMNS) -> tuple[int, int]:
    """(rows, columns) of a grid holding ``n_panels``: at most ``max_cols`` columns, the rows
    wrapping; one empty panel's grid for none."""
    n = max(1, int(n_panels))
    cols = min(max_cols, n)
    return math.ceil(n / cols), cols


def shows_power(pred: dict) -> bool:
    """True when a night's panel shows heat power: its T_air is held (the model's input), so
    the fit predicts the heat power instead."""
    return pred.get("t_air_model_c") is None and pred.get("q_model_w") is not None


def draw_nights(preds: list[dict], title: str | None = None, dpi: float = 110):
    """A matplotlib figure of ``preds`` (``impctl fit`` JSON ``predictions``): one panel per
    night in :func:`grid_shape`, a legend for every line drawn, heat-power axes from 0 kW,
    and the same T_air range on every T_air panel so nights compare at a glance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows, cols = grid_shape(len(preds))
    fig, axes = plt.subplots(rows, cols, figsize=(_PANEL_IN[0] * cols, _PANEL_IN[1] * rows + 0.7),
                             squeeze=False, dpi=dpi)
    for ax in axes.flat[len(preds):]:
        ax.axis("off")
    if not preds:
        axes[0, 0].text(0.5, 0.5, "no fitted curves in this result", ha="center",
                        transform=axes[0, 0].transAxes)
    power_top_kw = max([float(np.nanmax(np.asarray(p[k], float))) / 1e3 for p in preds
                        if shows_power(p) for k in ("q_measured_w", "q_model_w")
                        if len(p[k])] or [1.0])
    t_values = [np.asarray(p[k], float) for p in preds if not shows_power(p)
                for k in ("t_air_measured_c", "t_air_model_c") if p.get(k) is not None]
    t_range = _padded(np.concatenate(t_values)) if t_values else None
    handles: dict[str, object] = {}
    for ax, p in zip(axes.flat, preds, strict=False):
        t_h = np.asarray(p["time_s"], float) / 3600.0
        color = _COLORS.get(p["kind"], "k")
        if shows_power(p):
            (m,) = ax.plot(t_h, np.asarray(p["q_measured_w"], float) / 1e3, ".", ms=2.5,
                           color=_MEASURED)
            (f,) = ax.plot(t_h, np.asarray(p["q_model_w"], float) / 1e3, "-", lw=1.4,
                           color=color)
            handles.setdefault("measured", m)
            handles.setdefault("heat power predicted (normal night, T_air held)", f)
            ax.set_ylim(0, power_top_kw * 1.08)
            ax.set_ylabel("heat power [kW]", fontsize=7)
            held = np.nanmean(np.asarray(p["t_air_measured_c"], float))
            ax.set_title(f"{p['night_id']} · normal, T_air held ≈ {held:.1f} °C", fontsize=8,
                         color=color)
        else:
            (m,) = ax.plot(t_h, p["t_air_measured_c"], ".", ms=2.5, color=_MEASURED)
            handles.setdefault("measured", m)
            if p.get("t_air_model_c") is not None:
                (f,) = ax.plot(t_h, p["t_air_model_c"], "-", lw=1.4, color=color)
                handles.setdefault(f"T_air fitted ({p['kind']} night)", f)
            if t_range is not None:
                ax.set_ylim(*t_range)
            ax.set_ylabel("T_air [°C]", fontsize=7)
            ax.set_title(f"{p['night_id']} · {p['kind']}", fontsize=8, color=color)
        ax.set_xlabel("h since window start", fontsize=7)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.25)
    if handles:
        fig.legend(list(handles.values()), list(handles), loc="upper center",
                   ncol=min(3, len(handles)), fontsize=8, frameon=False, markerscale=3,
                   bbox_to_anchor=(0.5, 1.0 - 0.25 / fig.get_figheight()))
    if title:
        fig.suptitle(title, fontsize=10, y=1.0 - 0.05 / fig.get_figheight())
    fig.tight_layout(rect=(0, 0, 1, 1.0 - 0.5 / fig.get_figheight()))
    return fig


def _padded(values: np.ndarray) -> tuple[float, float]:
    """A T_air axis range around ``values`` with a little room, at least 2 K tall."""
    lo, hi = float(np.nanmin(values)), float(np.nanmax(values))
    mid, half = (lo + hi) / 2, max(hi - lo, 2.0) / 2 * 1.08
    return mid - half, mid + half


def plot_fit(fit, path: str | Path) -> None:
    """Measured vs fitted T_air (the paper's Fig. 5) and heat power per night, as a grid."""
    save_figure(*figure_of(fit), path)


def figure_of(fit) -> tuple[list[dict], str]:
    """What :func:`plot_fit` draws of a fitted NightFit: its curves per night (numpy arrays,
    as fitted: not the JSON's rounded lists) and the figure's title — plain data, which a
    process without torch can draw (:func:`save_figure`)."""
    hlc = fit.lumped_["hlc"]
    title = (f"5R1C night fit: HLC {hlc.value:.0f} W/K [{hlc.low:.0f}–{hlc.high:.0f}], "
             f"τ {fit.lumped_['tau'].value:.1f} h")
    return list(fit.predictions_), title


def save_figure(preds: list[dict], title: str, path: str | Path) -> None:
    """:func:`draw_nights` of ``preds`` under ``title``, written to ``path``."""
    import matplotlib.pyplot as plt

    fig = draw_nights(preds, title)
    fig.savefig(path)
    plt.close(fig)
