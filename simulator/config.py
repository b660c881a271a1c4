"""Configuration of one simulated Kronoterm installation."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any
from zoneinfo import ZoneInfo

import numpy as np

from impctl.clock import VirtualClock
from impctl.kronoterm.registers import Generation
from impctl.model import HouseParameters, default_house
from impctl.weather import winter_temperatures

from .faults import Faults
from .plant import Plant, PlantParams, WeatherFeed
from .realistic import PlantLike, RealisticPlant

if TYPE_CHECKING:
    import pandas as pd

#: Kronoterm's factory unit id.
DEFAULT_UNIT_ID = 20


@dataclass
class SimConfig:
    """What to simulate.

    Attributes
    ----------
    house : HouseParameters
        One house (e.g. from ``impctl.model.load_house``).
    generation : Generation
        Register set exposed (compact TT3000 or extended).
    weather : pandas.Series, optional
        Outdoor temperature [°C] on a time zone-aware index, wrapped around when the clock runs
        past its end. Default: the generator of ``impctl.weather`` from midnight five days
        before the clock's epoch, 62 days at 15 min, seed ``weather_seed``.
    weather_seed : int
    t_out_c : float, optional
        Outdoor temperature held constant [°C] instead of ``weather`` (tests, steady demos).
    clock : VirtualClock, optional
        Default: real time.
    plant : PlantParams
        The simulator's heat-pump options: for ``plant_kind="iso"`` all of them; for the
        realistic plant the DHW schedule, and ``defrost_period_s`` set turns defrost on.
    plant_kind : {"realistic", "iso"}
        ``"realistic"`` (default): :mod:`impctl.plant` (air/furniture capacity, hydronic
        emitter, cycling heat pump, gains, sensors) with ``realism``; ``"iso"``: the ideal 5R1C
        with a 20-minute emitter and a modulating heat pump (:class:`impctl_sim.Plant`), the
        simulator before issue 13.
    realism : impctl.plant.PlantParams, optional
        Realism options of the realistic plant; default :func:`default_realism`.
    timezone : str, optional
        IANA zone of the house (its gains follow the local day); default: the clock epoch's.
    setpoint_c : float
        Initial loop-1 setpoint (2187) [°C].
    room_thermostat : bool
        A Kronoterm room thermostat on loop 1 (2160 reads T_air); ``False`` → 2160 reads −400.
    unit_id : int
        Modbus unit id of the heat pump.
    heat_meter_id : int, optional
        Also answer as an external heat meter with this unit id (address 0–1: thermal power W,
        uint32 high word first).
    step_s : float, optional
        Model step [simulated s]; default 10 s on the ideal plant, 60 s on the realistic one
        (a step costs ~0.3 ms instead of µs; its fastest effects, timers and ramps, take
        minutes).
    warmup_s : float
        Simulated time run before the start so the house is near its periodic state [s].
    noise_sd_k : float
        Standard deviation of Gaussian noise on the T_air and T_out sensors [K].
    seed : int
        Seed of the sensor noise.
    faults : Faults
        Faults active from the start.
    """

    house: HouseParameters = field(default_factory=default_house)
    generation: Generation = Generation.EXTENDED
    weather: pd.Series | None = None
    weather_seed: int = 0
    t_out_c: float | None = None
    clock: VirtualClock | None = None
    plant: PlantParams = field(default_factory=PlantParams)
    plant_kind: str = "realistic"
    realism: Any = None
    timezone: str | None = None
    setpoint_c: float = 21.0
    room_thermostat: bool = True
    unit_id: int = DEFAULT_UNIT_ID
    heat_meter_id: int | None = None
    step_s: float | None = None
    warmup_s: float = 4 * 86400.0
    noise_sd_k: float = 0.0
    seed: int = 0
    faults: Faults = field(default_factory=Faults)

    def __post_init__(self) -> None:
        if self.step_s is None:
            self.step_s = 10.0 if self.plant_kind == "iso" else 60.0

    def weather_feed(self, clock: VirtualClock) -> WeatherFeed:
        """The outdoor-temperature source for ``clock``."""
        if self.t_out_c is not None:
            # a feed of two equal samples a day apart: it wraps around, so it never changes
            return WeatherFeed.of_arrays(np.array([0.0, 86400.0]), np.full(2, self.t_out_c))
        if self.weather is not None:
            return WeatherFeed(self.weather)
        # from the midnight (in the clock's zone) five days before the clock's start; pandas
        # is not loaded: the simulator starts in about half the CPU without it
        e = clock.epoch
        midnight = datetime(e.year, e.month, e.day, tzinfo=e.tzinfo)
        start = datetime.fromtimestamp(midnight.timestamp() - 5 * 86400.0, e.tzinfo)
        return WeatherFeed.of_arrays(*winter_temperatures(start, days=62, step_s=900,
                                                          seed=self.weather_seed))

    def make_plant(self, clock: VirtualClock, t_out_c: float) -> PlantLike:
        """The plant of ``plant_kind``, holding ``setpoint_c`` at ``t_out_c`` [°C]."""
        if self.plant_kind == "iso":
            return Plant(self.house, self.plant, setpoint_c=self.setpoint_c)
        if self.plant_kind != "realistic":
            raise ValueError(f"plant_kind must be 'realistic' or 'iso', not {self.plant_kind!r}")
        realism = self.realism if self.realism is not None else default_realism()
        if self.plant.defrost_period_s is not None:
            realism = realism.with_section("heat_pump", defrost=1)
        zone = ZoneInfo(self.timezone) if self.timezone else clock.epoch.tzinfo or UTC

        def utc_offset_h(posix_s: float) -> float:
            offset = datetime.fromtimestamp(posix_s, zone).utcoffset()
            return offset.total_seconds() / 3600.0 if offset else 0.0

        return RealisticPlant(self.house, realism, self.plant, setpoint_c=self.setpoint_c,
                              t_out_c=t_out_c, seed=self.seed, utc_offset_h=utc_offset_h)


def default_realism() -> Any:
    """The simulator's realistic house: :class:`impctl.plant.PlantParams` defaults (radiators,
    a weather-compensated modulating air-source heat pump with room influence, 230 W of night
    gains, a 0.1 K room sensor with a 10-minute lag) with defrost off, as the simulator has
    always started (``--defrost`` or ``[plant.heat_pump] defrost = 1`` turn it on)."""
    from impctl.plant import PlantParams as Realism

    params = Realism()
    return params.with_section("heat_pump", defrost=0)


def constant_weather(t_out_c: float) -> pd.Series:
    """Weather that never changes (useful in tests): two samples a day apart, same value."""
    import pandas as pd

    index = pd.DatetimeIndex(["2000-01-01", "2000-01-02"], tz="UTC")
    return pd.Series([t_out_c, t_out_c], index=index, name="t_out")
