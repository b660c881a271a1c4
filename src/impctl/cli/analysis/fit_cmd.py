"""``impctl fit``: the night-time Neural-ODE fit of a house's 5R1C parameters.

The command's own process reads the file, runs the season model (in a forked child) and writes
the results; the IMP fit, with torch, runs in a worker forked before the file is read
(:mod:`.fit_worker`). So the CLI (and the daemon) start without torch, and a refused file is
refused without loading it.
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import signal
import threading
import time
from pathlib import Path

import click

from ...atomic import replacing
from ...errors import InputError
from ...fit.household import DEFAULT_MAX_NIGHTS, MAX_NIGHTS_RANGE
from ...imp.gain import NIGHT_GAIN_LIMITS_W, NIGHT_GAIN_SD_W, NIGHT_GAIN_W
from .. import cli
from ..checks import (
    MAX_FILE_MB,
    agreed_emitter,
    bounded,
    emitter_option,
    file_mb,
    house_limit,
    instrument_options,
    time_zone,
)
from .fit_worker import FitRequest, FitWorker, draw_outcome


def _write_json(path: Path, data: dict) -> None:
    # Write beside the target and rename, so a failed run never leaves half a file.
    path.parent.mkdir(parents=True, exist_ok=True)
    with replacing(path, mode=0o600) as tmp, open(tmp, "w") as fh:
        json.dump(data, fh, indent=2, ensure_ascii=False)
        fh.write("\n")


@cli.command("fit")
@click.option("--nights", "nights_path", required=True,
              type=click.Path(dir_okay=False, path_type=Path),
              help="NIGHTS.csv: columns timestamp, t_air, t_out, q_hc; optional setpoint, "
                   "heating, night, kind, p_house_w, occupants, t_rooms_c, t_out_ref_c, "
                   "night_gain_w, defrost, p_el_w.")
@click.option("--model-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Trained range classifiers [default: per-user data dir].")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Write the full result as JSON here.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None,
              help="Draw each night, measured vs fitted: T_air where the heating was off, heat "
                   "power where T_air was held (PNG; a grid of at most four columns).")
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
@instrument_options
@emitter_option
def fit(nights_path: Path, model_dir: Path | None, json_path: Path | None,
        plot_path: Path | None, tz: str, timestamps: str, normal_model: str, ach_infl: float,
        ach_vent: float, max_nights: int, night_gain_w: float | None,
        night_gain_sd_w: float | None, t_air_offset_sd_k: float | None,
        t_out_offset_sd_k: float | None, meter_error: float | None,
        emitter: str | None) -> None:
    """Fit the house's 5R1C parameters to its IMP nights (the paper's step 4).

    Prints the lumped HLC, C_m and τ with 95 % intervals, the seven physical parameters with
    what determines each (the data, or only the class range / physical bounds), and the heat
    demand and T_air validation per night.
    """
    if ach_infl + ach_vent <= 0:
        raise InputError("--ach-infl and --ach-vent must have a positive sum")
    if night_gain_sd_w is not None and night_gain_w is None:
        raise InputError("--night-gain-sd-w is the SD of a declared gain: give --night-gain-w "
                         "too")
    from ...fit.household import FitOptions, choose_nights, household_classes, read_household
    from ...store.export import refuse_database

    refuse_database(json_path, "--json")
    refuse_database(plot_path, "--plot")
    options = FitOptions(normal_model=normal_model, timestamps=timestamps, ach_infl=ach_infl,
                         ach_vent=ach_vent, max_nights=max_nights, night_gain_w=night_gain_w,
                         night_gain_sd_w=night_gain_sd_w, t_air_offset_sd_k=t_air_offset_sd_k,
                         t_out_offset_sd_k=t_out_offset_sd_k, meter_error=meter_error)
    # Loaded once, before the worker forks: pandas and the nights' types (this process reads
    # with them, the worker fits them) and scipy.special (the fit's, and the season model's)
    import scipy.special  # noqa: F401

    from ...imp.files import nights_csv  # noqa: F401

    # torch (the fit) loads in a worker while this process reads the file: a bad file is
    # refused here without waiting for it, and this process never loads it (.fit_worker)
    with FitWorker() as worker:
        # the same path as every household of impctl fleet fit (impctl.fit.household)
        if 1.0 <= file_mb(nights_path) <= MAX_FILE_MB:  # ~25,000 rows: reading takes seconds
            click.echo(f"reading {nights_path} ({file_mb(nights_path):.0f} MB) …", err=True)
        nights = read_household(nights_path, tz)
        chosen = choose_nights(nights, options.max_nights)
        refusal = chosen.too_little(nights_path)
        if refusal is not None:
            raise refusal
        # The season model needs no torch: it runs beside the IMP fit.
        season_job = _SeasonJob(nights, agreed_emitter(emitter, nights, nights_path))
        classes = household_classes(chosen.cut, model_dir)
        notes = [*classes.notes, *([chosen.note] if chosen.note else [])]
        click.echo(f"fitting {len(chosen.chosen)} nights "
                   f"({sum(n.kind == 'constrained' for n in chosen.chosen)} constrained) …",
                   err=True)
        request = FitRequest(chosen.nights, classes.ranges, classes.probabilities,
                             classes.classes, notes, options.estimator_params(),
                             str(nights_path), plot=plot_path is not None)
        with _ticking("fitting"):
            outcome = worker.fit(request)
    from ...fit.result.table import format_table

    summary = outcome.summary
    click.echo(format_table(summary))
    season, season_note = season_job.result()
    if season is not None:
        summary["season"] = season
    elif season_note is not None:
        click.echo(season_note)
    if json_path is not None:
        _write_json(json_path, summary)
        click.echo(f"JSON written to {json_path}")
    if plot_path is not None:
        draw_outcome(outcome, plot_path)
        click.echo(f"plot written to {plot_path}")


class _SeasonJob:
    """The season model of the owner nights and the IMP nights together, computed in a forked
    process while the parent loads torch and fits the IMP nights (two cores: the season's
    seconds vanish from the wall time), or here when there is no fork or the child failed.

    The child imports the season model itself (scipy's optimiser and filters, a second and a
    half) and sends back what is printed and written — the JSON block and the text lines — so
    the parent never imports it unless it has to compute it itself.
    """

    def __init__(self, nights: list, emitter: str | None = None) -> None:
        self._nights, self._emitter = nights, emitter
        self._conn = self._proc = None
        if not any(n.kind == "owner" for n in nights):
            return
        try:
            ctx = multiprocessing.get_context("fork")
        except ValueError:  # no fork on this platform
            return
        parent, child = ctx.Pipe(duplex=False)
        # daemon: the child dies with the command (Ctrl-C, an error in the IMP fit)
        self._proc = ctx.Process(target=_season_child, args=(nights, emitter, child),
                                 daemon=True)
        self._proc.start()
        child.close()
        self._conn = parent

    def result(self) -> tuple[dict | None, str | None]:
        """(the season fit's JSON block or None, a note or None), the fit printed."""
        if not any(n.kind == "owner" for n in self._nights):
            return None, None
        out = None
        with _ticking("the season model"):
            if self._conn is not None:
                try:
                    out = self._conn.recv()
                except (EOFError, OSError):  # the child died: computed here below
                    pass
                self._proc.join()
            if out is None:
                out = _season(self._nights, self._emitter)
        block, note, lines = out
        if lines:
            click.echo("\n".join(lines))
        return block, note


def _season(nights: list, emitter: str | None) -> tuple[dict | None, str | None, list[str]]:
    """(the season fit's JSON block with its convergence, or None; a note or None; the text
    lines printed for it); ``emitter``: declared (``--emitter``), or None."""
    from ...season.convergence import convergence, format_convergence
    from ...season.fit import fit_nights
    from ...season.result import format_season

    season, note = fit_nights(nights, emitter=emitter)
    if season is None:
        return None, note, []
    curve = convergence(nights, season)
    season.convergence = curve
    return season.as_dict(), note, format_season(season) + format_convergence(curve)


def _season_child(nights: list, emitter: str | None, conn) -> None:
    # Ctrl-C reaches the whole process group: the command ends the child (a daemon) itself
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        conn.send(_season(nights, emitter))
    except Exception:  # noqa: BLE001 - the parent computes it again and sees the error itself
        conn.send(None)
    finally:
        conn.close()


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
