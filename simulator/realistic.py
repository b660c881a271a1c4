"""The realistic plant behind the simulator's registers (:mod:`impctl.plant`, issue 13).

:class:`RealisticPlant` gives :class:`impctl.plant.Plant` the surface the register image and the
server use (the same as the ideal :class:`~impctl_sim.plant.Plant`): Modbus inputs, compressor,
pumps, supply/return, powers, counters.
"""

from __future__ import annotations

import math

import numpy as np

from impctl.model import HouseParameters
from impctl.plant import OUTPUTS, periodic
from impctl.plant import Plant as _Core

from .plant import ControllerInputs, Plant, PlantParams, dhw_tank_c


class RealisticPlant(ControllerInputs):
    """The realistic plant of :mod:`impctl.plant` behind the simulator's registers.

    Air and furniture capacity, a hydronic emitter (radiators or underfloor), a heat pump with a
    heating curve or a room thermostat that modulates down to a minimum and cycles below it,
    defrost, night gains and imperfect sensors (see :class:`impctl.plant.PlantParams`). This
    class adds what a Kronoterm controller adds around it: the loop mode, system switch and
    2014 correction written over Modbus, DHW charges on a schedule, the internal and solar gains
    of an occupied house over the local day, energy counters and operating hours.

    Parameters
    ----------
    house : HouseParameters
        One house.
    realism : impctl.plant.PlantParams
        Realism options (floats).
    params : PlantParams
        The simulator's options; used here: the DHW schedule (``dhw_period_s``,
        ``dhw_duration_s``). Defrost comes from ``realism.heat_pump``.
    setpoint_c : float
        Initial loop-1 setpoint [°C]; the plant starts in the steady state holding it.
    t_out_c : float
        Outdoor temperature of that steady state [°C].
    seed : int
        Sensor noise and gains.
    utc_offset_h : callable(POSIX s) → hours, optional
        Local time of the house (gains follow the local day); default UTC.
    """

    kind = "realistic"

    def __init__(self, house: HouseParameters, realism, params: PlantParams | None = None,
                 setpoint_c: float = 21.0, t_out_c: float = 0.0, seed: int = 0,
                 utc_offset_h=None) -> None:
        if house.n_houses is not None:
            raise ValueError("the simulator runs one house")
        self.house = house
        self.params = params or PlantParams()
        self.realism = realism
        self.core = _Core(house, realism, setpoint_c=setpoint_c, t_out_c=t_out_c, seed=seed)
        self._rng = np.random.default_rng([seed, 13])
        self._utc_offset_h = utc_offset_h or (lambda t: 0.0)
        self._walk = 0.0
        self._clear: dict[int, float] = {}
        # Inputs (registers written by the client).
        self.setpoint_c = setpoint_c
        self.correction_k = 0
        self.loop_mode = 1
        self.system_on = 1
        #: Fault hook: a compressor that gives no heat while everything reads normal.
        self.compressor_failed = False
        self.time_s = 0.0
        self.t_dhw_c = 48.0
        self.e_th_kwh = self.e_el_kwh = 0.0
        self.hours_heating = self.hours_dhw = 0.0
        self.internal_gains_w = self.solar_gains_w = 0.0
        self._out = {name: getattr(self.core, name) for name in OUTPUTS}

    # -- inputs ----------------------------------------------------------------------------
    @property
    def max_power_w(self) -> float:
        """Nominal thermal output of the heat pump [W]; setting it ≤ 1 W fails the
        compressor (no heat, no error reported), as the ideal plant's cap does."""
        return 1.0 if self.compressor_failed else self.core.nominal_w

    @max_power_w.setter
    def max_power_w(self, value: float) -> None:
        self.compressor_failed = value <= 1.0

    # -- outputs ---------------------------------------------------------------------------
    def __getattr__(self, name: str):
        out = self.__dict__.get("_out")
        if out is not None and name in out:
            return out[name]
        raise AttributeError(name)

    t_air_sensor_c = property(lambda self: self._out["t_air_sensed_c"],
                              doc="What the room sensor reads [°C] (lag, noise, resolution).")
    t_out_sensor_c = property(lambda self: self._out["t_out_sensed_c"],
                              doc="What the outdoor sensor reads [°C].")
    dhw_active = property(lambda self: self._out["dhw"], doc="DHW charge running.")
    defrost_active = property(lambda self: self._out["defrost"], doc="Defrost running.")
    pump_on = property(lambda self: self._out["pump_on"], doc="Main circulation pump.")
    q_em_w = property(lambda self: self._out["emitter_w"], doc="Emitter output to the room [W].")
    t_w_target_c = property(lambda self: self._out["t_water_target_c"],
                            doc="Target water temperature of the control [°C].")
    def _steady_flow_c(self, node_c: float) -> float:
        ctl, core = self.core.core.controller, self.core.core
        return float(ctl.steady_flow_c(np.array([node_c]), self.room_setpoint_c,
                                       core.flow_lag_k_per_w)[0])

    def installer_curve_c(self) -> tuple[float, float]:
        """The plant's own curve (``curve_gain`` × the matched one) as the flows at −15 and
        +15 °C outdoor for the room setpoint [°C]: what 2309/2314 read before a write."""
        ctl, sp = self.core.core.controller, np.array([self.room_setpoint_c])
        return tuple(self._steady_flow_c(float(ctl.target_water_c(sp, sp, np.array([t]))[0]))
                     for t in (-15.0, 15.0))

    def set_curve(self, points_c: tuple[float, float] | None) -> None:
        """Run the two-point flow curve ``points_c`` (2309/2314 written) set for the room
        setpoint now; None: the plant's own curve again."""
        fa, fb = points_c if points_c is not None else (np.nan, np.nan)
        self.core.core.set_flow_curve(fa, fb, self.room_setpoint_c)

    @property
    def flow_target_c(self) -> float:
        """The flow temperature the control aims at (2128) [°C]: the two-point curve's where
        one runs, else the steady flow of the built-in curve's water target."""
        flow = float(self.core.core.controller.flow_target_c[0])
        return flow if np.isfinite(flow) else self._steady_flow_c(self._out["t_water_target_c"])

    space_heat_metered_w = property(lambda self: 0.0 if self._out["dhw"] else
                                    self._out["heat_meter_w"],
                                    doc="Space heat the heat meter reads [W] (meter errors).")

    @property
    def loop_pump_on(self) -> bool:
        """Loop-1 circulation pump: runs whenever the loop is on (also between cycles)."""
        return self.heating_enabled

    @property
    def p_th_w(self) -> float:
        """Thermal output the controller reports (2329): metered space heat + DHW [W]."""
        return self.space_heat_metered_w + self._out["dhw_w"]

    @property
    def p_el_w(self) -> float:
        """Electrical power [W]."""
        return self._out["electric_w"]

    @property
    def cop(self) -> float:
        """Instantaneous COP [-] (0 while the compressor is off)."""
        heat = abs(self._out["heat_pump_w"]) + self._out["dhw_w"]
        el = self._out["electric_w"] - self.core.core.standby_w[0]
        return heat / el if self._out["compressor_on"] and el > 0 else 0.0

    @property
    def heat_demand(self) -> bool:
        """The control asks for heat (2046 b0: thermostat calling, or the curve's demand)."""
        return bool(self._out["heat_demand"]) and not self.compressor_failed

    @property
    def load_pct(self) -> int:
        """Compressor modulation [%] of nominal."""
        return min(100, max(0, round(100 * self._out["heat_pump_w"] / self.core.nominal_w)))

    @property
    def protection_bits(self) -> int:
        """2319: b0 anti-cycling lockout (heating wanted, minimum off time running),
        b1 compressor starting (within its ramp)."""
        ctl, hp = self.core.core.control, self.realism.heat_pump
        timer = float(ctl.timer_s[0])
        locked = (self.heating_enabled and not self._out["compressor_on"]
                  and timer < float(hp.min_off_s))
        starting = self._out["compressor_on"] and timer < float(hp.ramp_s)
        return int(locked) | (int(starting) << 1)

    # -- step ------------------------------------------------------------------------------
    def _gains(self, dt_s: float) -> tuple[float, float]:
        """Internal and solar gains of the local hour [W] (levels of ``realism.gains``)."""
        g = self.realism.gains
        local_s = self.time_s + 3600.0 * self._utc_offset_h(self.time_s)
        hour = (local_s / 3600.0) % 24.0
        night = hour >= 22.0 or hour < 7.0
        level = float(g.night_w if night else g.day_w)
        self._walk += float(self._rng.standard_normal()) * math.sqrt(dt_s / 3600.0)
        internal = min(max(level + float(g.drift_w) * self._walk, 0.0), 2.0 * level)
        day = int(local_s // 86400)
        if day not in self._clear:
            self._clear = {day: float(self._rng.uniform())}
        sun = math.sin(math.pi * (hour - 8.0) / 8.0) if 8.0 <= hour <= 16.0 else 0.0
        return internal, float(g.solar_peak_w) * sun * self._clear[day]

    def step(self, dt_s: float, t_out_c: float) -> None:
        """Advance the plant by ``dt_s`` seconds at outdoor temperature ``t_out_c``."""
        p = self.params
        on = bool(self.system_on)
        dhw = on and periodic(self.time_s, p.dhw_period_s, p.dhw_duration_s)
        self.internal_gains_w, self.solar_gains_w = self._gains(dt_s)
        core = self.core
        core.setpoint_c = self.room_setpoint_c
        core.loop_on = self.loop_mode != 0 and not self.compressor_failed
        core.system_on = on
        self._out = out = core.step(dt_s, t_out_c, dhw=dhw,
                                    internal_gains_w=self.internal_gains_w,
                                    solar_gains_w=self.solar_gains_w)
        heat = max(out["heat_pump_w"], 0.0) + out["dhw_w"]
        self.e_th_kwh += heat * dt_s / 3.6e6
        self.e_el_kwh += out["electric_w"] * dt_s / 3.6e6
        if out["compressor_on"]:
            if out["dhw"]:
                self.hours_dhw += dt_s / 3600.0
            else:
                self.hours_heating += dt_s / 3600.0
        if p.dhw_period_s is not None:
            self.t_dhw_c = dhw_tank_c(self.t_dhw_c, out["dhw_w"], dt_s)
        self.time_s += dt_s


#: Either plant; the register image and the server use only their common surface.
PlantLike = Plant | RealisticPlant


def describe_plant(plant: PlantLike) -> str:
    """One line: which plant, and the realistic plant's main options."""
    if plant.kind == "iso":
        return f"iso (ideal 5R1C, emitter τ {plant.params.emitter_tau_s / 60:.0f} min)"
    return "realistic (" + realism_summary(plant.realism) + ")"


def realism_summary(realism) -> str:
    """The realistic plant's main options in a few words (emitter, control, sensor)."""
    from impctl.plant import CONTROL_CURVE, CONTROL_THERMOSTAT, UNDERFLOOR

    e, hp, s, g = realism.emitter, realism.heat_pump, realism.sensors, realism.gains
    emitter = "underfloor" if int(e.kind) == UNDERFLOOR else "radiators"
    control = {CONTROL_CURVE: "weather curve", CONTROL_THERMOSTAT: "room thermostat"}.get(
        int(hp.control), "ideal control")
    unit = "on/off" if float(hp.min_modulation) >= 1.0 else (
        f"modulating ≥ {float(hp.min_modulation):.0%}")
    return (f"{emitter}, {control}, {unit}, defrost {'on' if int(hp.defrost) else 'off'}, "
            f"night gains {float(g.night_w):.0f} W, room sensor {float(s.t_air_quantum_k):g} K "
            f"lag {float(s.t_air_lag_s) / 60:.0f} min")
