"""The ISO 13790 5R1C simple hourly model: house parameters, Annex C step, continuous form.

Units: °C, W, W/K, J/K, m², s (time steps) and h (time constants).
"""

from .annex_c import Simulation, simulate
from .continuous import (
    air_derivative,
    air_temperature,
    mass_derivative,
    mass_from_air,
    surface_temperature,
)
from .house import (
    TABLE_IV,
    Conductances,
    HouseParameters,
    am_factor,
    conductances,
    default_house,
    house_from_mapping,
    load_house,
    read_toml,
)
from .house_limits import PARAMETER_UNITS

__all__ = [
    "PARAMETER_UNITS",
    "TABLE_IV",
    "Conductances",
    "HouseParameters",
    "Simulation",
    "air_derivative",
    "air_temperature",
    "am_factor",
    "conductances",
    "default_house",
    "house_from_mapping",
    "load_house",
    "mass_derivative",
    "mass_from_air",
    "read_toml",
    "simulate",
    "surface_temperature",
]
