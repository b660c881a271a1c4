"""The report's PNG figures, drawn from a fit result (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def night_fits(fit: dict, path: Path) -> Path:
    """Measured vs fitted T_air per constrained night (the paper's Fig. 5, blue) and measured
    vs predicted heat power per normal night, where T_air is held and the model's input (red):
    a grid of at most four columns, a legend, power axes from 0 kW
    (:func:`impctl.fit.result.plot.draw_nights`)."""
    from ..fit.result.plot import draw_nights

    plt = _plt()
    fig = draw_nights(fit.get("predictions") or [], dpi=100)
    fig.savefig(path)
    plt.close(fig)
    return path


def heat_demand(validation: dict, path: Path) -> Path:
    """Heat delivered per normal night [kWh]: measured vs predicted (Fig. 3/4 style).

    ``validation`` holds ``normal`` rows with ``q_measured_kwh`` and ``q_model_kwh``.
    """
    plt = _plt()
    rows = validation.get("normal", []) or []
    fig, ax = plt.subplots(figsize=(6.5, 3.0))
    if rows:
        x = np.arange(len(rows))
        meas = [r["q_measured_kwh"] for r in rows]
        model = [r["q_model_kwh"] for r in rows]
        ax.bar(x - 0.2, meas, 0.4, label="measured", color="0.55")
        ax.bar(x + 0.2, model, 0.4, label="predicted (fitted model)", color="tab:red")
        ax.set_xticks(x, [str(r["night_id"]) for r in rows], fontsize=7)
        ax.set_xlabel("normal night")
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, "no normal nights", ha="center", transform=ax.transAxes)
    ax.set_ylabel("heat over the night [kWh]")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def class_probabilities(fit: dict, path: Path) -> Path:
    """The classified range of floor area, mass class and wall U with its probability, each
    bar saying what that probability is: calibrated, or the forest's vote share."""
    plt = _plt()
    fig = class_figure(fit)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def class_figure(fit: dict):
    """The figure of :func:`class_probabilities` (matplotlib Figure, not saved)."""
    from ..fit.result.report import probability_kind

    plt = _plt()
    classes = fit.get("classes", {})
    fig, ax = plt.subplots(figsize=(6.5, 2.4))
    names = list(classes)
    probs = [classes[n].get("probability") or 0.0 for n in names]
    labels = []
    for n in names:
        lo, hi = classes[n]["range"]
        labels.append(f"{n}\n{lo:g}–{hi:g}\n({classes[n].get('source', '')})")
    ax.barh(range(len(names)), probs, color="tab:green")
    for i, n in enumerate(names):
        if classes[n].get("probability") is not None:
            inside = probs[i] > 0.7  # the words fit inside a long bar, beside a short one
            ax.text(probs[i] + (-0.01 if inside else 0.01), i,
                    f"{probs[i]:.2f} {probability_kind(classes[n])}",
                    ha="right" if inside else "left", va="center", fontsize=7,
                    color="white" if inside else "0.2")
        else:  # no class: the nights do not determine it (or no classifier ran)
            ax.text(0.01, i, "no class: the whole prior range", ha="left", va="center",
                    fontsize=7, color="0.2")
    ax.set_yticks(range(len(names)), labels, fontsize=7)
    ax.set_xlim(0, 1)
    kinds = {probability_kind(c) for c in classes.values() if c.get("probability") is not None}
    what = kinds.pop() if len(kinds) == 1 else "per bar"
    ax.set_xlabel(f"probability of the chosen range ({what})")
    fig.tight_layout()
    return fig


def parameter_ranges(fit: dict, path: Path, truth=None) -> Path:
    """Left: HLC, C_m and τ with their 95 % intervals (and the truth when known). Right: each
    physical parameter's estimate inside its search range (0 = low bound, 1 = high); filled
    markers = determined by the data, open = only by the range."""
    plt = _plt()
    names = list(fit["parameters"])
    bounds = fit.get("bounds", {})
    true = truth.as_dict() if truth is not None else {}
    fig, (ax_l, ax) = plt.subplots(1, 2, figsize=(9.5, 3.0),
                                   gridspec_kw={"width_ratios": [1, 1.6]})
    true_lumped = {} if truth is None else {
        "hlc": float(truth.hlc_w_per_k), "c_m": float(truth.c_m_j_per_k),
        "tau": float(truth.tau_h)}
    for i, key in enumerate(("hlc", "c_m", "tau")):
        e = fit["lumped"][key]
        ref = e["value"]
        if e.get("low") is not None and e.get("high") is not None:
            ax_l.plot([100 * (e["low"] / ref - 1), 100 * (e["high"] / ref - 1)], [i, i],
                      color="tab:red", lw=3, alpha=0.5)
        ax_l.plot(0, i, "o", color="tab:red")
        if key in true_lumped:
            ax_l.plot(100 * (true_lumped[key] / ref - 1), i, "|", color="k", ms=14)
    ax_l.set_yticks(range(3), ["HLC", "C_m", "τ"], fontsize=8)
    ax_l.axvline(0, color="0.8", lw=0.8)
    ax_l.set_xlabel("% from the estimate (bar: 95 % interval, |: true)", fontsize=7)
    ax_l.tick_params(labelsize=7)
    for i, name in enumerate(names):
        lo, hi = bounds.get(name, (0.0, 1.0))
        span = (hi - lo) or 1.0
        est = (fit["parameters"][name] - lo) / span
        det = fit.get("determined", {}).get(name, False)
        ax.plot([0, 1], [i, i], color="0.85", lw=6, solid_capstyle="butt")
        ax.plot(est, i, "o", color="tab:red", mfc="tab:red" if det else "white")
        if name in true:
            ax.plot((float(true[name]) - lo) / span, i, "|", color="k", ms=14)
    ax.set_yticks(range(len(names)), names, fontsize=7)
    ax.set_xlim(-0.05, 1.05)
    ax.set_xlabel("position in the search range; | = true value", fontsize=7)
    ax.tick_params(labelsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def campaign_intervals(rows: list[dict], path: Path) -> Path:
    """How the 95 % half-widths of HLC and τ (relative to the estimates, %) shrank fit after
    fit, against the valid nights each fit used (the adaptive campaign's progress)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5.5, 3.2))
    n = [r["valid_nights"] for r in rows]
    for key, label, color in (("hlc_rel_pct", "HLC", "tab:blue"), ("tau_rel_pct", "τ",
                                                                   "tab:orange")):
        ys = [np.nan if r[key] is None else r[key] for r in rows]
        ax.plot(n, ys, "o-", color=color, label=label)
    ax.set_xlabel("valid nights in the fit")
    ax.set_ylabel("95 % half-width / estimate [%]")
    ax.set_yscale("log")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
