"""``impctl train`` and ``impctl classify``: the virtual population and the range classifiers.

Heavy modules (scikit-learn, the population) are imported inside the commands, so the CLI and
the daemon start fast.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from ...errors import InputError
from .. import cli
from ..checks import MAX_FILE_MB, refuse_large_file, time_zone

#: Fewest households ``impctl train`` accepts: a test split of 20 % must hold every class.
MIN_HOUSEHOLDS = 20


@cli.command()
@click.option("--households", default=900, show_default=True, type=int,
              help="Virtual households to simulate.")
@click.option("--seed", default=0, show_default=True, type=int,
              help="Seed of the households, their weather days, the noise, the split, the forests.")
@click.option("--weather", "weather_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="EPW file or timestamp,t_out CSV [°C]; default: built-in winter.")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Model directory [default: $IMPCTL_MODEL_DIR or the per-user data dir].")
@click.option("--plant", type=click.Choice(["realistic", "iso"]), default="realistic",
              show_default=True,
              help="Virtual households on the realistic plant (emitters, cycling heat pumps, "
                   "gains, sensors; impctl.plant) or the ideal ISO 5R1C.")
def train(households: int, seed: int, weather_path: Path | None, out: Path | None,
          plant: str) -> None:
    """Simulate the IMP on virtual households and train the parameter-range classifiers.

    Writes OUT/models.json, OUT/<parameter>.joblib (the classifiers) and OUT/forests.npz (the
    same forests as checked arrays, read by fit and classify), OUT/dataset/ (Parquet
    and manifest) and OUT/report.txt, OUT/report.json (accuracies vs baselines and the paper's
    Table III), then prints the report.
    """
    from ...classifiers.files.saved import default_model_dir
    from ...population.imp_run.setup import ImpSimConfig, usable_nights
    from ...weather import read_weather

    if households < MIN_HOUSEHOLDS:
        raise InputError(f"--households must be >= {MIN_HOUSEHOLDS}, got {households}")
    imp = ImpSimConfig.for_plant(plant)  # the nights the gateway records on that plant
    weather = None
    if weather_path is not None:
        weather = read_weather(weather_path, imp.tz)
        found = len(usable_nights(weather, imp))
        if found < imp.days:
            raise InputError(
                f"only {found} usable nights (22:00–05:00 with {imp.spinup_days:g} days of data "
                f"before, mean T_out < {imp.max_t_out_c:g} °C); {imp.days} are needed",
                weather_path)
    out = out if out is not None else default_model_dir()
    if out.exists() and not out.is_dir():
        raise InputError("--out must be a directory", out)
    # scikit-learn and the population's modules only now: a bad input is refused in a moment
    from ...classifiers.files.saved import save_models
    from ...classifiers.report import format_report
    from ...classifiers.training import TrainConfig, train_classifiers
    from ...population.dataset import generate_dataset

    with click.progressbar(length=households, label="simulating households",
                           file=sys.stderr) as bar:
        dataset = generate_dataset(households, seed, weather=weather, weather_path=weather_path,
                                   imp=imp, progress=bar.update, plant=plant)
    cfg = TrainConfig()
    n_forests = 2 * len(dataset.manifest["ranges"])
    with click.progressbar(length=n_forests, label="training classifiers",
                           file=sys.stderr) as bar:
        models, reports = train_classifiers(dataset, cfg, seed, progress=bar.update)
    report_json = {name: r.as_dict() for name, r in reports.items()}
    dataset.save(out / "dataset")
    save_models(models, out, seed=seed, n_households=households,
                emission_lag_h=imp.emitter_lag_h, report=report_json,
                dataset_manifest=dataset.manifest)
    text = format_report(reports, small=cfg.small_campaign)
    (out / "report.txt").write_text(text)
    (out / "report.json").write_text(json.dumps(report_json, indent=2) + "\n")
    from ...classifiers.report import reliability_figure

    reliability_figure(reports, out / "reliability.png")
    click.echo(text)
    click.echo(f"models, dataset and report written to {out}")


@cli.command()
@click.option("--nights", "nights_path", required=True,
              type=click.Path(dir_okay=False, path_type=Path),
              help="NIGHTS.csv: timestamp,t_air,t_out,q_hc[,setpoint,heating,night,kind].")
@click.option("--model-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Where `impctl train` wrote the models [default: per-user data dir].")
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
@click.option("--tz", default="Europe/Ljubljana", show_default=True, callback=time_zone,
              help="Time zone of naive timestamps and of the 22:00–05:00 windows.")
def classify(nights_path: Path, model_dir: Path | None, as_json: bool, tz: str) -> None:
    """Put a house into floor-area, heat-capacity and wall-U ranges from its IMP nights."""
    from ...classifiers.files.saved import classify_nights
    from ...imp import read_nights
    from ...imp.gaps import cut_at_gaps
    from ...imp.night import split_owner
    from ...imp.plausibility import check_units
    from ...population.ranges import UNITS

    refuse_large_file(nights_path, MAX_FILE_MB)
    nights, owner_note = split_owner(read_nights(nights_path, tz))
    if owner_note is not None:
        click.echo(owner_note, err=True)
    check_units(nights, nights_path)
    nights, gaps = cut_at_gaps(nights)
    results = classify_nights(nights, model_dir)
    kinds = {k: sum(n.kind == k for n in nights) for k in ("constrained", "normal")}
    if as_json:
        click.echo(json.dumps({
            "classes": {name: r.as_dict() for name, r in results.items()},
            "nights": {**kinds, "ids": [n.night_id for n in nights]},
            "gaps": [g.as_dict() for g in gaps],
        }, indent=2))
        return
    for g in gaps:
        click.echo(f"gap: {g.describe()}")
    click.echo(f"{len(nights)} nights: {kinds['constrained']} constrained, "
               f"{kinds['normal']} normal")
    left_out = next((r.nights_left_out for r in results.values() if r.nights_left_out), ())
    if left_out:
        click.echo(f"left out (setpoint the classifiers were never trained on): "
                   f"{'; '.join(left_out)}")
    click.echo(f"{'parameter':<12}{'range':>16}  {'unit':<13}probability")
    for name, r in results.items():
        rng = f"{r.range[0]:g} – {r.range[1]:g}"
        click.echo(f"{name:<12}{rng:>16}  {UNITS.get(name, ''):<13}{r.probability_text()}")
