"""``impctl campaign next``: the predicted precision after each possible next night.

The daemon runs it as a subprocess after each fit and hands the JSON to
:func:`impctl.campaign.decide`; numpy and pandas are imported inside the command only.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import click

from ...errors import InputError
from ...imp.protocol import (
    DEFAULT_BAND_K,
    DEFAULT_CONSTRAINED_SETPOINT_C,
    DEFAULT_PREHEAT_H,
    DEFAULT_SETPOINTS_C,
)
from ...numtext import non_ascii_problem, parse_float
from .. import cli
from ..checks import MAX_FILE_MB, SETPOINT_C, T_OUT_C, in_range, refuse_large_file, time_zone


@cli.group("campaign")
def campaign() -> None:
    """The adaptive campaign: which night teaches the fit the most."""


def _setpoints(ctx: click.Context, param: click.Parameter, value: str) -> list[float]:
    place = max(param.opts, key=len)
    out = []
    for part in value.split(","):
        try:
            sp = parse_float(part)
        except ValueError as exc:
            why = non_ascii_problem(part) and str(exc)
            raise InputError(why or f"{part.strip()!r} is not a number (a comma-separated list "
                             "of °C, e.g. 21,22,23)", place=place) from None
        out.append(in_range(sp, SETPOINT_C, place, "°C"))
    return out


def _setpoint(ctx: click.Context, param: click.Parameter, value: float) -> float:
    return in_range(value, SETPOINT_C, max(param.opts, key=len), "°C")


def _read_fit(path: Path) -> dict:
    try:
        result = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("no such file", path) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a readable JSON file ({exc})", path) from None
    if not isinstance(result, dict) or result.get("schema") != "impctl-fit/1":
        raise InputError("not the JSON of `impctl fit --json` (schema impctl-fit/1 expected)",
                         path)
    for key in ("parameters", "lumped", "predictions", "per_night"):
        if not result.get(key):
            raise InputError(f"the fit result has no '{key}'", path, f"key '{key}'")
    for name in ("hlc", "tau"):
        q = result["lumped"].get(name) or {}
        if not all(isinstance(q.get(k), (int, float)) and math.isfinite(q[k]) and q[k] > 0
                   for k in ("value", "low", "high")):
            raise InputError(f"lumped {name} has no finite positive value and interval",
                             path, f"key 'lumped.{name}'")
    return result


@campaign.command("next")
@click.option("--fit", "fit_path", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="FIT.json written by `impctl fit --json` after the last valid night.")
@click.option("--nights", "nights_path", required=True,
              type=click.Path(dir_okay=False, path_type=Path),
              help="NIGHTS.csv the fit used (its sample step is the next night's).")
@click.option("--forecast-t-out-c", required=True, type=float,
              help="The next night's mean outdoor temperature [°C].")
@click.option("--constrained-setpoint-c", default=DEFAULT_CONSTRAINED_SETPOINT_C,
              show_default=True, type=float,
              callback=_setpoint, help="T_set of a constrained night [°C].")
@click.option("--normal-setpoints-c", default=",".join(f"{x:g}" for x in DEFAULT_SETPOINTS_C),
              show_default=True,
              callback=_setpoints, help="T_set of the normal nights, comma-separated [°C].")
@click.option("--comfort-band-k", default=DEFAULT_BAND_K, show_default=True, type=float,
              help="Constrained nights pre-heat to T_set + band and end at T_set − band [K].")
@click.option("--preheat-h", default=DEFAULT_PREHEAT_H, show_default=True, type=float,
              help="Pre-heat before a constrained night [h].")
@click.option("--window-h", default=7.0, show_default=True, type=float,
              help="Length of the night window [h].")
@click.option("--tz", default="Europe/Ljubljana", show_default=True, callback=time_zone,
              help="Time zone of naive timestamps in NIGHTS.csv.")
@click.option("--json", "json_path", required=True,
              type=click.Path(dir_okay=False, path_type=Path), help="Write the candidates here.")
def next_night(fit_path: Path, nights_path: Path, forecast_t_out_c: float,
               constrained_setpoint_c: float, normal_setpoints_c: list[float],
               comfort_band_k: float, preheat_h: float, window_h: float, tz: str,
               json_path: Path) -> None:
    """Predict the 95 % half-widths of HLC and τ after each possible next night.

    Writes {"forecast_t_out_c", "candidates": [{"kind", "setpoint_c", "hlc_rel_pred",
    "tau_rel_pred"}], "outlook": {"nights", "hlc_rel_pred", "tau_rel_pred", "hlc_floor_rel",
    "tau_floor_rel"}} (criterion: module impctl.campaign.design, README "Adaptive campaign").
    """
    import numpy as np

    from ...campaign.design import Protocol, predict
    from ...imp import read_nights
    from ...imp.night import split_owner
    from ...store.export import refuse_database
    from .fit_cmd import _write_json

    in_range(forecast_t_out_c, T_OUT_C, "--forecast-t-out-c", "°C")
    in_range(comfort_band_k, (0.0, 5.0), "--comfort-band-k", "K", low_open=True)
    in_range(preheat_h, (0.0, 12.0), "--preheat-h", "h")
    in_range(window_h, (1.0, 16.0), "--window-h", "h")
    refuse_database(json_path, "--json")
    refuse_large_file(nights_path, MAX_FILE_MB)
    result = _read_fit(fit_path)
    nights, owner_note = split_owner(read_nights(nights_path, tz))
    if owner_note is not None:
        click.echo(owner_note, err=True)
    steps = np.concatenate([np.diff(np.asarray(n.time_s, float)) for n in nights]
                           ) if nights else np.array([])
    steps = steps[steps > 0]
    if not len(steps):
        raise InputError("no night with two or more samples: the sample step is unknown",
                         nights_path)
    step_s = float(np.median(steps))
    protocol = Protocol(window_h=window_h, preheat_h=preheat_h, band_k=comfort_band_k,
                        emission_lag_h=float(result.get("fit", {}).get("emission_lag_h", 1.0)),
                        day_setpoint_c=constrained_setpoint_c)
    try:
        candidates, outlook = predict(result, forecast_t_out_c,
                                      constrained_setpoint_c=constrained_setpoint_c,
                                      normal_setpoints_c=normal_setpoints_c, step_s=step_s,
                                      protocol=protocol)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"the fit result cannot be simulated ({exc})", fit_path) from None
    out = {"forecast_t_out_c": forecast_t_out_c, "sample_step_s": step_s,
           "candidates": [{"kind": c.kind, "setpoint_c": c.setpoint_c,
                           "hlc_rel_pred": _finite(c.hlc_rel_pred),
                           "tau_rel_pred": _finite(c.tau_rel_pred)} for c in candidates],
           "outlook": {"nights": outlook.nights,
                       "hlc_rel_pred": _finite(outlook.hlc_rel_pred),
                       "tau_rel_pred": _finite(outlook.tau_rel_pred),
                       "hlc_floor_rel": _finite(outlook.hlc_floor_rel),
                       "tau_floor_rel": _finite(outlook.tau_floor_rel)}}
    _write_json(json_path, out)
    for c in candidates:
        click.echo(f"{c.kind:<11} {c.setpoint_c:5.1f} °C   HLC ±{c.hlc_rel_pred:6.1%}   "
                   f"τ ±{c.tau_rel_pred:6.1%}")
    click.echo(f"after {outlook.nights} more nights: HLC ±{outlook.hlc_rel_pred:6.1%}   "
               f"τ ±{outlook.tau_rel_pred:6.1%}   (floor: sensors, meter, model: HLC "
               f"±{outlook.hlc_floor_rel:.1%}, τ ±{outlook.tau_floor_rel:.1%})")
    click.echo(f"JSON written to {json_path}")


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None
