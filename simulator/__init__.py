"""Kronoterm heat-pump Modbus simulator backed by the 5R1C model (import package ``impctl_sim``).

In-process use (tests)::

    from impctl_sim import KronotermSimulator, SimConfig
    async with KronotermSimulator(SimConfig(...)) as sim:
        ...  # Modbus TCP on 127.0.0.1:sim.port

Command line: ``impctl-sim --house H.toml --port 5020 --speed 600 --generation extended``.
"""

from .config import SimConfig, constant_weather
from .faults import Faults, parse_faults
from .plant import Plant, PlantParams, WeatherFeed
from .server import KronotermSimulator, SimStats

__all__ = [
    "Faults",
    "KronotermSimulator",
    "Plant",
    "PlantParams",
    "SimConfig",
    "SimStats",
    "WeatherFeed",
    "constant_weather",
    "parse_faults",
]
