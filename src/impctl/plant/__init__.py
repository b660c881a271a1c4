"""The realistic plant: a 5R1C house as real heat-pump houses are.

Same conductances and the same total heat capacity as the house's ISO 13790 parameters, plus what
real houses have: air and furniture capacity, a hydronic emitter with its own capacity and an
output ∝ (θ_w − θ_air)ⁿ, a heat pump with weather-compensated or thermostat control, minimum
modulation, on/off cycling with hysteresis and anti-short-cycle timers, a start ramp, defrost and
DHW interruptions, internal and solar gains, and imperfect sensors. Units: °C, W, J, s.

Rooms by physical concern: :mod:`.params` (every option, default, range); :mod:`.building`
(the envelope and its capacities, the gains); :mod:`.hydronics` (the emitter, the heat pump and
its control); :mod:`.instruments` (the sensors and the heat meter); :mod:`.simulation` runs many
houses (batch) or one house step by step; :mod:`.housefile` reads a house file's ``[plant]``.
"""

from .building.envelope import CapacitySplit, split_capacity
from .building.gains import HouseGains
from .housefile import load_plant, plant_params_from_mapping
from .params import (
    CONTROL_CURVE,
    CONTROL_IDEAL,
    CONTROL_THERMOSTAT,
    RADIATORS,
    SECTIONS,
    UNDERFLOOR,
    Capacities,
    Emitter,
    Gains,
    HeatPump,
    PlantParams,
    Sensors,
)
from .simulation.simulate import OUTPUTS, PlantCore, PlantRun, simulate_plant
from .simulation.stepper import Plant, periodic

__all__ = [
    "CONTROL_CURVE",
    "CONTROL_IDEAL",
    "CONTROL_THERMOSTAT",
    "OUTPUTS",
    "RADIATORS",
    "SECTIONS",
    "UNDERFLOOR",
    "Capacities",
    "CapacitySplit",
    "Emitter",
    "Gains",
    "HeatPump",
    "HouseGains",
    "Plant",
    "PlantCore",
    "PlantParams",
    "PlantRun",
    "Sensors",
    "load_plant",
    "periodic",
    "plant_params_from_mapping",
    "simulate_plant",
    "split_capacity",
]
