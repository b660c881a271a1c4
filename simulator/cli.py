"""``impctl-sim``: run the simulated Kronoterm heat pump as a Modbus server.

Prints one ``impctl-sim: serving …`` line (with the bound port and the clock spec another process
can pass to ``VirtualClock.from_spec``), then serves until SIGINT/SIGTERM. Bad input prints one
line on stderr and exits with status 2.
"""

from __future__ import annotations

import asyncio
import logging
import signal
import sys
from datetime import UTC, datetime
from pathlib import Path

import click

from impctl.cli.checks import SETPOINT_C, bounded
from impctl.clock import VirtualClock
from impctl.errors import InputError
from impctl.kronoterm.registers import Generation
from impctl.model import default_house
from impctl.weather import read_weather

from .config import SimConfig
from .faults import parse_faults
from .plant import PlantParams
from .realistic import describe_plant
from .server import KronotermSimulator

# Option bounds (one line and exit status 2 outside them, never a traceback).
PORT = (0, 65535)
BAUDRATE = (300, 4_000_000)
SPEED = (0.0, 1e6)                 # simulated s per wall s
WALL_EPOCH_S = (0.0, 1e10)         # POSIX s
SEED = (0, 2**32 - 1)
UNIT_ID = (1, 247)                 # Modbus unit ids
DHW_PERIOD_H = (0.5, 168.0)
NOISE_K = (0.0, 5.0)
T_OUT_C = (-50.0, 40.0)


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--house", type=click.Path(dir_okay=False, path_type=Path),
              help="House TOML (impctl.model.load_house; its optional [plant.*] tables set the "
                   "realistic plant's options); default: the built-in house.")
@click.option("--plant", "plant_kind", type=click.Choice(["realistic", "iso"]),
              default="realistic", show_default=True,
              help="realistic: air/furniture capacity, hydronic emitter, cycling heat pump, "
                   "gains, sensors (impctl.plant); iso: the ideal 5R1C with a 20-min emitter.")
@click.option("--emitter", type=click.Choice(["radiators", "underfloor"]),
              help="Realistic plant: emitter kind (overrides the house file).")
@click.option("--control", type=click.Choice(["curve", "thermostat"]),
              help="Realistic plant: weather curve with room influence, or an on/off room "
                   "thermostat (overrides the house file).")
@click.option("--host", default="127.0.0.1", show_default=True, help="TCP address to bind.")
@click.option("--port", default=5020, show_default=True, type=int, callback=bounded(PORT),
              help="TCP port (0 = free).")
@click.option("--allow-remote", is_flag=True, help="Allow binding to a non-loopback address.")
@click.option("--rtu", metavar="PORT_OR_URL",
              help="Serve Modbus RTU on a serial device or pyserial URL "
                   "(socket://127.0.0.1:PORT = RTU over TCP) instead of Modbus TCP.")
@click.option("--baudrate", default=19200, show_default=True, type=int,
              callback=bounded(BAUDRATE), help="RTU baud rate.")
@click.option("--generation", type=click.Choice([g.value for g in Generation]),
              default="extended", show_default=True, help="Register set exposed.")
@click.option("--speed", default=1.0, show_default=True, type=float,
              callback=bounded(SPEED, low_open=True),
              help="Simulated seconds per wall-clock second. Above 1 the simulation is "
                   "load-sensitive: simulated time runs on while a process waits for the CPU "
                   "(a dry run; `impctl demo` runs on virtual time instead).")
@click.option("--epoch", help="Simulated start time, ISO 8601 with zone (default: now).")
@click.option("--wall-epoch", type=float, callback=bounded(WALL_EPOCH_S, "s"),
              help="Wall-clock anchor, POSIX s (default: now).")
