"""The curve's figure: flow temperature against outdoor temperature — what the house needs
(central, and the bound the recommendation keeps above), the curve the heat pump runs, the
recommended one, and the hours the running curve was read from. Drawn from the JSON, so the
report draws the same figure from a stored result.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def draw_curve(result: dict, dpi: float = 110):
    """A matplotlib figure of an ``impctl-curve/1`` JSON object."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    need = result["need"]
    t = np.asarray(need["t_out_c"], float)
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=dpi)
    ax.fill_between(t, need["flow_c"], need["flow_upper_c"], color="tab:green", alpha=0.25,
                    lw=0, label=f"what the house needs ({result['confidence']:.0%} bound)")
    ax.plot(t, need["flow_c"], color="tab:green", lw=1.2)
    rec = result["recommended"]
    ax.plot(rec["t_out_c"], rec["flow_c"], color="tab:blue", lw=2.2,
            label=f"recommended ({result['margin_k']:g} K margin)")
    run = result.get("running")
    if run is not None:
        what = "heat pump's target" if run["source"] == "target" else "measured flow"
        ax.plot(run["t_out_c"], run["flow_c"], color="tab:red", lw=2.0, ls="--",
                label=f"running now ({what})")
        lo, hi = run["t_out_range_c"]
        ax.axvspan(lo, hi, color="0.9", zorder=0, label="outdoor range recorded")
    ax.set_xlabel("outdoor temperature [°C]")
    ax.set_ylabel("flow temperature [°C]")
    sp = result["setpoint_c"]["value"]
    ax.set_title(f"Heating curve for a room at {sp:.1f} °C")
    ax.set_xlim(t.min(), t.max())
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    return fig


def plot_curve(result: dict, path: str | Path) -> Path:
    """Draw :func:`draw_curve` into ``path`` (PNG)."""
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = draw_curve(result)
    fig.savefig(path)
    plt.close(fig)
    return path
