"""``impctl fleet fit`` (a fleet's nights on Dask → FLEET.parquet) and ``impctl flex``.

Dask, torch and pandas are imported inside the commands only.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from ...errors import InputError
from ...fit.household import DEFAULT_MAX_NIGHTS, MAX_NIGHTS_RANGE
from ...imp.gain import NIGHT_GAIN_LIMITS_W
from .. import cli
from ..checks import FLEX_DROP_K, SETPOINT_C, T_OUT_C, bounded, instrument_options, time_zone


@cli.group("fleet")
def fleet() -> None:
    """Fit a whole fleet of households (aggregators), on a Dask cluster."""


@fleet.command("fit")
@click.argument("input_path", metavar="INPUT", type=click.Path(path_type=Path))
@click.option("--out", required=True, type=click.Path(path_type=Path),
              help="FLEET.parquet: a Parquet dataset folder, one row per household.")
@click.option("--model-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Trained range classifiers [default: per-user data dir; without any, the "
                   "whole prior ranges].")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="An existing Dask scheduler, e.g. tcp://HOST:8786 [default: a local "
                   "cluster of worker processes on this machine].")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Worker processes of the local cluster [default: one per core].")
@click.option("--tz", default="Europe/Ljubljana", show_default=True, callback=time_zone,
              help="Time zone of naive timestamps and of the 22:00–05:00 windows.")
@click.option("--timestamps", type=click.Choice(["instant", "interval"]), default="instant",
              show_default=True, help="Sample convention, as for impctl fit.")
@click.option("--max-nights", default=DEFAULT_MAX_NIGHTS, show_default=True, type=int,
              callback=bounded(MAX_NIGHTS_RANGE),
              help="Fit at most this many nights per household, as impctl fit does "
                   f"({MAX_NIGHTS_RANGE[0]}–{MAX_NIGHTS_RANGE[1]}).")
@click.option("--resume", is_flag=True,
              help="Continue an interrupted run: skip households already in --out (same "
                   "INPUT and options).")
@click.option("--previous", type=click.Path(path_type=Path), default=None,
              help="The last run's FLEET.parquet: a household whose IMP nights are unchanged "
                   "(same options and impctl version) keeps its IMP fit from there, and its "
                   "season model starts where that run's ended — a morning's run costs a "
                   "fraction of a full one.")
@click.option("--report", "report_dir", type=click.Path(file_okay=False, path_type=Path),
              default=None, help="Also write the fleet report (HTML + PNG) into this folder.")
@click.option("--batch-size", type=click.IntRange(min=1), default=64, show_default=True,
              help="Households fitted together in one batched optimiser call (one Dask "
                   "task); a fleet smaller than two batches per worker is cut finer.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option("--night-gain-w", default=None, type=float,
              callback=bounded(NIGHT_GAIN_LIMITS_W, "W"),
              help="A night gain declared for every household [W], as for impctl fit. Not "
                   "given: a household's own night_gain_w column declares it, else its "
                   "p_house_w/occupants columns measure it, else it is estimated or assumed "
                   "(the row's night_gain_source says which).")
@click.option("--night-gain-sd-w", default=None, type=float,
              callback=bounded(NIGHT_GAIN_LIMITS_W, "W"),
              help="SD of the declared night gain [W] (default 0: known exactly).")
@instrument_options
def fleet_fit(input_path: Path, out: Path, model_dir: Path | None, scheduler: str | None,
              workers: int | None, tz: str, timestamps: str, max_nights: int, resume: bool,
              previous: Path | None, report_dir: Path | None, batch_size: int, quiet: bool,
              night_gain_w: float | None, night_gain_sd_w: float | None,
              t_air_offset_sd_k: float | None, t_out_offset_sd_k: float | None,
              meter_error: float | None) -> None:
    """Fit every household's nights in INPUT; one row per household into --out.

    INPUT: a folder of NIGHTS files (*.csv, *.parquet; household id = file stem), or one
    Parquet file / dataset with a 'household' column plus the NIGHTS columns. Each household
    is read, checked and fitted as impctl fit takes its file, with the same numbers; one that
    impctl fit would refuse (too large, implausible units or fit) or that cannot be fitted
    (unreadable, too few nights, failed fit) gets a row saying why. --out (outside INPUT)
    keeps a manifest: an interrupted run is marked partial.
    """
    from ...fit.household import FitOptions
    from ...fleet.run import check_places, fit_fleet

    if night_gain_sd_w is not None and night_gain_w is None:
        raise InputError("--night-gain-sd-w is the SD of a declared gain: give --night-gain-w "
                         "too")
    check_places(input_path, out, report_dir)
    options = FitOptions(timestamps=timestamps, max_nights=max_nights, night_gain_w=night_gain_w,
                         night_gain_sd_w=night_gain_sd_w, t_air_offset_sd_k=t_air_offset_sd_k,
                         t_out_offset_sd_k=t_out_offset_sd_k, meter_error=meter_error)
    run = fit_fleet(input_path, out, model_dir=model_dir, scheduler=scheduler, workers=workers,
                    tz=tz, options=options, resume=resume, previous=previous,
                    batch_size=batch_size,
                    progress=not quiet, echo=click.echo)
    rate = run.fitted / run.wall_s if run.wall_s > 0 else 0.0
    c = run.counts
    reused = (f", {run.reused} with their IMP fit from --previous ({run.unchanged} with no new "
              "night: the whole row)" if previous else "")
    click.echo(f"{run.found} households: {run.fitted} fitted now ({c['ok']} ok, "
               f"{c['insufficient']} insufficient, {c['error']} error{reused}), {run.skipped} "
               f"already in {out}; {run.wall_s:.1f} s wall, {rate:.2f} households/s on "
               f"{run.workers} workers")
    if run.changed:
        click.echo(f"{run.changed} households' heat loss changed during their season (FLEET "
                   "columns season_changed_since, season_change_w_per_k)")
    if report_dir is not None:
        from ...report.fleet import write_fleet_report

        page = write_fleet_report(out, report_dir)
        click.echo(f"report written to {page}")


@cli.command("flex")
@click.argument("source", type=click.Path(dir_okay=True, path_type=Path))
@click.option("--household", "households", multiple=True,
              help="With a FLEET.parquet SOURCE: these households [default: all fitted].")
@click.option("--t-set", "t_set_c", default=21.0, show_default=True, type=float,
              callback=bounded(SETPOINT_C, "°C"),
              help=f"Indoor setpoint of the steady state [°C]; {SETPOINT_C[0]:g}–"
                   f"{SETPOINT_C[1]:g}.")
@click.option("--t-out", "t_out_c", default=0.0, show_default=True, type=float,
              callback=bounded(T_OUT_C, "°C"),
              help=f"Outdoor temperature, held [°C]; {T_OUT_C[0]:g}–{T_OUT_C[1]:g}.")
@click.option("--drop", "drop_k", default=1.0, show_default=True, type=float,
              callback=bounded(FLEX_DROP_K, "K", low_open=True),
              help=f"T_air drop that ends the coast [K]; above 0, at most {FLEX_DROP_K[1]:g}.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
def flex(source: Path, households: tuple[str, ...], t_set_c: float, t_out_c: float,
         drop_k: float, as_json: bool) -> None:
    """How long a fitted house can coast with the heating off, and the heat it needs after.

    SOURCE: an impctl fit JSON, or a FLEET.parquet of impctl fleet fit. From steady state at
    --t-set and --t-out, heating off: coast_h = hours until T_air has fallen by --drop;
    rebound_kwh = heat beyond steady-state demand in the 2 h after heating resumes. Computed
    with the fitted 5R1C plus the switch-off terms the fit kept (emitter release,
    air/furniture, night gain; without them the 5R1C's instantaneous switch-off drop is not
    counted); the interval from τ's, those terms' and the model structure's uncertainty
    (impctl.flex).
    """
    conditions = {"t_set_c": t_set_c, "t_out_c": t_out_c, "drop_k": drop_k}
    if source.suffix == ".json" and source.is_file():
        if households:
            raise InputError("--household applies to a FLEET.parquet source", source)
        from ...flex import flexibility_of_fit

        try:
            summary = json.loads(source.read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"not a readable fit JSON ({exc})", source) from None
        if not isinstance(summary, dict):
            raise InputError("not an impctl fit result", source)
        try:
            results = {source.stem: flexibility_of_fit(summary, **conditions)}
        except InputError as exc:
            raise exc.at(source) from None
    else:
        from ...fleet.results.flex_rows import fleet_flexibility
        from ...fleet.results.manifest import completeness

        results = fleet_flexibility(source, list(households), **conditions)
        partial = completeness(source)
        if partial:  # said where it is read: on stderr beside JSON, first in the table
            click.echo(f"{source}: {partial}", err=as_json)
    if as_json:
        click.echo(json.dumps({k: v.block() for k, v in results.items()}, indent=2))
        return
    click.echo(f"At {t_set_c:g} °C indoors, {t_out_c:g} °C outdoors; coast until T_air has "
               f"fallen {drop_k:g} K, rebound over the 2 h after")
    click.echo(f"  {'household':<20} {'coast_h':>8} {'95 % interval':>15} {'rebound_kwh':>12} "
               f"{'steady_w':>9} {'switch-off drop_k':>18}")
    for name, f in results.items():
        iv = f"{f.coast_h_low:.2f}–{f.coast_h_high:.2f}"
        click.echo(f"  {name:<20} {f.coast_h:>8.2f} {iv:>15} {f.rebound_kwh:>12.2f} "
                   f"{f.steady_state_w:>9.0f} {f.switch_off_drop_k:>18.2f}  {f.coast_method}")
