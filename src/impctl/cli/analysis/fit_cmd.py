"""``impctl fit``: the night-time Neural-ODE fit of a house's 5R1C parameters.

torch is imported inside the command only, so the CLI (and the daemon) start without it.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
import threading
import time
from pathlib import Path

import click

from ...errors import InputError
from ...night_gain import NIGHT_GAIN_LIMITS_W, NIGHT_GAIN_SD_W, NIGHT_GAIN_W
from .. import cli
from ..checks import MAX_FILE_MB, bounded, file_mb, house_limit, refuse_large_file, time_zone

#: Nights fitted by default / accepted by --max-nights: the fit's memory and time grow about
#: linearly with the nights (bench/fit_large.py); an IMP campaign has 5–8.
DEFAULT_MAX_NIGHTS = 30
MAX_NIGHTS_RANGE = (2, 120)

_NEEDS = {
    "constrained": "a constrained night (heating off; at least {h:g} h of cooling after the "
                   "{lag:g} h emission lag) — it carries the time constant τ",
    "normal": "a normal night (setpoint held, heat power logged, at least {h:g} h) — it carries "
              "the absolute scale: HLC and C_m",
}


def _write_json(path: Path, data: dict) -> None:
    # Write beside the target and rename, so a failed run never leaves half a file.
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "w") as fh:
            json.dump(data, fh, indent=2, ensure_ascii=False)
            fh.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@cli.command("fit")
@click.option("--nights", "nights_path", required=True,
              type=click.Path(dir_okay=False, path_type=Path),
              help="NIGHTS.csv: timestamp,t_air,t_out,q_hc[,setpoint,heating,night,kind]"
                   "[,p_house_w,occupants,t_rooms_c,t_out_ref_c,night_gain_w].")
@click.option("--model-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Trained range classifiers [default: per-user data dir].")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Write the full result as JSON here.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Draw measured vs fitted T_air and heat power (PNG).")
@click.option("--tz", default="Europe/Ljubljana", show_default=True, callback=time_zone,
              help="Time zone of naive timestamps and of the 22:00–05:00 windows.")
@click.option("--timestamps", type=click.Choice(["instant", "interval"]), default="instant",
              show_default=True,
              help="instant: temperatures are readings, q_hc the mean power until the next "
                   "row; interval: every value is the mean over the interval starting at its "
                   "timestamp.")
@click.option("--normal-model", type=click.Choice(["demand", "series", "mean"]),
              default="demand", show_default=True,
              help="Normal nights: heat power predicted from the held T_air (demand), or the "
                   "paper's eq. 5 driven by the measured power series or its night mean.")
@click.option("--ach-infl", default=0.01, show_default=True, type=float,
              callback=house_limit("ach_infl"),
              help="Fixed infiltration air changes [1/h] (the classifiers' population); "
                   "0–20.")
@click.option("--ach-vent", default=0.0, show_default=True, type=float,
              callback=house_limit("ach_vent"),
              help="Fixed ventilation air changes [1/h]; 0–20.")
@click.option("--max-nights", default=DEFAULT_MAX_NIGHTS, show_default=True, type=int,
              callback=bounded(MAX_NIGHTS_RANGE),
              help="Fit at most this many nights: the most recent ones, a third of them "
                   "constrained (memory and time grow with the nights; "
                   f"{MAX_NIGHTS_RANGE[0]}–{MAX_NIGHTS_RANGE[1]}).")
@click.option("--night-gain-w", default=None, type=float,
              callback=bounded(NIGHT_GAIN_LIMITS_W, "W"),
              help="The house's mean night gain besides the heating [W], declared: known "
                   "(0 for an empty house; ≈ 75 W per sleeper + base load). Not given: "
                   "measured from the nights' p_house_w/occupants columns, else estimated "
                   f"or assumed ({NIGHT_GAIN_W:g} W ± {NIGHT_GAIN_SD_W:.0f}, said so); "
                   f"{NIGHT_GAIN_LIMITS_W[0]:g}–{NIGHT_GAIN_LIMITS_W[1]:g}.")
@click.option("--night-gain-sd-w", default=None, type=float,
              callback=bounded(NIGHT_GAIN_LIMITS_W, "W"),
              help="SD of the declared night gain [W] (default 0: known exactly).")
def fit(nights_path: Path, model_dir: Path | None, json_path: Path | None,
        plot_path: Path | None, tz: str, timestamps: str, normal_model: str, ach_infl: float,
        ach_vent: float, max_nights: int, night_gain_w: float | None,
        night_gain_sd_w: float | None) -> None:
    """Fit the house's 5R1C parameters to its IMP nights (the paper's step 4).

    Prints the lumped HLC, C_m and τ with 95 % intervals, the seven physical parameters with
    what determines each (the data, or only the class range / physical bounds), and the heat
    demand and T_air validation per night.
    """
    from ...fit.estimator import NightFit
    from ...fit.nights.data import prepare_nights
    from ...fit.result.plot import plot_fit
    from ...fit.result.report import fit_to_dict
    from ...fit.result.table import format_table
    from ...imp import EMISSION_LAG_H, read_nights
    from ...imp.gaps import cut_at_gaps
    from ...imp.plausibility import check_units, fit_problem

    if ach_infl + ach_vent <= 0:
        raise InputError("--ach-infl and --ach-vent must have a positive sum")
    if night_gain_sd_w is not None and night_gain_w is None:
        raise InputError("--night-gain-sd-w is the SD of a declared gain: give --night-gain-w "
                         "too")
    from ...store.export import refuse_database

    refuse_database(json_path, "--json")
    refuse_database(plot_path, "--plot")
    refuse_large_file(nights_path, MAX_FILE_MB)
    if file_mb(nights_path) >= 1.0:  # ~25,000 rows: reading takes seconds
        click.echo(f"reading {nights_path} ({file_mb(nights_path):.0f} MB) …", err=True)
    nights = read_nights(nights_path, tz)
    check_units(nights, nights_path)
    estimator = NightFit(normal_model=normal_model, timestamps=timestamps, ach_infl=ach_infl,
                         ach_vent=ach_vent, night_gain_w=night_gain_w,
                         night_gain_sd_w=night_gain_sd_w)
    cut, _ = cut_at_gaps(nights, estimator.emission_lag_h)
    kept, _, skipped = prepare_nights(cut, estimator.emission_lag_h, estimator.min_night_h,
                                      estimator.resume_threshold_w)
    chosen = _most_recent(kept, max_nights)
    if len(chosen) < len(kept):
        ids = {n.night_id for n in chosen}
        nights = [n for n in nights if n.night_id in ids]
        cut = [n for n in cut if n.night_id in ids]
        first, last = chosen[0].night_id, chosen[-1].night_id
        limit_note = (f"{len(kept)} usable nights in the file; the fit uses the {len(chosen)} "
                      f"most recent ({first} … {last}; --max-nights {max_nights})")
    else:
        limit_note = None
    missing = [_NEEDS[k].format(h=estimator.min_night_h, lag=EMISSION_LAG_H)
               for k in ("constrained", "normal") if not any(n.kind == k for n in kept)]
    if missing:
        found = ", ".join(f"{n.night_id} ({n.kind})" for n in nights) or "none"
        why = "; ".join(f"{i}: {r}" for i, r in skipped)
        raise InputError(
            "too little data to fit: missing " + " and ".join(missing)
            + f". Nights found: {found}" + (f"; skipped: {why}" if why else ""), nights_path)

    # the classifiers see the IMP nights only (not an auto-cut night that is neither kind)
    classes, ranges, notes = _classes([n for n in cut if not n.not_held], model_dir)
    if limit_note:
        notes.append(limit_note)
    click.echo(f"fitting {len(chosen)} nights ({sum(n.kind == 'constrained' for n in chosen)} "
               f"constrained) …", err=True)
    probabilities = {n: c["probabilities"] for n, c in classes.items() if c.get("probabilities")}
    from ...fit.prior import with_class_probabilities

    # the population prior mixes the classes by the classifiers' probabilities
    estimator.prior = with_class_probabilities(estimator.prior, probabilities)
    with _ticking("fitting"):
        estimator.fit(nights, ranges)
    summary = fit_to_dict(estimator, classes, notes)
    # A fit no house gives is a unit or column problem: refuse it, write nothing.
    why = fit_problem(summary["lumped"]["hlc"]["value"],
                      (summary["validation"].get("mean") or {}).get("eps_pct"))
    if why is not None:
        raise InputError(why, nights_path)
    click.echo(format_table(summary))
    if json_path is not None:
        _write_json(json_path, summary)
        click.echo(f"JSON written to {json_path}")
    if plot_path is not None:
        plot_fit(estimator, plot_path)
        click.echo(f"plot written to {plot_path}")


@contextlib.contextmanager
def _ticking(what: str, every_s: float = 5.0):
    """A line on stderr every ``every_s`` seconds while the block runs (long fits)."""
    done = threading.Event()
    started = time.monotonic()

    def tick() -> None:
        while not done.wait(every_s):
            click.echo(f"  … {what}, {time.monotonic() - started:.0f} s", err=True)

    thread = threading.Thread(target=tick, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


def _most_recent(kept: list, max_nights: int) -> list:
    """At most ``max_nights`` nights, the most recent; a third of them (at least one)
    constrained when there are enough, the rest normal; in time order."""
    cons = [n for n in kept if n.kind == "constrained"]
    normal = [n for n in kept if n.kind == "normal"]
    n_cons = min(len(cons), max(1, max_nights // 3))
    n_normal = min(len(normal), max_nights - n_cons)
    n_cons = min(len(cons), max_nights - n_normal)
    chosen = cons[len(cons) - n_cons:] + normal[len(normal) - n_normal:]
    return sorted(chosen, key=lambda n: n.start)


def _classes(nights, model_dir):
    """Classified ranges, or — without usable classifiers — the prior, said out loud."""
    from ...classifiers.saved import classify_nights
    from ...population.ranges import DEFAULT_RANGES

    try:
        results = classify_nights(nights, model_dir)
    except InputError as exc:
        classes = {name: {"range": (rs[0][0], rs[-1][1]), "probability": None,
                          "source": "prior"} for name, rs in DEFAULT_RANGES.items()}
        note = (f"no classification ({exc.problem}); floor_area, c_f and u_walls were searched "
                "over their whole prior ranges, so the fit rests on the nights alone")
        return classes, {n: c["range"] for n, c in classes.items()}, [note]
    classes = {name: {"range": r.range, "probability": r.probability, "source": "classifier",
                      "probabilities": dict(r.probabilities), "search_range": r.fit_range}
               for name, r in results.items()}
    left_out = next((r.nights_left_out for r in results.values() if r.nights_left_out), ())
    notes = [f"the classes leave out {len(left_out)} nights run at setpoints the classifiers "
             f"were never trained on: {'; '.join(left_out)} (the fit uses them)"
             ] if left_out else []
    # the fit searches the classes up to SEARCH_LEVEL of probability, not the likeliest alone
    return classes, {n: c["search_range"] for n, c in classes.items()}, notes
