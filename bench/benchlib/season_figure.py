"""bench/season.py's figure: the error against the owner nights, drawn from the summary a run
prints (``--figure``) or saved (``--json``, redrawn by ``--from-json``).

Top row, one panel per quantity (HLC, τ, C_m): |error| median and P90 [%] with their 95 %
bootstrap intervals as error bars, against the owner nights; the energy signature's HLC beside
the season model's. Bottom row: the coverage of the 95 % intervals [%] and their median
half-width [%]. The 0-night point is the IMP fit alone: the run's own (``--owner-nights 0,…``,
the same households), or — when the run has none — bench/fit.py's figure of record
(:data:`IMP_ONLY_PUBLISHED`), other households, drawn apart and said so on the axis.

A saved JSON is checked before anything is drawn (:func:`check_saved`): a missing or mistyped
key is one line naming the file and the place (:class:`SavedError`), and nothing is written.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path

#: Quantity names of the summary, with the label and unit the figure gives them.
QUANTITIES = {"HLC": "HLC [W/K]", "tau": "τ [h]", "C_m": "C_m [J/K]"}
#: Keys every quantity of a summary row carries (bench/season.py ``summarize``).
QUANTITY_KEYS = ("median_pct", "median_ci", "p90_pct", "p90_ci", "coverage", "half_width_pct")
#: The IMP fit alone on the realistic plant, 8 IMP nights of the gateway (2 constrained, 6
#: normal), 5-minute rows, true class ranges: bench/fit.py's figure of record
#: (docs/explanation/accuracy.md, "The fit"), 50 households other than the season bench's. Only
#: the medians and P90 were published, not their bootstrap intervals.
IMP_ONLY_PUBLISHED = {
    "command": "bench/fit.py --households 50 --ranges true --steps 300 --no-lsq",
    "households": 50,
    "HLC": {"median_pct": 13.3, "p90_pct": 31.4, "coverage": 0.94, "half_width_pct": 43.0},
    "tau": {"median_pct": 10.2, "p90_pct": 26.0, "coverage": 1.00, "half_width_pct": 46.0},
    "C_m": {"median_pct": 13.6, "p90_pct": 37.1, "coverage": 1.00, "half_width_pct": 48.0},
}


class SavedError(ValueError):
    """A saved JSON the figure cannot be drawn from: ``str`` is the one line to print."""

    def __init__(self, source: str | Path, place: str, problem: str):
        super().__init__(f"{source}: {place}: {problem}" if place else f"{source}: {problem}")


def _number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _interval(x) -> bool:
    return isinstance(x, list) and len(x) == 2 and all(_number(v) for v in x)


def check_saved(data, source: str | Path) -> None:
    """Raise :class:`SavedError` unless ``data`` (a loaded JSON of ``bench/season.py --json``)
    holds what the figure draws: ``args`` (households, seed, variant) and ``summary`` rows,
    each with owner_nights and per quantity :data:`QUANTITY_KEYS`."""
    hint = "(bench/season.py --json writes it; a --calibrate run has none)"
    if not isinstance(data, dict):
        raise SavedError(source, "", f"not a JSON object {hint}")
    for key in ("args", "summary"):
        if key not in data:
            raise SavedError(source, "", f"no key {key!r} {hint}")
    args = data["args"]
    if not isinstance(args, dict):
        raise SavedError(source, "args", "not an object")
    for key in ("households", "seed", "variant"):
        if key not in args:
            raise SavedError(source, "args", f"no key {key!r}")
    rows = data["summary"]
    if not isinstance(rows, list) or not rows:
        raise SavedError(source, "summary", f"not a non-empty list {hint}")
    for i, row in enumerate(rows):
        place = f"summary[{i}]"
        if not isinstance(row, dict):
            raise SavedError(source, place, "not an object")
        n = row.get("owner_nights")
        if not isinstance(n, int) or isinstance(n, bool) or n < 0:
            raise SavedError(source, f"{place}.owner_nights",
                             f"{n!r} is not a number of nights (0 or more)")
        for name in QUANTITIES:
            q = row.get(name)
            if not isinstance(q, dict):
                raise SavedError(source, place, f"no quantity {name!r}")
            for key in QUANTITY_KEYS:
                ok = _interval if key.endswith("_ci") else _number
                if not ok(q.get(key)):
                    what = "two numbers" if key.endswith("_ci") else "a number"
                    raise SavedError(source, f"{place}.{name}.{key}",
                                     f"{q.get(key)!r} is not {what}"
                                     if key in q else "missing")
        sig = row.get("signature")
        if sig is not None and not (isinstance(sig, dict) and _number(sig.get("median_pct"))
                                    and _interval(sig.get("median_ci"))
                                    and _number(sig.get("p90_pct"))):
            raise SavedError(source, f"{place}.signature",
                             "needs median_pct, median_ci and p90_pct")
    if len({r["owner_nights"] for r in rows}) != len(rows):
        raise SavedError(source, "summary", "an owner-night count appears twice")


def load_saved(path: str | Path) -> dict:
    """A saved JSON, checked (:func:`check_saved`); :class:`SavedError` when it cannot be read."""
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except OSError as exc:
        raise SavedError(path, "", exc.strerror or str(exc)) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise SavedError(path, "", f"not JSON ({exc})") from None
    check_saved(data, path)
    return data


def check_target(path: str | Path) -> None:
    """Raise :class:`SavedError` unless the figure can be written at ``path`` (a .png in an
    existing directory): checked before a run, not after an hour of fits."""
    p = Path(path)
    if p.suffix.lower() != ".png":
        raise SavedError(path, "--figure", "give a .png file")
    if not p.parent.resolve().is_dir():
        raise SavedError(path, "--figure", f"no directory {str(p.parent)!r}")
    if p.is_dir():
        raise SavedError(path, "--figure", "is a directory")


def _yerr(value: float, ci) -> list[list[float]]:
    lo, hi = ci
    return [[max(value - lo, 0.0)], [max(hi - value, 0.0)]]


def draw(summary: list[dict], args: dict, path: str | Path) -> bool:
    """Draw the figure of ``summary`` (bench/season.py's rows) into the PNG ``path`` (written
    whole or not at all); True when the 0-night point is bench/fit.py's published one."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(summary, key=lambda r: r["owner_nights"])
    own_zero = any(r["owner_nights"] == 0 for r in rows)
    # the run's own 0-night point is one curve with the rest (the same households)
    season = rows if own_zero else [r for r in rows if r["owner_nights"] > 0]
    # equal steps per count: the usual counts double (7, 14, 28, 56), a log scale with 0 on it
    ticks = [0, *[r["owner_nights"] for r in season if r["owner_nights"] > 0]]
    pos = {n: i for i, n in enumerate(ticks)}
    labels = [str(n) for n in ticks[1:]]
    zero_label = "8 IMP nights,\nother households\n(bench/fit.py)"
    if own_zero:
        zero = rows[0]
        zero_label = "0\n(the IMP fit alone)" + (
            f"\n{zero['unidentified']} of {zero.get('fitted', '?')} without\na constrained night"
            if zero.get("unidentified") else "")
    fig = plt.figure(figsize=(14, 9.2))
    grid = fig.add_gridspec(2, 6, height_ratios=(1.35, 1.0))
    top = [fig.add_subplot(grid[0, 2 * i:2 * i + 2]) for i in range(3)]
    bottom = [fig.add_subplot(grid[1, 0:3]), fig.add_subplot(grid[1, 3:6])]
    colors = dict(zip(QUANTITIES, ("C0", "C1", "C2"), strict=True))
    xs = [pos[r["owner_nights"]] for r in season]
    for ax, (name, label) in zip(top, QUANTITIES.items(), strict=True):
        for key, style, what in (("median", "-o", "median"), ("p90", "--s", "P90")):
            ys = [r[name][f"{key}_pct"] for r in season]
            err = [_yerr(r[name][f"{key}_pct"], r[name][f"{key}_ci"]) for r in season]
            ax.errorbar(xs, ys, yerr=[[e[0][0] for e in err], [e[1][0] for e in err]],
                        fmt=style, color=colors[name], capsize=3, label=f"season model, {what}")
        if not own_zero:
            _published_point(ax, name, colors[name])
        sig = [r for r in season if r.get("signature")] if name == "HLC" else []
        if sig:
            sx = [pos[r["owner_nights"]] for r in sig]
            med = [r["signature"]["median_pct"] for r in sig]
            err = [_yerr(r["signature"]["median_pct"], r["signature"]["median_ci"])
                   for r in sig]
            ax.errorbar(sx, med, yerr=[[e[0][0] for e in err], [e[1][0] for e in err]],
                        fmt="-o", color="0.45", capsize=3, label="energy signature, median")
            # P90s of 80-100 %: said in the legend, not drawn (the panel would flatten)
            p90 = " / ".join(f"{r['signature']['p90_pct']:.0f}" for r in sig)
            ax.plot([], [], " ", label=f"energy signature, P90: {p90} %")
        ax.set_title(f"{label}: |error| against the owner nights", fontsize=10)
        ax.set_ylabel("|error| [%]")
        # head room for the legend above the curves
        top_pct = max((y for line in ax.get_lines() for y in line.get_ydata()
                       if math.isfinite(y)), default=10.0)
        ax.set_ylim(0, (2.4 if name == "HLC" else 1.6) * top_pct)
        ax.legend(fontsize=7.5, loc="upper right")
    for ax in bottom:
        for name in QUANTITIES:
            key, scale = (("coverage", 100.0) if ax is bottom[0] else ("half_width_pct", 1.0))
            ax.plot(xs, [scale * r[name][key] for r in season], "-o", color=colors[name],
                    label=QUANTITIES[name].split(" ")[0])
            if not own_zero:
                ax.plot([0], [scale * IMP_ONLY_PUBLISHED[name][key]], "D", color=colors[name],
                        mfc="white")
    if not own_zero:
        for ax in bottom:
            ax.plot([], [], "D", color="0.3", mfc="white", label="IMP fit alone (bench/fit.py)")
    bottom[0].axhline(95.0, color="k", lw=0.8, ls=":", label="nominal 95 %")
    bottom[0].set_ylabel("coverage of the 95 % intervals [%]")
    lowest = min(100.0 * r[n]["coverage"] for r in season for n in QUANTITIES)
    bottom[0].set_ylim(min(50.0, lowest - 5.0), 102)
    bottom[1].set_ylabel("median half-width of the 95 % intervals [%]")
    bottom[1].set_ylim(bottom=0)
    for ax in [*top, *bottom]:
        ax.set_xticks(range(len(ticks)), [zero_label, *labels], fontsize=8)
        ax.set_xlim(-0.5, len(ticks) - 0.5)
        if not own_zero:   # other households: apart from the curve
            ax.axvline(0.5, color="0.6", lw=0.8, ls=":")
        ax.grid(alpha=0.3)
    for ax in top:
        ax.set_xlabel("owner nights")
    for ax in bottom:
        ax.set_xlabel("owner nights (besides the IMP campaign)")
        ax.legend(fontsize=8, loc="lower right" if ax is bottom[0] else "upper right")
    households = max(r.get("households", args["households"]) for r in rows)
    title = (f"The season model on the {args['variant']} plant: {households} simulated "
             f"households, seed {args['seed']}"
             + (f", {args['nights']} nights each" if "nights" in args else "")
             + "\nerror bars: 95 % bootstrap intervals of the median and the P90")
    if not own_zero:
        title += ("; the 0-night point: the IMP fit alone, "
                  f"{IMP_ONLY_PUBLISHED['households']} other households (bench/fit.py)")
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)
    return not own_zero


def _published_point(ax, name: str, color: str) -> None:
    """bench/fit.py's published IMP fit at 0 owner nights: hollow, not joined to the curve
    (other households; no bootstrap intervals were published)."""
    q = IMP_ONLY_PUBLISHED[name]
    ax.plot([0], [q["median_pct"]], "D", color=color, mfc="white",
            label="IMP fit alone (bench/fit.py), median")
    ax.plot([0], [q["p90_pct"]], "v", color=color, mfc="white",
            label="IMP fit alone (bench/fit.py), P90")


def _save(fig, path: str | Path) -> None:
    """Write the PNG beside ``path`` and move it there: a failed draw leaves nothing."""
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".png", dir=target.parent)
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=110, format="png")
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)   # as an ordinary new file, not mkstemp's 0600
        os.replace(tmp, target)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def format_published() -> str:
    """The line a run without its own 0-night point prints about the one drawn instead."""
    p = IMP_ONLY_PUBLISHED
    parts = ", ".join(f"{n} {p[n]['median_pct']:g} %" for n in QUANTITIES)
    return (f"the 0-night point drawn is bench/fit.py's figure of record ({p['command']}: "
            f"{p['households']} other households; median {parts})")

