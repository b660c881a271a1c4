"""Kronoterm heat-pump Modbus simulator (import package ``impctl_sim``): the realistic plant of
:mod:`impctl.plant` by default (:class:`RealisticPlant`), or the ideal 5R1C (:class:`Plant`,
``SimConfig(plant_kind="iso")``).

In-process use (tests)::

    from impctl_sim import KronotermSimulator, SimConfig
    async with KronotermSimulator(SimConfig(...)) as sim:
        ...  # Modbus TCP on 127.0.0.1:sim.port

Command line: ``impctl-sim --house H.toml --port 5020 --speed 600 --generation extended``.
"""

from .config import SimConfig, constant_weather, default_realism
from .faults import Faults, parse_faults
from .plant import Plant, PlantParams, WeatherFeed
from .realistic import RealisticPlant
from .server import KronotermSimulator, SimStats

__all__ = [
    "Faults",
    "KronotermSimulator",
    "Plant",
    "PlantParams",
    "RealisticPlant",
    "SimConfig",
    "SimStats",
    "WeatherFeed",
    "constant_weather",
    "default_realism",
    "parse_faults",
]
