"""``impctl demo`` end to end: classifiers (cached, or trained alongside), the campaign, export
and fit, the report and the summary."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from ..clock import loop as vtime
from ..errors import InputError
from ..store import Store
from .campaign import campaign_summary, run_campaign
from .options import (
    DEFAULT_SPEED,
    DemoError,
    DemoOptions,
    Progress,
    demo_weather,
    fit_night_gain_w,
    house_and_realism,
    plant_summary,
)


def _last_line(text: str) -> str:
    lines = text.strip().splitlines()
    return lines[-1] if lines else "no message"


def _cmd(*args: str) -> list[str]:
    return [sys.executable, "-c", "from impctl.cli import main; main()", *args]


#: What a cached model's population must share with the demo's nights to be reused.
_PROTOCOL_KEYS = ("setpoints_c", "constrained_setpoint_c", "band_k", "preheat_h",
                  "stop_at_t_min")
#: The value of a key a model's manifest predates (populations before branch h14r cooled
#: every constrained night to the window's end).
_PROTOCOL_MISSING = {"stop_at_t_min": False}


def _models_unfit(model_dir: Path, plant: str) -> str | None:
    """Why the classifiers in ``model_dir`` cannot serve a demo on ``plant`` (None: reuse
    them): models are reused only when trained on the population of the plant the demo
    simulates (their dataset manifest's ``plant``), on the nights the gateway runs there
    (decision record 0005, one protocol)."""
    try:
        from ..classifiers.files.saved import load_classifiers
        from ..population.imp_run.setup import ImpSimConfig

        # What `impctl fit` loads: the compact forests (0.1 s), else the pickled ones
        # (scikit-learn's import and unpickling: ~2.7 s of a demo that reuses them).
        _, meta = load_classifiers(model_dir)
    except (InputError, OSError):
        return "no loadable models"
    dataset = meta.get("dataset") or {}
    trained_for = dataset.get("plant")
    if trained_for != plant:
        return (f"they were trained for the {trained_for or 'unrecorded'} plant's population, "
                f"the demo simulates the {plant} plant")
    imp = dataset.get("imp") or {}
    want = ImpSimConfig.for_plant(plant).as_dict()  # `impctl train --plant`'s nights
    if not all(imp.get(k, _PROTOCOL_MISSING.get(k)) == want[k] for k in _PROTOCOL_KEYS):
        return "they were trained on another night protocol"
    return None


def _start_training(opts: DemoOptions, model_dir: Path, progress: Progress):
    """Reuse cached classifiers if compatible, else train in a subprocess (other core)."""
    why = _models_unfit(model_dir, opts.plant)
    if why is None:
        progress.train_state = "cached models reused"
        progress.line(f"classifiers: reusing the compatible models in {model_dir}")
        return None
    if why != "no loadable models":  # never used silently: say why they are replaced
        progress.line(f"classifiers: not reusing the models in {model_dir}: {why}")
    progress.train_state = "training"
    progress.train_t0 = time.perf_counter()
    progress.line(f"classifiers: training on {opts.households} virtual households "
                  f"of the {opts.plant} plant (in a subprocess) → {model_dir}")
    log = open(opts.out / "train.log", "w")  # noqa: SIM115 - closed when the process ends
    return subprocess.Popen(
        _cmd("train", "--households", str(opts.households), "--seed", str(opts.seed),
             "--plant", opts.plant, "--out", str(model_dir)),
        stdout=log, stderr=subprocess.STDOUT, env={**os.environ, "OMP_NUM_THREADS": "1"})


def _wait_training(trainer, opts: DemoOptions, progress: Progress, why: str) -> None:
    if trainer is None:
        return
    progress.line(f"waiting for the classifier training to finish ({why})")
    if trainer.wait() != 0:
        raise DemoError(f"classifier training failed; see {opts.out / 'train.log'}")
    progress.train_state = progress.trainer_done(trainer)


def run_demo(opts: DemoOptions, echo: Callable[[str], None] = print) -> dict:
    """Run the whole demo; returns the summary dict (also written to OUT/summary.json)."""
    # Inputs first: a bad house file or --out must leave nothing behind (not even demo.log).
    if opts.plant not in ("realistic", "iso"):
        raise InputError("must be realistic or iso", place="--plant")
    if opts.speed is None:
        opts = replace(opts, speed=DEFAULT_SPEED[opts.plant])
    house, realism = house_and_realism(opts)
    if opts.out.exists() and not opts.out.is_dir():
        raise InputError("--out must be a directory", opts.out)
    opts.out.mkdir(parents=True, exist_ok=True)
    # The daemon's own log (every write, restore and night verdict) goes to a file; the
    # console shows the demo's progress lines.
    logging.basicConfig(level=logging.INFO, force=True,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
                        handlers=[logging.FileHandler(opts.out / "demo.log", mode="w")])
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    logging.getLogger("apscheduler").setLevel(logging.WARNING)
    plant = plant_summary(opts, realism)
    progress = Progress(echo)
    progress.line(f"plant: {plant['kind']} ({plant['description']})")
    from ..classifiers.files.saved import default_model_dir

    model_dir = Path(opts.model_dir) if opts.model_dir else default_model_dir()
    if not opts.model_dir and opts.plant != "realistic":
        # Beside the default models (the realistic plant's, those `impctl fit` reads by
        # default): an ideal-plant demo never replaces them.
        model_dir = model_dir.with_name(f"{model_dir.name}-{opts.plant}")
    trainer = _start_training(opts, model_dir, progress)
    weather = demo_weather(opts)
    if opts.adaptive:
        # The daemon fits after every night and decides on those fits: with the classifiers.
        opts = replace(opts, model_dir=model_dir)
        _wait_training(trainer, opts, progress, "the adaptive campaign's fits use them")
        trainer = None
    # Simulator and daemon on one virtual-time loop: the clock waits for both (see .campaign).
    started = time.perf_counter()
    db_path = vtime.run(run_campaign(opts, house, progress, trainer, weather, realism))
    progress.timing_s["campaign"] = time.perf_counter() - started
    _wait_training(trainer, opts, progress, "the fit uses them")
    started = time.perf_counter()
    nights_csv = opts.out / "nights.csv"
    fit_json = opts.out / "fit.json"
    progress.line("exporting the valid nights and the owner records"
                  + ("" if opts.adaptive else " and fitting (impctl fit)"))
    export = subprocess.run(_cmd("export", "--db", str(db_path), "--out", str(nights_csv),
                                 "--force"), capture_output=True, text=True)
    if export.returncode != 0:
        raise DemoError("impctl export failed: " + _last_line(export.stderr))
    if opts.adaptive:  # the daemon's last fit, on every valid night, is the result
        with Store(db_path) as store:
            last, decision = store.last_fit(), store.decisions(1)
        if last is None:
            raise DemoError("the adaptive campaign ended without a fit: "
                               + (decision[0].reason if decision else "no decision")
                               + " (see demo.log)")
        result = last[2]
        fit_json.write_text(json.dumps(result, indent=2) + "\n")
    else:
        gain = fit_night_gain_w(opts)
        fit = subprocess.run(_cmd("fit", "--nights", str(nights_csv), "--json", str(fit_json),
                                  "--model-dir", str(model_dir),
                                  *(() if gain is None else ("--night-gain-w", repr(gain)))),
                             capture_output=True, text=True)
        if fit.returncode != 0:
            raise DemoError("impctl fit failed: " + _last_line(fit.stderr))
        result = json.loads(fit_json.read_text())
        with Store(db_path) as store:
            store.add_fit([n.id for n in store.nights(valid=True)], result)
    from ..report.demand import fitted_house, heat_demand_check
    from ..report.summary import demo_summary, format_summary

    with Store(db_path) as store:
        demand = heat_demand_check(fitted_house(result), store, weather)
    progress.timing_s["export_fit"] = time.perf_counter() - started
    summary = demo_summary(house, result, demand, wall_s=time.perf_counter() - progress.t0,
                           train_state=progress.train_state, plant=plant)
    # Wall seconds of the phases: the campaign (simulator + daemon on virtual time), export
    # and fit, the classifier training (in a subprocess, beside the campaign; None: cached).
    summary["timing_s"] = dict(progress.timing_s)
    with Store(db_path) as store:
        summary.update(campaign_summary(store, opts))
    progress.line("writing the report")
    from ..report import write_report

    write_report(db_path, opts.out, truth=house, fit=result, summary=summary, demand=demand)
    (opts.out / "summary.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    echo(format_summary(summary))
    echo(summary["campaign"]["line"])
    echo(summary["owner"]["line"])
    echo(f"report: {opts.out / 'report.html'}")
    return summary
