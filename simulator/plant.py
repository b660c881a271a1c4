"""The simulated plant: a 5R1C house heated by a modulating heat pump through a lagging emitter.

Per step of Δt seconds (explicit, one house, plain floats):

* **House**: the ISO 13790 Annex C step of :mod:`impctl.model.annex_c` (its per-house constants
  ``_Step``), with the emitter output Φ_em forced into the air node.
* **Emitter** (water + radiators/floor loop): capacity C_em = τ_em·UA_em, output
  Φ_em = UA_em·(θ_w − θ_air) ≥ 0, solved implicitly with the air node. After the heat pump stops,
  θ_w decays with τ_em (default 20 min), so heat keeps flowing for about an hour.
* **Heat pump**, loop-1 thermostat: the Annex C demand Φ_need to hold the room setpoint (2187 +
  correction 2014) sets a water target θ_w* = θ_set + Φ_need/UA_em; the thermal power
  P_th = C_em(θ_w* − θ_w)/τ_c + Φ_em is clipped to 0…P_max. Off when loop mode (2042) is 0 or
  the system (2012) is off. COP = η·T_sup/(T_sup − θ_e + 5 K) (kelvin), clipped to 1.5…6.5.
* Optional interruptions: DHW charging (space heating paused) and defrost (heat drawn from the
  water).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from impctl.model import HouseParameters
from impctl.model.annex_c import _Step

if TYPE_CHECKING:
    import pandas as pd


@dataclass(frozen=True)
class PlantParams:
    """Heat-pump and emitter parameters (W, K, s).

    Attributes
    ----------
    max_power_w : thermal power cap; ``None`` = the house's ``max_heating_power`` (or 12 kW).
    emitter_tau_s : emitter time constant C_em/UA_em [s].
    emitter_ua_w_per_k : emitter conductance; ``None`` = 2.2 × the house's heat-loss coefficient.
    control_tau_s : how fast the heat pump drives the water to its target [s].
    flow_w_per_k : loop flow ṁ·c_p [W/K] (supply − return = P_th/ṁc_p).
    cop_eta : fraction of the Carnot COP reached.
    standby_w : electrical draw while the system is on [W].
    dhw_period_s, dhw_duration_s, dhw_power_w : DHW charging every period (``None`` = never).
    defrost_below_c, defrost_period_s, defrost_duration_s, defrost_draw_w : defrost cycles when
        θ_e is below the threshold (``defrost_period_s=None`` = never).
    """

    max_power_w: float | None = None
    emitter_tau_s: float = 1200.0
    emitter_ua_w_per_k: float | None = None
    control_tau_s: float = 600.0
    flow_w_per_k: float = 1200.0
    cop_eta: float = 0.45
    standby_w: float = 20.0
    dhw_period_s: float | None = None
    dhw_duration_s: float = 1800.0
    dhw_power_w: float = 4000.0
    defrost_below_c: float = 5.0
    defrost_period_s: float | None = None
    defrost_duration_s: float = 360.0
    defrost_draw_w: float = 1500.0


def dhw_tank_c(t_tank_c: float, charge_w: float, dt_s: float) -> float:
    """DHW tank temperature after ``dt_s`` s of charging at ``charge_w`` W [°C] (display only:
    a 1.2 MJ/K tank losing towards 20 °C with a 2e5 s time constant)."""
    return t_tank_c + dt_s * (charge_w / 1.2e6 - (t_tank_c - 20.0) / 2.0e5)


class WeatherFeed:
    """Outdoor temperature at any simulated time: linear interpolation, wrapped around.

    Parameters
    ----------
    series : pandas.Series
        Outdoor temperature [°C] on a time zone-aware index (≥ 2 samples).
    """

    def __init__(self, series: pd.Series) -> None:
        import pandas as pd

        index = pd.DatetimeIndex(series.index)
        self._set((index.as_unit("ns").asi8 / 1e9).astype(float), series.to_numpy(dtype=float))

    @classmethod
    def of_arrays(cls, posix_s: np.ndarray, t_out_c: np.ndarray) -> WeatherFeed:
        """The feed of outdoor temperatures ``t_out_c`` [°C] at POSIX times ``posix_s`` [s]."""
        feed = cls.__new__(cls)
        feed._set(np.asarray(posix_s, dtype=float), np.asarray(t_out_c, dtype=float))
        return feed

    def _set(self, t: np.ndarray, v: np.ndarray) -> None:
        if len(v) < 2:
            raise ValueError("weather needs at least two samples")
        self._t, self._v = t, v
        self._span = self._t[-1] - self._t[0]

    def t_out_c(self, sim_s: float) -> float:
        """Outdoor temperature at POSIX time ``sim_s`` [°C]."""
        offset = (sim_s - self._t[0]) % self._span
        return float(np.interp(self._t[0] + offset, self._t, self._v))


class ControllerInputs:
    """What the controller's registers set, read the same way by both plants: loop-1 mode
    (2042), system on (2012), setpoint (2187) and its correction (2014)."""

    system_on: bool
    loop_mode: int
    setpoint_c: float
    correction_k: float

    @property
    def heating_enabled(self) -> bool:
        """Loop 1 on (mode 1 or 2) and the system on."""
        return bool(self.system_on) and self.loop_mode != 0

    @property
    def room_setpoint_c(self) -> float:
        """Effective room setpoint: 2187 plus the 2014 correction [°C]."""
        return self.setpoint_c + self.correction_k

    def installer_curve_c(self) -> tuple[float, float]:
        """The loop-1 curve points (2309/2314) the controller starts with [°C]."""
        return (45.0, 30.0)

    def set_curve(self, points_c: tuple[float, float] | None) -> None:
        """Curve points written (2309/2314); None: back to the controller's own curve. The
        ideal plant has no curve: its heat follows the room's need whatever the points."""

    @property
    def flow_target_c(self) -> float:
        """The flow temperature the control aims at (2128) [°C]."""
        return self.t_w_target_c