@click.option("--clock", "clock_spec", help="Full clock spec (overrides --epoch/--speed).")
@click.option("--clock-file", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the clock spec to this file for other processes.")
@click.option("--faults", default="none", show_default=True,
              help="Faults at start, e.g. 'delay=2,greeting,fixed-tid,missing=2103'.")
@click.option("--faults-file", type=click.Path(dir_okay=False, path_type=Path),
              help="File with faults, re-read whenever it changes (run-time switching).")
@click.option("--weather", type=click.Path(dir_okay=False, path_type=Path),
              help="Weather file (EPW or timestamp,t_out CSV); default: built-in generator.")
@click.option("--weather-seed", default=0, show_default=True, type=int, callback=bounded(SEED))
@click.option("--t-out", "t_out", type=float, callback=bounded(T_OUT_C, "°C"),
              help="Hold the outdoor temperature at this value [°C] instead of a weather "
                   "file or the generator.")
@click.option("--setpoint", default=21.0, show_default=True, type=float,
              callback=bounded(SETPOINT_C, "°C"), help="Initial loop-1 setpoint [°C].")
@click.option("--no-thermostat", is_flag=True, help="No room thermostat: 2160 reads -400.")
@click.option("--heat-meter-id", type=int, callback=bounded(UNIT_ID),
              help="Also answer as a heat meter on this unit id.")
@click.option("--dhw-period-h", type=float, callback=bounded(DHW_PERIOD_H, "h"),
              help="DHW charging every this many hours.")
@click.option("--defrost", is_flag=True, help="Defrost cycles below +5 °C outdoors.")
@click.option("--noise", default=0.0, show_default=True, type=float,
              callback=bounded(NOISE_K, "K"), help="Sensor noise SD on T_air/T_out [K].")
@click.option("--seed", default=0, show_default=True, type=int, callback=bounded(SEED),
              help="Noise seed.")
@click.option("-v", "--verbose", count=True, help="More logging (-vv for pymodbus debug).")
def cli(house, plant_kind, emitter, control, host, port, allow_remote, rtu, baudrate,
        generation, speed, epoch, wall_epoch, clock_spec, clock_file, faults, faults_file,
        weather, weather_seed, t_out, setpoint, no_thermostat, heat_meter_id, dhw_period_h,
        defrost, noise, seed, verbose) -> None:
    """Simulated Kronoterm heat pump (5R1C house) on a real Modbus server."""
    logging.basicConfig(level=logging.WARNING - 10 * min(verbose, 2),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if t_out is not None and weather is not None:
        raise InputError("give a weather file or a constant outdoor temperature, not both",
                         place="--t-out")
    if clock_spec:
        clock = VirtualClock.from_spec(clock_spec)
    else:
        start = _parse_epoch(epoch) if epoch else datetime.now(UTC)
        clock = VirtualClock(start, speed, wall_epoch)
    params = PlantParams(dhw_period_s=None if dhw_period_h is None else dhw_period_h * 3600,
                         defrost_period_s=5400.0 if defrost else None)
    house_params, realism = _house_and_realism(house, emitter, control)
    config = SimConfig(
        house=house_params, plant_kind=plant_kind, realism=realism,
        generation=Generation(generation),
        weather=read_weather(weather) if weather else None,
        weather_seed=weather_seed, t_out_c=t_out, clock=clock, plant=params,
        setpoint_c=setpoint,
        room_thermostat=not no_thermostat, heat_meter_id=heat_meter_id, noise_sd_k=noise,
        seed=seed, faults=parse_faults(faults),
    )
    asyncio.run(_serve(config, host, port, allow_remote, rtu, baudrate, faults_file, clock_file))


def _house_and_realism(path: Path | None, emitter: str | None, control: str | None):
    """The house and the realistic plant's options: simulator defaults, then the house
    file's [plant.*] tables, then the --emitter/--control flags."""
    from impctl.model import read_toml
    from impctl.plant import CONTROL_CURVE, CONTROL_THERMOSTAT, Emitter
    from impctl.plant.housefile import load_plant

    from .config import default_realism

    if path is None:
        house, realism = default_house(), default_realism()
    else:
        house, realism = load_plant(path)
        if "defrost" not in read_toml(path).get("plant", {}).get("heat_pump", {}):
            realism = realism.with_section("heat_pump", defrost=0)  # the simulator's default
    if emitter == "underfloor":
        realism = realism.with_section("emitter", **_fields(Emitter.underfloor()))
    elif emitter == "radiators":
        realism = realism.with_section("emitter", **_fields(Emitter()))
    if control:
        realism = realism.with_section(
            "heat_pump", control=CONTROL_CURVE if control == "curve" else CONTROL_THERMOSTAT)
    return house, realism


def _fields(section) -> dict:
    from dataclasses import fields

    return {f.name: getattr(section, f.name) for f in fields(section)}


def _parse_epoch(text: str) -> datetime:
    try:
        value = datetime.fromisoformat(text)
    except ValueError:
        raise InputError(f"not an ISO 8601 time: {text!r}", place="--epoch") from None
    if value.tzinfo is None:
        raise InputError("the epoch needs a time zone, e.g. 2026-01-10T18:00+01:00",
                         place="--epoch")
    return value


async def _serve(config: SimConfig, host: str, port: int, allow_remote: bool, rtu: str | None,
                 baudrate: int, faults_file: Path | None, clock_file: Path | None) -> None:
    sim = KronotermSimulator(config, faults_file=faults_file)
    bound = await sim.start(host, port, rtu=rtu, baudrate=baudrate, allow_remote=allow_remote)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    if clock_file:
        clock_file.write_text(sim.clock.spec() + "\n")
    if rtu is None:
        where = f"tcp {sim.host}:{bound}"
    else:
        where = f"rtu socket://{sim.host}:{bound}" if rtu.startswith("socket://") else f"rtu {rtu}"
    click.echo(f"impctl-sim: serving {where} unit {config.unit_id} "
               f"{config.generation.value}; faults {sim.faults.describe()}; "
               f"clock {sim.clock.spec()}")
    click.echo(f"impctl-sim: plant {describe_plant(sim.plant)}")
    sys.stdout.flush()
    try:
        await stop.wait()
    finally:
        await sim.stop()


def main(argv: list[str] | None = None) -> None:
    """Console entry point; bad input → one line on stderr, exit status 2; a port that is
    taken and the like → one line, exit status 1."""
    from impctl.cli import run_group

    run_group(cli, argv, "impctl-sim", fail=(OSError, RuntimeError))
