"""The fit's figure (matplotlib): measured vs fitted T_air per night, heat power on normal
nights."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_fit(fit, path: str | Path) -> None:
    """Measured vs fitted T_air per night (the paper's Fig. 5) and heat power on normal nights."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    preds = fit.predictions_
    n = len(preds)
    fig, axes = plt.subplots(2, n, figsize=(max(6.0, 2.6 * n), 5.5), squeeze=False,
                             sharey="row")
    for i, p in enumerate(preds):
        t_h = np.asarray(p["time_s"]) / 3600.0
        ax = axes[0, i]
        ax.plot(t_h, p["t_air_measured_c"], ".", ms=3, label="measured")
        if p["t_air_model_c"] is not None:
            ax.plot(t_h, p["t_air_model_c"], "-", lw=1.2, label="fitted")
        else:
            ax.text(0.5, 0.08, "held: model input", ha="center", transform=ax.transAxes,
                    fontsize=7)
        ax.set_title(f"{p['night_id']}\n{p['kind']}", fontsize=8)
        ax.tick_params(labelsize=7)
        ax2 = axes[1, i]
        if "q_model_w" in p:
            ax2.plot(t_h, np.asarray(p["q_measured_w"]) / 1e3, ".", ms=3, label="measured")
            ax2.plot(t_h, np.asarray(p["q_model_w"]) / 1e3, "-", lw=1.2, label="predicted")
        else:
            ax2.text(0.5, 0.5, "heating off", ha="center", va="center",
                     transform=ax2.transAxes, fontsize=8)
            ax2.set_xlim(ax.get_xlim())
        ax2.set_xlabel("h since window start", fontsize=7)
        ax2.tick_params(labelsize=7)
    axes[0, 0].set_ylabel("T_air [°C]")
    axes[1, 0].set_ylabel("heat power [kW]")
    for row in axes:
        with_lines = [a for a in row if a.get_legend_handles_labels()[0]]
        if with_lines:
            with_lines[0].legend(fontsize=7)
    hlc = fit.lumped_["hlc"]
    fig.suptitle(f"5R1C night fit: HLC {hlc.value:.0f} W/K [{hlc.low:.0f}–{hlc.high:.0f}], "
                 f"τ {fit.lumped_['tau'].value:.1f} h", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