class Plant(ControllerInputs):
    """State and step of the simulated house + heat pump.

    Parameters
    ----------
    house : HouseParameters
        One house.
    params : PlantParams
    setpoint_c : float
        Initial loop-1 setpoint [°C].
    t_init_c : float, optional
        Initial mass and water temperature [°C] (default: the setpoint).
    """

    def __init__(self, house: HouseParameters, params: PlantParams = PlantParams(),
                 setpoint_c: float = 21.0, t_init_c: float | None = None) -> None:
        if house.n_houses is not None:
            raise ValueError("the simulator runs one house")
        self.house = house
        self.params = params
        self._net = house.network
        cap = float(house.max_heating_power)
        self.max_power_w = params.max_power_w or (cap if math.isfinite(cap) else 12000.0)
        self.ua_w_per_k = params.emitter_ua_w_per_k or 2.2 * float(house.hlc_w_per_k)
        self.c_em_j_per_k = params.emitter_tau_s * self.ua_w_per_k
        self._steps: dict[float, _Step] = {}
        # Inputs (registers written by the client).
        self.setpoint_c = setpoint_c
        self.correction_k = 0
        self.loop_mode = 1
        self.system_on = 1
        # State.
        t0 = setpoint_c if t_init_c is None else t_init_c
        self.time_s = 0.0
        self.t_m_c = t0
        self.t_air_c = t0
        self.t_w_c = t0
        self.t_dhw_c = 48.0
        self.t_out_c = 0.0
        self.p_th_w = 0.0  # heat-pump thermal output (space + DHW − defrost draw)
        self.p_el_w = 0.0
        self.q_em_w = 0.0  # heat the emitter gives the room
        self.cop = 0.0
        self.dhw_active = False
        self.defrost_active = False
        self.heat_demand = False
        self.t_w_target_c = t0
        self.e_th_kwh = 0.0
        self.e_el_kwh = 0.0
        self.hours_heating = 0.0
        self.hours_dhw = 0.0

    @property
    def t_supply_c(self) -> float:
        """Supply (flow) water temperature [°C]."""
        return self.t_w_c + self._space_power() / (2 * self.params.flow_w_per_k)

    @property
    def t_return_c(self) -> float:
        """Return water temperature [°C]."""
        return self.t_w_c - self._space_power() / (2 * self.params.flow_w_per_k)

    def _space_power(self) -> float:
        return 0.0 if self.dhw_active else self.p_th_w

    # What the register image shows; the realistic plant has its own sensors and compressor.
    kind = "iso"

    @property
    def t_air_sensor_c(self) -> float:
        """What the room sensor reads before the simulator's optional noise [°C]."""
        return self.t_air_c

    @property
    def t_out_sensor_c(self) -> float:
        """What the outdoor sensor reads before the simulator's optional noise [°C]."""
        return self.t_out_c

    @property
    def compressor_on(self) -> bool:
        """Compressor running (heating, DHW or defrost)."""
        return self.p_th_w > 0

    @property
    def pump_on(self) -> bool:
        """Main circulation pump running."""
        return self.p_th_w > 0

    @property
    def loop_pump_on(self) -> bool:
        """Loop-1 circulation pump running."""
        return self.heating_enabled

    @property
    def load_pct(self) -> int:
        """Compressor load (modulation) [%]."""
        return min(100, max(0, round(100 * self.p_th_w / self.max_power_w)))

    @property
    def protection_bits(self) -> int:
        """2319: b0 anti-cycling lockout, b1 compressor starting (the ideal plant has none)."""
        return 0

    @property
    def space_heat_metered_w(self) -> float:
        """Space-heating heat a heat meter on the loop reads [W]."""
        return self._space_power()

    def _step_constants(self, dt_s: float) -> _Step:
        if dt_s not in self._steps:
            self._steps[dt_s] = _Step(self._net, dt_s)
        return self._steps[dt_s]

    def _phase(self, period: float | None, duration: float, offset: float) -> bool:
        return period is not None and (self.time_s + offset) % period < duration

    def step(self, dt_s: float, t_out_c: float) -> None:
        """Advance the plant by ``dt_s`` seconds at outdoor temperature ``t_out_c``."""
        p, k = self.params, self._step_constants(dt_s)
        self.t_out_c = t_out_c
        on = bool(self.system_on)
        self.dhw_active = on and self._phase(p.dhw_period_s, p.dhw_duration_s, 0.0)
        self.defrost_active = (on and not self.dhw_active and t_out_c < p.defrost_below_c
                               and self._phase(p.defrost_period_s, p.defrost_duration_s, 900.0))
        t_m_free, _, t_air_free = k.free(self.t_m_c, t_out_c, 0.0, 0.0)
        # Emitter output, implicit in the air temperature it warms.
        q_em = self.ua_w_per_k * (self.t_w_c - t_air_free) / (1 + self.ua_w_per_k * k.k_air)
        q_em = max(q_em, 0.0)
        space = 0.0
        self.heat_demand = False
        if self.heating_enabled and not self.dhw_active and not self.defrost_active:
            need = max(0.0, (self.room_setpoint_c - t_air_free) / k.k_air)
            self.heat_demand = need > 0.0
            t_w_target = self.room_setpoint_c + min(need, self.max_power_w) / self.ua_w_per_k
            self.t_w_target_c = t_w_target
            drive = self.c_em_j_per_k * (t_w_target - self.t_w_c) / p.control_tau_s
            space = min(max(drive + q_em, 0.0), self.max_power_w)
        if self.defrost_active:
            space = -p.defrost_draw_w
        dhw = p.dhw_power_w if self.dhw_active else 0.0
        self.t_w_c += dt_s * (space - q_em) / self.c_em_j_per_k
        self.t_m_c = t_m_free + q_em * k.k_m
        self.t_air_c = t_air_free + q_em * k.k_air
        self.q_em_w = q_em
        self.p_th_w = space + dhw
        if p.dhw_period_s is not None:  # without DHW cycles the tank just stays at 48 °C
            self.t_dhw_c = dhw_tank_c(self.t_dhw_c, dhw, dt_s)
        t_hot = (self.t_w_c if not self.dhw_active else self.t_dhw_c) + 273.15
        lift = max(t_hot - (t_out_c + 273.15) + 5.0, 1.0)
        self.cop = min(max(p.cop_eta * t_hot / lift, 1.5), 6.5) if self.p_th_w else 0.0
        self.p_el_w = (abs(self.p_th_w) / self.cop if self.cop else 0.0) + (p.standby_w if on
                                                                             else 0.0)
        self.e_th_kwh += max(self.p_th_w, 0.0) * dt_s / 3.6e6
        self.e_el_kwh += self.p_el_w * dt_s / 3.6e6
        self.hours_heating += dt_s / 3600.0 if space > 0 else 0.0
        self.hours_dhw += dt_s / 3600.0 if dhw > 0 else 0.0
        self.time_s += dt_s
