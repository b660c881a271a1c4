"""Air-source heat pump and its control, vectorised over houses (RH §3).

Per step, from what the controller knows at the start of the step (sensed room and outdoor
temperature, the water temperature):

* **Target water temperature**: the heating curve θ_w* = θ_set + gain·(HLC·(θ_set − θ_e)/K)^(1/n)
  (the emitter's matched curve, set ``curve_gain`` high as installers do) plus the room
  influence k·(θ_set − θ_air,sensed), clipped to 15…design + 10 °C.
* **Demand**: curve mode — always while the loop is on; thermostat mode — a room thermostat with
  hysteresis band ``room_hysteresis_k`` on the sensed room temperature.
* **Requested output** P_req = K·(θ_w* − θ_air)ⁿ + C_em·(θ_w* − θ_w)/τ_c ≥ 0.
* **Compressor**: capacity P_max = P_nom·(1 + c·(θ_e − 7)) (clipped to 40–130 %), minimum
  P_min = min_modulation·P_nom. It runs at clip(P_req, P_min, P_max) with a start ramp
  (P_nom per ``ramp_s``); below P_min it cycles on water-temperature hysteresis (stop when
  θ_w > θ_w* + h, start when θ_w < θ_w* − h), honouring the minimum on and off times. Loop off,
  system off and DHW stop space heating at once (the minimum off time still applies after).
* **Defrost** (outdoor −12…+5 °C): after ``defrost_interval_s`` of compressor run time, and
  not before ``defrost_min_run_s`` since the compressor's last space-heating start (a DHW
  charge counts as a stop), the unit reverses for
  ``defrost_duration_s`` and draws ``defrost_draw``·P_nom from the water.
* **Sizing** (:func:`nominal_output_w`): P_nom is set so that the mean output at the design
  outdoor temperature, defrosts included, is ``sizing`` × the design load.
* **DHW** (an input): space heating paused; the compressor heats the tank at P_nom.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..params import CONTROL_THERMOSTAT, HeatPump
from .flow_curve import curve_flow_c, flow_for_node, node_for_flow

Array = NDArray[np.float64]

#: Outdoor range in which defrosts happen [°C] (RH §3, §6: −12…+5 °C).
DEFROST_RANGE_C = (-12.0, 5.0)
#: Capacity reference outdoor temperature [°C] (A7 rating point).
CAPACITY_REF_C = 7.0
#: Clip of the capacity factor [-] [own choice].
CAPACITY_CLIP = (0.4, 1.3)
#: Clip of the target water temperature: lower bound [°C] and margin above design [K].
WATER_MIN_C, WATER_MARGIN_K = 15.0, 10.0


def capacity_factor(capacity_per_k: Array, t_out_c: Array) -> Array:
    """Capacity at ``t_out_c`` / nominal (+7 °C) capacity [-], clipped to :data:`CAPACITY_CLIP`."""
    f = 1.0 + capacity_per_k * (t_out_c - CAPACITY_REF_C)
    return np.minimum(np.maximum(f, CAPACITY_CLIP[0]), CAPACITY_CLIP[1])


def nominal_output_w(hp: HeatPump, design_load_w: Array, design_t_out_c: Array) -> Array:
    """Nominal (+7 °C) thermal output [W] of a heat pump sized on its design point.

    At the design outdoor temperature θ_d the capacity is P_nom·f(θ_d) (:func:`capacity_factor`);
    in the defrost band a unit running flat out spends ``defrost_interval_s`` (I) heating and
    ``defrost_duration_s`` (D) drawing ``defrost_draw``·P_nom (r) from the water, so its mean
    output is P_nom·(I·f − D·r)/(I + D) (the integrated capacity of EN 14511). P_nom is chosen so
    that this mean equals ``sizing`` × ``design_load_w`` [W]. With every parameter in its range
    I·f − D·r ≥ 2100·0.4 − 600 > 0.
    """
    f = capacity_factor(np.asarray(hp.capacity_per_k, dtype=float),
                        np.asarray(design_t_out_c, dtype=float))
    t_d = np.asarray(design_t_out_c, dtype=float)
    frosty = ((np.asarray(hp.defrost) > 0) & (t_d >= DEFROST_RANGE_C[0])
              & (t_d <= DEFROST_RANGE_C[1]))
    i_s = np.asarray(hp.defrost_interval_s, dtype=float)
    d_s = np.asarray(hp.defrost_duration_s, dtype=float)
    integrated = np.where(frosty, (i_s * f - d_s * np.asarray(hp.defrost_draw, dtype=float))
                          / (i_s + d_s), f)
    return np.asarray(hp.sizing, dtype=float) * np.asarray(design_load_w, dtype=float) / integrated


@dataclass
class ControlState:
    """Controller and compressor state, arrays over houses."""

    running: NDArray[np.bool_]      # compressor on for space heating (incl. defrost)
    timer_s: Array                  # time since the compressor last switched
    power_w: Array                  # last thermal output into the water [W]
    run_since_defrost_s: Array
    defrost_left_s: Array
    calling: NDArray[np.bool_]      # room thermostat calls for heat

    @classmethod
    def idle(cls, n: int) -> ControlState:
        """Compressor off long enough to start at once."""
        return cls(np.zeros(n, bool), np.full(n, 1e9), np.zeros(n), np.zeros(n), np.zeros(n),
                   np.zeros(n, bool))


@dataclass(frozen=True)
class ControlOutput:
    """One step's decision: thermal power into the water [W] and states."""

    power_w: Array
    compressor_on: NDArray[np.bool_]
    defrost: NDArray[np.bool_]
    target_water_c: Array
    p_max_w: Array
    demand: NDArray[np.bool_]       # the controller calls for space heat


