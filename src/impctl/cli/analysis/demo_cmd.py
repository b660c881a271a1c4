"""``impctl demo`` and ``impctl report``."""

from __future__ import annotations

from pathlib import Path

import click

from ...errors import InputError
from ...numtext import non_ascii_problem, parse_float, parse_int
from .. import cli


def _nights(text: str) -> tuple[int, int]:
    try:
        c, n = (parse_int(x) for x in text.split("+"))
    except ValueError:
        raise InputError(non_ascii_problem(text)
                         or f"expected CONSTRAINED+NORMAL such as 2+6, got {text!r}",
                         place="--nights") from None
    if c < 1 or n < 1:
        raise InputError("a campaign needs at least one night of each kind", place="--nights")
    return c, n


@cli.command("demo")
@click.option("--house", "house_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Demo your own virtual house (house TOML).")
@click.option("--nights", default=None,
              help="Constrained + normal nights of the fixed campaign [default: 2+6].")
@click.option("--adaptive", is_flag=True,
              help="The adaptive campaign instead: a fit after every night, the next night "
                   "chosen by expected information, a stop at the target (--target) or at "
                   "--max-nights.")
@click.option("--max-nights", type=click.IntRange(2, 30), default=5, show_default=True,
              help="--adaptive: nights run at most.")
@click.option("--target", default="0.05,0.08", show_default=True,
              help="--adaptive: HLC,τ 95 % interval half-widths relative to the estimates.")
@click.option("--owner-days", "owner_days", default="2+3", show_default=True,
              help="Days of the owner's own heating the daemon records (read-only) before "
                   "the campaign + after it; exported with the nights as kind owner. Each "
                   "simulated day costs about a second of wall time.")
@click.option("--speed", type=float, default=None,
              help="Simulated seconds per second of the event loop's virtual time: how the "
                   "daemon's real-time pauses (Modbus timeouts, retry delays) scale into "
                   "simulated time. Simulated time advances only when the simulator and the "
                   "daemon wait, so the results do not depend on the machine's load [default: "
                   "10000 on the realistic plant, 20000 on the ideal one].")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path),
              default=Path("impctl-demo"), show_default=True, help="Output directory.")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed of the weather and of the classifier training.")
@click.option("--model-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Classifier cache; models trained for another plant are named and "
                   "retrained [default: the per-user data dir; models-iso beside it for "
                   "--plant iso].")
@click.option("--households", type=int, default=900, show_default=True,
              help="Virtual households for training when no cached models fit.")
@click.option("--plant", type=click.Choice(["realistic", "iso"]), default="realistic",
              show_default=True,
              help="realistic: air/furniture capacity, radiators, a cycling weather-compensated "
                   "heat pump, gains, sensors (the house file's [plant.*] tables); iso: the "
                   "ideal 5R1C the fit assumes.")
def demo_command(house_path, nights, adaptive, max_nights, target, owner_days, speed, out,
                 seed, model_dir, households, plant) -> None:
    """Run the whole product against a simulated heat pump and write the report.

    Simulator (Modbus TCP on loopback) → the daemon's IMP campaign on simulated time →
    classifiers (trained or cached) → Neural-ODE fit → report and a truth-vs-estimate table.
    The same seed gives the same nights and numbers on any machine, busy or not: simulated
    time advances only when the simulator and the daemon wait. A campaign that cannot finish
    exits with status 1 and says why.
    """
    from ...demo import DemoError, DemoOptions, run_demo

    if speed is not None and not 0 < speed <= 30000:  # NaN too
        raise InputError("must lie in (0, 30000] (the daemon's Modbus timeouts, a second, "
                         "must stay short in simulated time)", place="--speed")
    if adaptive and nights is not None:
        raise InputError("is a fixed campaign; --adaptive chooses its nights (use --max-nights)",
                         place="--nights")
    c, n = _nights(nights or "2+6")
    before, after = _owner_days(owner_days)
    options = DemoOptions(out=out, house_path=house_path, constrained_nights=c,
                          normal_nights=n, speed=speed, seed=seed, model_dir=model_dir,
                          households=households, plant=plant, adaptive=adaptive,
                          max_nights=max_nights, target_rel=_target(target),
                          owner_days_before=before, owner_days_after=after)
    try:
        run_demo(options, echo=click.echo)
    except DemoError as exc:  # one line and exit status 1, never a traceback
        raise click.ClickException(f"demo: {exc}") from None


#: Owner days before and after the campaign, each at most (the demo's weather covers about
#: six days before its start and a month after).
OWNER_DAYS_MAX = (6, 21)


def _owner_days(text: str) -> tuple[int, int]:
    try:
        before, after = (parse_int(x) for x in text.split("+"))
    except ValueError:
        raise InputError(non_ascii_problem(text)
                         or f"expected BEFORE+AFTER such as 2+3, got {text!r}",
                         place="--owner-days") from None
    if not (0 <= before <= OWNER_DAYS_MAX[0] and 0 <= after <= OWNER_DAYS_MAX[1]):
        raise InputError(f"days before must lie in 0–{OWNER_DAYS_MAX[0]}, after in "
                         f"0–{OWNER_DAYS_MAX[1]} (the demo's weather), got {text!r}",
                         place="--owner-days")
    return before, after


def _target(text: str) -> tuple[float, float]:
    try:
        hlc, tau = (parse_float(x) for x in text.split(","))
    except ValueError:
        raise InputError(non_ascii_problem(text)
                         or f"expected HLC,TAU such as 0.05,0.08, got {text!r}",
                         place="--target") from None
    if not (0 < hlc < 1 and 0 < tau < 1):
        raise InputError("relative half-widths must lie in (0, 1), e.g. 0.05,0.08",
                         place="--target")
    return hlc, tau


@cli.command("report")
@click.option("--config", "config_path", type=click.Path(path_type=Path),
              default="/etc/impctl/config.toml", show_default=True,
              help="Daemon configuration: where the store is (state_dir) and the time zone of "
                   "the tables. Not read when --db is given.")
@click.option("--db", "db_path", type=click.Path(path_type=Path), default=None,
              help="Store file (default: impctl.db in the config's state_dir).")
@click.option("--fit", "fit_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="A fit JSON from `impctl fit --json` (default: the newest "
                                 "fit in the store).")
@click.option("--curve", "curve_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="An `impctl curve --json` result (default: the one the "
                                 "daemon keeps beside the store, if any).")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path),
              default=Path("impctl-report"), show_default=True,
              help="Output directory for report.html and its fig_*.png figures; created if "
                   "missing (its parent must exist). Files are written only when the whole "
                   "report succeeded.")
def report_command(config_path, db_path, fit_path, curve_path, out) -> None:
    """Write the HTML report with its PNG figures for a campaign.

    Reads the nights from the store (--db, or the store of --config) and the fit from --fit or
    the store; writes OUT/report.html and OUT/fig_nights.png, fig_heat_demand.png,
    fig_classes.png, fig_parameters.png (and, with a heating curve, its section and
    fig_curve.png).
    """
    from ...report import write_report
    from ...report.curve import read_curve_json
    from ...report.fit_json import read_fit_json

    tz = "Europe/Ljubljana"
    fit = read_fit_json(fit_path) if fit_path is not None else None
    curve = read_curve_json(curve_path) if curve_path is not None else None
    if db_path is None:
        from ...config import load_config

        cfg = load_config(config_path)
        db_path, tz = cfg.db_path, cfg.timezone
    page = write_report(db_path, out, fit=fit, tz=tz, curve=curve)
    click.echo(f"report: {page}")
