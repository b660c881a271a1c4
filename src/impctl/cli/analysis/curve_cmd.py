"""``impctl curve``: the heating curve this house needs, against the one its heat pump runs.

No torch: pandas, scipy and (for ``--plot``) matplotlib, imported inside the command.
"""

from __future__ import annotations

from pathlib import Path

import click

from ...errors import InputError
from .. import cli
from ..checks import SETPOINT_C, bounded, time_zone
from .fit_cmd import _write_json

#: The margin a curve may be given [K]: 0 (the bound itself) to 5 K.
MARGIN_K = (0.0, 5.0)


@cli.command("curve")
@click.option("--nights", "nights_path", required=True,
              type=click.Path(dir_okay=False, path_type=Path),
              help="NIGHTS.csv with the heating nights: timestamp, t_air, t_out, q_hc and the "
                   "flow and return temperatures t_flow_c, t_return_c; optional "
                   "t_flow_target_c (the heat pump's curve), p_el_w, dhw, defrost, setpoint, "
                   "heating, kind (owner, normal, constrained).")
@click.option("--fit", "fit_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="The house's `impctl fit --json` result: its heat loss and "
                                 "night gain. Without it the heat loss is read from the "
                                 "owner's nights (needs a spread of outdoor temperatures).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Write the result as JSON (impctl-curve/1) here.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="Draw the curves (PNG).")
@click.option("--margin-k", default=None, type=float, callback=bounded(MARGIN_K, "K"),
              help="Kelvin of flow temperature kept above the bound of what the house needs "
                   "[default: 1].")
@click.option("--setpoint-c", default=None, type=float, callback=bounded(SETPOINT_C, "°C"),
              help="The room temperature the curve must hold [°C] (default: the owner's "
                   "nights' setpoint, else 21 °C, said so).")
@click.option("--tz", default="Europe/Ljubljana", show_default=True, callback=time_zone,
              help="Time zone of naive timestamps and of the nights (22:00–06:00).")
def curve_cmd(nights_path: Path, fit_path: Path | None, json_path: Path | None,
              plot_path: Path | None, margin_k: float | None, setpoint_c: float | None,
              tz: str) -> None:
    """The heating curve this house needs, what its heat pump runs, and what lowering it saves.

    From the nights with the heating on: the radiators' or floor's heat output against the
    water temperature (measured), the heat the house needs at each outdoor temperature (the
    fit's heat loss, anchored on the heat the nights show), the lowest flow temperature that
    keeps the room at its setpoint with the margin, as a straight heating curve (two points,
    at −15 and +15 °C outside), against the curve the heat pump runs (its own flow target),
    and the electricity the difference makes over a winter.
    """
    from ...curve import DEFAULT_MARGIN_K, analyse, read_rows
    from ...report.fit_json import read_fit_json
    from ...store.export import refuse_database

    refuse_database(json_path, "--json")
    refuse_database(plot_path, "--plot")
    for out in (json_path, plot_path):
        if out is not None and out.resolve() == nights_path.resolve():
            raise InputError("would overwrite the NIGHTS file", out)
    fit = read_fit_json(fit_path) if fit_path is not None else None
    rows = read_rows(nights_path, tz)
    result = analyse(rows, fit, setpoint_c=setpoint_c,
                     margin_k=DEFAULT_MARGIN_K if margin_k is None else margin_k,
                     source=nights_path)
    for line in result.lines():
        click.echo(line)
    data = result.to_dict()
    if json_path is not None:
        _write_json(json_path, data)
        click.echo(f"JSON written to {json_path}")
    if plot_path is not None:
        from ...curve.plot import plot_curve

        plot_curve(data, plot_path)
        click.echo(f"plot written to {plot_path}")