class Controller:
    """The heat pump of ``n`` houses (module docstring).

    Parameters
    ----------
    hp : HeatPump
    nominal_w : nominal thermal output [W]
    k_w, exponent : emitter output constant [W/Kⁿ] and exponent
    hlc_w_per_k : heat-loss coefficient [W/K]
    c_em : emitter heat capacity [J/K]
    design_water_c : design mean water temperature [°C]
    """

    def __init__(self, hp: HeatPump, nominal_w: Array, k_w: Array, exponent: Array,
                 hlc_w_per_k: Array, c_em: Array, design_water_c: Array, n: int) -> None:
        def b(v):
            return np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()

        self.nominal_w, self.k_w, self.n_exp = b(nominal_w), b(k_w), b(exponent)
        self.hlc, self.c_em = b(hlc_w_per_k), b(c_em)
        self.water_max_c = b(design_water_c) + WATER_MARGIN_K
        self.thermostat = b(hp.control) == CONTROL_THERMOSTAT
        self.p_min_frac = b(hp.min_modulation)
        self.cap_per_k = b(hp.capacity_per_k)
        self.curve_gain = b(hp.curve_gain)
        self.room_k = b(hp.room_influence_k_per_k)
        self.hyst_w = b(hp.water_hysteresis_k)
        self.hyst_room = b(hp.room_hysteresis_k)
        self.min_on, self.min_off = b(hp.min_on_s), b(hp.min_off_s)
        self.ramp_w_per_s = self.nominal_w / b(hp.ramp_s)
        self.tau_c = b(hp.control_tau_s)
        self.defrost_on = b(hp.defrost) > 0
        self.defrost_interval = b(hp.defrost_interval_s)
        self.defrost_min_run = b(hp.defrost_min_run_s)
        self.defrost_duration = b(hp.defrost_duration_s)
        self.defrost_w = b(hp.defrost_draw) * self.nominal_w
        # Precomputed for the per-step arithmetic.
        self._hlc_per_k = self.hlc / self.k_w
        self._inv_n = 1.0 / self.n_exp
        self._c_per_tau = self.c_em / self.tau_c
        self._p_min_nom = self.p_min_frac * self.nominal_w
        self._any_thermostat = bool(self.thermostat.any())
        self._half_band = 0.5 * self.hyst_room
        self._not_thermostat = ~self.thermostat
        self._any_defrost = bool(self.defrost_on.any())
        self._no = np.zeros(n, bool)
        #: Two-point flow curves (:meth:`set_flow_curve`); None: the built-in curve everywhere.
        self._curve: tuple[Array, ...] | None = None
        self._has_curve = np.zeros(n, bool)
        #: Flow temperature the control aimed at in the last step [°C] (the curve's, or the
        #: built-in curve's node target as a steady flow).
        self.flow_target_c = np.full(n, np.nan)

    def set_flow_curve(self, flow_a_c: Array, flow_b_c: Array, setpoint_ref_c: Array,
                       lag_k_per_w: Array) -> None:
        """Run a two-point flow curve (:mod:`.flow_curve`) instead of the built-in one where
        ``flow_a_c`` is finite (flows at −15 and +15 °C outdoor [°C], the setpoint they are set
        for [°C], the flow's lag over the node per W [K/W]); NaN keeps the built-in curve."""
        n = self.k_w.shape[0]

        def b(v):
            return np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()

        fa, fb, ref, lag = b(flow_a_c), b(flow_b_c), b(setpoint_ref_c), b(lag_k_per_w)
        self._has_curve = np.isfinite(fa) & np.isfinite(fb)
        self._curve = (fa, fb, ref, lag) if self._has_curve.any() else None
        # A house back on its built-in curve aims at that curve's target from its next step
        # (read from the step's water target): without this its last two-point flow would
        # stand for ever, as the step only updates the flow target while a curve runs.
        self.flow_target_c = np.where(self._has_curve, self.flow_target_c, np.nan)

    @property
    def flow_curve_set(self) -> NDArray[np.bool_]:
        """Houses running a two-point flow curve (:meth:`set_flow_curve`)."""
        return self._has_curve.copy()

    def p_max_w(self, t_out_c: Array) -> Array:
        """Capacity at outdoor ``t_out_c`` [W]."""
        return self.nominal_w * capacity_factor(self.cap_per_k, t_out_c)

    def target_water_c(self, setpoint_c: Array, t_air_sensed: Array,
                       t_out_sensed: Array) -> Array:
        """Heating curve with room influence [°C]."""
        load = self._hlc_per_k * np.maximum(setpoint_c - t_out_sensed, 0.0)
        curve = setpoint_c + self.curve_gain * load ** self._inv_n
        room = self.room_k * (setpoint_c - t_air_sensed)
        target = curve + room
        if self._curve is not None:
            fa, fb, ref, lag = self._curve
            flow = curve_flow_c(fa, fb, ref, setpoint_c, t_out_sensed) + room
            node = node_for_flow(flow, setpoint_c, self.k_w, self.n_exp, lag)
            target = np.where(self._has_curve, node, target)
            self.flow_target_c = np.where(self._has_curve, flow, np.nan)
        return np.minimum(np.maximum(target, WATER_MIN_C), self.water_max_c)

    def steady_flow_c(self, node_c: Array, setpoint_c: Array, lag_k_per_w: Array) -> Array:
        """Steady flow temperature of a node target [°C] (:func:`.flow_curve.flow_for_node`)."""
        return flow_for_node(node_c, setpoint_c, self.k_w, self.n_exp, lag_k_per_w)

    def step(self, st: ControlState, dt: float, enabled: NDArray[np.bool_], setpoint_c: Array,
             t_air_sensed: Array, t_out_sensed: Array, t_out_c: Array, t_water_c: Array,
             t_air_c: Array, dhw: NDArray[np.bool_],
             force_defrost: NDArray[np.bool_] | None) -> ControlOutput:
        """Decide this step's output and advance ``st`` by ``dt`` seconds.

        ``setpoint_c`` must be finite where ``enabled`` is False (any value).
        """
        target = self.target_water_c(setpoint_c, t_air_sensed, t_out_sensed)
        space_on = enabled & ~dhw
        if self._any_thermostat:
            band = self._half_band
            st.calling = np.where(st.calling, t_air_sensed < setpoint_c + band,
                                  t_air_sensed < setpoint_c - band)
            demand = space_on & (self._not_thermostat | st.calling)
        else:
            demand = space_on
        d = np.maximum(target - t_air_c, 0.0)
        p_req = self.k_w * d ** self.n_exp + self._c_per_tau * (target - t_water_c)
        p_req = np.maximum(p_req, 0.0) * demand
        p_max = self.p_max_w(t_out_c)
        p_min = np.minimum(self._p_min_nom, p_max)
        low = p_req < p_min
        running0 = st.running
        start = (demand & (st.timer_s >= self.min_off) & ~running0
                 & (~low | ((p_req > 0) & (t_water_c < target - self.hyst_w))))
        stop = running0 & (~space_on | ((st.timer_s >= self.min_on) & (
            ~demand | (low & (t_water_c > target + self.hyst_w)))))
        running = (running0 | start) & ~stop
        cmd = np.minimum(np.maximum(p_req, p_min), p_max)
        prev = st.power_w * ~start
        power = np.minimum(cmd, np.maximum(prev, 0.0) + self.ramp_w_per_s * dt) * running
        st.timer_s = np.where(start | stop, dt, st.timer_s + dt)
        st.running = running
        if self._any_defrost or force_defrost is not None:
            # Reverse cycle after enough run time in the frost band, never in the first
            # minutes after a start (timer_s is the time since the last start while running).
            frosty = (t_out_c >= DEFROST_RANGE_C[0]) & (t_out_c <= DEFROST_RANGE_C[1])
            due = (self.defrost_on & frosty & (st.run_since_defrost_s >= self.defrost_interval)
                   & (st.timer_s >= self.defrost_min_run))
            if force_defrost is not None:
                due = due | force_defrost
            begin = running & (st.defrost_left_s <= 0) & due
            if not begin.any() and not st.defrost_left_s.any():
                # Nobody defrosting or starting to: only the run-time counters move.
                st.run_since_defrost_s = st.run_since_defrost_s + dt * running
                st.power_w = power
                return ControlOutput(power, running | dhw, self._no, target, p_max, demand)
            left = np.where(begin, self.defrost_duration, st.defrost_left_s) * running
            defrosting = left > 0
            st.power_w = np.where(defrosting, st.power_w, power)
            power = np.where(defrosting, -self.defrost_w, power)
            st.run_since_defrost_s = np.where(begin, 0.0, st.run_since_defrost_s
                                              + dt * (running & ~defrosting))
            st.defrost_left_s = np.maximum(left - dt, 0.0)
        else:
            defrosting = self._no
            st.power_w = power
        return ControlOutput(power, running | dhw, defrosting, target, p_max, demand)


def cop(t_supply_c: Array, t_out_c: Array, eta: Array) -> Array:
    """COP = η·T_sup/(T_sup − T_out + 5 K) in kelvin, clipped to 1.5…6.5 [-]."""
    t_hot = t_supply_c + 273.15
    lift = np.maximum(t_hot - (t_out_c + 273.15) + 5.0, 1.0)
    return np.clip(eta * t_hot / lift, 1.5, 6.5)
