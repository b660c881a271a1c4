"""``impctl simulate``: run the 5R1C model over a drivers file, or the built-in house.

numpy and pandas are imported inside the command so that other commands (the daemon above
all) start without them.
"""

from __future__ import annotations

from pathlib import Path

import click

from ...errors import InputError
from .. import cli
from ..checks import SETPOINT_C, SIM_DAYS, SIM_STEP_S, T_M_INIT_C, bounded, time_zone

#: impctl.weather.DEFAULT_TZ, repeated here to keep pandas out of the CLI's import.
_DEFAULT_TZ = "Europe/Ljubljana"
#: Most steps of the built-in weather (a year at 10 s; ~0.5 GB of arrays at the limit).
MAX_STEPS = 3_200_000


@cli.command("simulate")
@click.option("--house", "house_path", type=click.Path(path_type=Path),
              help="House TOML (Table I keys). Default: the built-in 150 m² house.")
@click.option("--drivers", "drivers_path", type=click.Path(path_type=Path),
              help="DRIVERS.csv: timestamp,t_out[,setpoint,phi_hc,internal_gains,solar_gains].")
@click.option("--weather", "weather_path", type=click.Path(path_type=Path),
              help="Instead of --drivers: an EPW or timestamp,t_out CSV weather file.")
@click.option("--out", "out_path", type=click.Path(path_type=Path),
              help="OUT.csv: timestamp,t_out,t_air,t_s,t_m,phi_hc (°C, W).")
@click.option("--setpoint", type=float, default=None, callback=bounded(SETPOINT_C, "°C"),
              help="Heating setpoint [°C] when the drivers have no setpoint column (default 21); "
                   "5–35.")
@click.option("--heating-off", "heating_off", default=None,
              help="Daily local window with heating off, e.g. 22:00-05:00.")
@click.option("--t-m-init", "t_m_init", type=float, default=None,
              callback=bounded(T_M_INIT_C, "°C"),
              help="Mass temperature before the first step [°C] "
                   "(default: first setpoint, else 20); −40–60.")
@click.option("--step", type=float, default=None, callback=bounded(SIM_STEP_S, "s"),
              help="Time step [s] (default: from the timestamps); 1–86400.")
@click.option("--days", type=float, default=31.0, show_default=True,
              callback=bounded(SIM_DAYS, "days"),
              help="Length of the built-in weather [days] (no --drivers); 0.1–3660.")
@click.option("--seed", type=int, default=0, show_default=True, help="Built-in weather seed.")
@click.option("--tz", default=_DEFAULT_TZ, show_default=True, callback=time_zone,
              help="Time zone of naive timestamps and of --heating-off.")
def simulate_command(house_path, drivers_path, weather_path, out_path, setpoint, heating_off,
                     t_m_init, step, days, seed, tz) -> None:
    """Simulate a house with the ISO 13790 5R1C model (Annex C, any time step).

    With no arguments: the built-in default house over built-in winter weather (one month,
    hourly, heating at 21 °C), printing a summary.
    """
    import pandas as pd

    from ...drivers import parse_window, read_drivers, run_drivers, summary, write_atomically
    from ...imp.tables import step_seconds
    from ...model import default_house, load_house
    from ...store.export import refuse_database
    from ...weather import read_weather, winter_weather

    refuse_database(out_path, "--out")
    house = load_house(house_path) if house_path else default_house()
    if house_path:
        _check_plant_tables(house_path)
    label = str(house_path) if house_path else "built-in default (150 m², medium)"
    window = parse_window(heating_off) if heating_off else None
    if drivers_path and weather_path:
        raise click.UsageError("give --drivers or --weather, not both")
    if drivers_path:
        table, dt_s = read_drivers(drivers_path, step, tz)
    else:
        if weather_path:
            t_out = read_weather(weather_path, tz=tz)
            data_step = step_seconds(t_out.index, weather_path)
            dt_s = step or data_step or 3600.0
        else:
            dt_s = step or 3600.0
            steps = days * 86400.0 / dt_s
            if not 2 <= steps <= MAX_STEPS:
                raise InputError(f"--days {days:g} at --step {dt_s:g} s gives {steps:.0f} "
                                 f"steps; 2 … {MAX_STEPS:,} are simulated", place="--days")
            t_out = winter_weather(days=days, step_s=dt_s, seed=seed, tz=tz)
        table = pd.DataFrame({"timestamp": t_out.index, "t_out": t_out.to_numpy()})
    has_sp_column = "setpoint" in table
    sp = None if has_sp_column else (21.0 if setpoint is None else setpoint)
    out = run_drivers(house, table, dt_s, sp, window, t_m_init)
    if out_path:
        write_atomically(out, out_path)
    click.echo(summary(house, out, dt_s, label))
    if out_path:
        click.echo(f"wrote {len(out)} rows to {out_path}")


def _check_plant_tables(path: Path) -> None:
    """The house file's ``[plant.*]`` tables checked as everywhere else (a bad one is one line,
    exit 2), and said to be unused here: this command runs the ideal 5R1C model."""
    from ...model import read_toml
    from ...plant.housefile import plant_params_from_mapping

    tables = read_toml(path).get("plant")
    plant_params_from_mapping(tables, path)
    if tables:
        names = ", ".join(f"[plant.{name}]" for name in tables)
        click.echo(f"note: {path}: {names} checked but not used: impctl simulate runs the "
                   "ideal 5R1C model (impctl demo --house runs the realistic plant)", err=True)
