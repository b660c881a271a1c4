"""``impctl season``: the season model alone — HLC, τ and C_m from every recorded night.

No torch and no classifiers: the IMP fit is ``impctl fit``'s. This is the daemon's morning
refit (a new owner night, the search started where the last fit ended) and the quick look at
a season's record.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import click

from ...errors import InputError
from .. import cli
from ..checks import agreed_emitter, emitter_option, time_zone
from .fit_cmd import _write_json


@cli.command("season")
@click.option("--nights", "nights_path", required=True,
              type=click.Path(dir_okay=False, path_type=Path),
              help="NIGHTS.csv with owner nights (kind=owner) and, if any, IMP nights: "
                   "timestamp, t_air, t_out, q_hc, kind; optional as for impctl fit.")
@click.option("--warm-start", "warm_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None,
              help="An earlier `impctl fit --json` or `impctl season --json` result of the same "
                   "house: the search starts only where its season model ended (a fraction of "
                   "a full search; a result without one is refused, one of an earlier "
                   "version of the model starts a full search).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Write the result as JSON ({\"season\": …}) here.")
@click.option("--convergence/--no-convergence", default=True, show_default=True,
              help="Refit at 7, 14, 28 and 56 owner nights: the estimate against the nights.")
@click.option("--tz", default="Europe/Ljubljana", show_default=True, callback=time_zone,
              help="Time zone of naive timestamps and of the 22:00–05:00 windows.")
@emitter_option
def season(nights_path: Path, warm_path: Path | None, json_path: Path | None,
           convergence: bool, tz: str, emitter: str | None) -> None:
    """Fit the season model to a house's recorded nights: HLC [W/K], τ [h] and C_m with 95 %
    intervals, the energy signature of the same owner nights beside them.
    """
    from ...store.export import refuse_database

    refuse_database(json_path, "--json")
    start, start_bound_s = _warm_start(warm_path) if warm_path is not None else (None, None)
    from ...fit.household import read_household
    from ...season.convergence import convergence as against_nights
    from ...season.convergence import format_convergence
    from ...season.fit import fit_nights
    from ...season.result import format_season

    nights = read_household(nights_path, tz)
    if not any(n.kind == "owner" for n in nights):
        raise InputError("no owner nights (kind=owner): the season model reads the owner's "
                         "own nights", nights_path)
    emitter = agreed_emitter(emitter, nights, nights_path)
    began = time.perf_counter()
    fit, note = fit_nights(nights, start=start, emitter=emitter, start_bound_s=start_bound_s)
    if fit is None:
        raise InputError(note or "the season model was not fitted", nights_path)
    fit_s = time.perf_counter() - began
    curve = against_nights(nights, fit) if convergence else []
    fit.convergence = curve
    curve_s = time.perf_counter() - began - fit_s
    click.echo("\n".join(format_season(fit) + format_convergence(curve)))
    click.echo(f"fitted in {fit_s:.2f} s"
               + (f" (the search started from {warm_path})" if fit.warm_start else
                  f" (a full search: the water read another emitter than {warm_path}'s)"
                  if start is not None else "")
               + (f", against owner nights in {curve_s:.2f} s" if curve else ""))
    if json_path is not None:
        block = fit.as_dict()
        block["search"] = {"warm_start": fit.warm_start, "start_given": start is not None,
                           "time_s": round(fit_s, 3),
                           "convergence_time_s": round(curve_s, 3)}
        _write_json(json_path, {"season": block})
        click.echo(f"JSON written to {json_path}")


def _warm_start(path: Path) -> tuple[tuple[float, ...] | None, float | None]:
    """θ of an earlier result and the bound on the emitter's lag it ended under [s] (None
    where it does not say; refused in one line when it has no θ; (None, None), a full search,
    when it is an earlier version of the model's)."""
    from ...season.result import theta_of

    try:
        result = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a readable JSON result ({exc})", path, "--warm-start") from None
    theta = theta_of(result)
    if theta is None and _earlier_model(result):
        # a result from before an update of the model: a start it cannot use, not bad input
        click.echo(f"{path}: its season model is an earlier version's (season.theta "
                   f"without {', '.join(_missing_theta(result))}): a full search")
        return None, None
    if theta is None:
        raise InputError("no season model to start from (season.theta missing or not "
                         "positive numbers)", path, "--warm-start")
    bound_h = ((result.get("season") or {}).get("emitter") or {}).get("tau_e_max_h")
    bound_ok = isinstance(bound_h, int | float) and math.isfinite(bound_h) and bound_h > 0
    return theta, float(bound_h) * 3600.0 if bound_ok else None


def _missing_theta(result: dict) -> list[str]:
    from ...season.projection.columns import THETA

    return [k for k in THETA if k not in result["season"]["theta"]]


def _earlier_model(result) -> bool:
    """A season.theta of finite positive numbers under names this model does not all have."""
    block = (result.get("season") or {}).get("theta") if isinstance(result, dict) else None
    if not isinstance(block, dict) or not block:
        return False
    ok = all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
             and v > 0 for v in block.values())
    return ok and bool(_missing_theta(result))
