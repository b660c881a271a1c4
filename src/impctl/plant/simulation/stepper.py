"""One house, one step at a time: the plant behind the Modbus simulator.

:class:`Plant` wraps :class:`~.simulate.PlantCore` for a single house. The simulator
sets the inputs it gets from registers (room setpoint, loop mode, system on/off) and calls
:meth:`Plant.step` with the outdoor temperature; DHW charges come from :func:`periodic` (or any
schedule), defrosts from the heat pump's own logic (or ``defrost=True`` to force one).
"""

from __future__ import annotations

import numpy as np

from ...model import HouseParameters
from ..instruments.sensors import SensorBank
from ..params import PlantParams
from .simulate import OUTPUTS, PlantCore


def periodic(time_s: float, period_s: float | None, duration_s: float,
             offset_s: float = 0.0) -> bool:
    """True during the first ``duration_s`` of every ``period_s`` (None = never) [s]."""
    return period_s is not None and (time_s + offset_s) % period_s < duration_s


class Plant:
    """The realistic plant of one house, driven step by step.

    Parameters
    ----------
    house : HouseParameters
        One house.
    params : PlantParams, optional
        Realism options (floats); default :class:`PlantParams` (a typical heat-pump house).
    setpoint_c : float
        Initial room setpoint [°C]; the plant starts in the steady state holding it.
    t_out_c : float
        Outdoor temperature of that steady state [°C].
    seed : int
        Sensor noise.

    Attributes
    ----------
    setpoint_c : float
        Room setpoint [°C] (input).
    loop_on, system_on : bool
        Heating loop mode on / whole system on (inputs); space heating needs both.
    time_s : float
        Simulated time since the start [s].
    Every output of the last step (:data:`impctl.plant.OUTPUTS`) is an attribute: ``t_air_c``
    (true), ``t_air_sensed_c``, ``t_supply_c``, ``t_return_c``, ``heat_pump_w`` (thermal
    output, negative during defrost), ``electric_w``, ``compressor_on``, ``pump_on``,
    ``defrost``, ``dhw`` … Floats and bools.
    """

    def __init__(self, house: HouseParameters, params: PlantParams | None = None, *,
                 setpoint_c: float = 21.0, t_out_c: float = 0.0, seed: int = 0) -> None:
        if house.n_houses is not None:
            raise ValueError("Plant runs one house; use simulate_plant for many")
        self.params = params or PlantParams()
        self.core = PlantCore(house, self.params, seed, n=1)
        self.core.start_steady(setpoint_c, t_out_c)
        self.setpoint_c = float(setpoint_c)
        self.loop_on = True
        self.system_on = True
        self.time_s = 0.0
        self._last: dict[str, float | bool] = {}
        # Fill the outputs with a negligible step, then restore the exact start (state and noise).
        self.step(1e-3, t_out_c)
        self.core.sensors = SensorBank(self.params.sensors, 1, np.random.default_rng(seed))
        self.core.start_steady(setpoint_c, t_out_c)
        self.time_s = 0.0

    @property
    def heating_enabled(self) -> bool:
        """Space heating allowed: loop on and system on."""
        return bool(self.loop_on and self.system_on)

    @property
    def nominal_w(self) -> float:
        """Nominal thermal output of the heat pump [W]."""
        return float(self.core.nominal_w[0])

    def step(self, dt_s: float, t_out_c: float, *, dhw: bool = False,
             defrost: bool = False, internal_gains_w: float = 0.0,
             solar_gains_w: float = 0.0) -> dict[str, float | bool]:
        """Advance by ``dt_s`` seconds at outdoor ``t_out_c`` [°C]; returns the outputs."""
        on = self.heating_enabled
        dhw = bool(dhw and self.system_on)
        out = self.core.step(float(dt_s), np.array([float(t_out_c)]),
                             np.array([self.setpoint_c]), np.array([on]),
                             np.array([float(internal_gains_w)]), np.array([float(solar_gains_w)]),
                             np.array([dhw]),
                             np.array([True]) if defrost and self.system_on else None)
        self._last = {k: (bool(v[0]) if v.dtype == bool else float(v[0]))
                      for k, v in out.items()}
        if not self.system_on:
            self._last["electric_w"] = 0.0
        self.time_s += dt_s
        return dict(self._last)

    def __getattr__(self, name: str):
        if name in OUTPUTS and "_last" in self.__dict__:
            return self.__dict__["_last"][name]
        raise AttributeError(name)
