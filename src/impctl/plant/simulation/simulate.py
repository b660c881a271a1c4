"""The realistic plant over time: batch (many houses, numpy) and step-wise (one house).

Both run the same :class:`PlantCore`: per step the controller decides the heat pump's output from
the sensors, the envelope + emitter network is solved (:mod:`impctl.plant.building.envelope`),
the sensors read the result. Units: °C, W, J, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...model import HouseParameters
from ..building.envelope import (
    CapacitySplit,
    Network,
    NodeState,
    Solver,
    split_capacity,
    steady_state,
)
from ..hydronics import emitter as em
from ..hydronics.heatpump import Controller, ControlState, cop, nominal_output_w
from ..instruments.sensors import SensorBank
from ..params import CONTROL_IDEAL, PlantParams

Array = NDArray[np.float64]


def _b(v, n: int) -> Array:
    return np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()


class PlantCore:
    """Constants and state of ``n`` houses on the realistic plant.

    Parameters
    ----------
    house : HouseParameters
        One house or many (arrays of length n).
    params : PlantParams
        Realism options (floats, or arrays over the same houses).
    seed : int or Generator
        Sensor noise.
    n : int, optional
        Number of houses when both house and params are scalar.
    """

    def __init__(self, house: HouseParameters, params: PlantParams,
                 seed: int | np.random.Generator = 0, n: int | None = None) -> None:
        n = n or house.n_houses or _n_of(params) or 1
        self.n = n
        self.house = house
        self.params = params
        net = house.network
        self.hlc = _b(net.hlc_w_per_k, n)
        self.floor_area = _b(net.floor_area_m2, n)
        e, hp, cap = params.emitter, params.heat_pump, params.capacities
        self.exponent = _b(e.exponent, n)
        self.k_w = _b(em.output_constant(self.hlc, e, self.floor_area), n)
        self.g_pipe = _b(em.pipe_conductance(self.k_w, self.hlc, e), n)
        self.nominal_w = _b(nominal_output_w(hp, em.design_load_w(self.hlc, e),
                                             e.design_t_out_c), n)
        want_em = _b(em.capacity_j_per_k(self.k_w, e, self.floor_area, self.nominal_w), n)
        volume = self.floor_area * _b(house.wall_height, n)
        self.split: CapacitySplit = split_capacity(
            house, _b(cap.air_j_per_m3k, n) * volume,
            _b(cap.furniture_j_per_m2k, n) * self.floor_area, want_em, _b(cap.max_share, n))
        self.split = CapacitySplit(*(_b(getattr(self.split, f.name), n)
                                     for f in fields(CapacitySplit)))
        self.c_em = self.split.emitter
        self.network = Network.build(house, self.split, _b(cap.furniture_rate_per_s, n), n)
        self.solver = Solver(self.network)
        self.controller = Controller(hp, self.nominal_w, self.k_w, self.exponent, self.hlc,
                                     self.c_em, _b(em.node_design_c(self.k_w, self.hlc, e), n),
                                     n)
        self.ideal = _b(hp.control, n) == CONTROL_IDEAL
        self.any_ideal = bool(self.ideal.any())
        cap_house = _b(house.max_heating_power, n)
        self.ideal_max_w = np.where(np.isfinite(cap_house), cap_house, np.inf)
        flow = _b(hp.flow_w_per_k, n)
        self.flow_w_per_k = np.where(flow > 0, flow, self.nominal_w / 5.0)
        self.cop_eta = _b(hp.cop_eta, n)
        self.standby_w = _b(hp.standby_w, n)
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        self.sensors = SensorBank(params.sensors, n, rng)
        self.state = NodeState(*(np.full(n, 20.0) for _ in range(5)))
        self.control = ControlState.idle(n)
        self.sensed_air = np.full(n, 20.0)
        self.sensed_out = np.full(n, 0.0)

    @property
    def flow_lag_k_per_w(self) -> Array:
        """How far the flow runs above the emitter node per W of output [K/W]:
        1/G_pipe + 1/(2·ṁc)."""
        return 1.0 / self.g_pipe + 0.5 / self.flow_w_per_k

    def set_flow_curve(self, flow_a_c: ArrayLike, flow_b_c: ArrayLike,
                       setpoint_ref_c: ArrayLike) -> None:
        """Let the heat pumps run a two-point flow curve: flow temperatures [°C] at −15 and
        +15 °C outdoor, set for ``setpoint_ref_c`` [°C]; NaN keeps a house's built-in curve
        (:mod:`impctl.plant.hydronics.flow_curve`)."""
        self.controller.set_flow_curve(flow_a_c, flow_b_c, setpoint_ref_c,
                                       self.flow_lag_k_per_w)

    # --- initial state -------------------------------------------------------------------
    def start_steady(self, t_air_c: ArrayLike, t_out_c: ArrayLike,
                     t_m_c: ArrayLike | None = None) -> None:
        """Steady state holding ``t_air_c`` at ``t_out_c`` (heat from the emitter, no gains);
        ``t_m_c`` overrides the mass temperature [°C]."""
        n = self.n
        ss = steady_state(self.house, _b(t_air_c, n), _b(t_out_c, n))
        air, mass = _b(ss["air"], n), _b(ss["mass"], n)
        power = np.maximum(_b(ss["power_w"], n), 0.0)
        water = air + (power / self.k_w) ** (1.0 / self.exponent)
        if t_m_c is not None:
            mass = _b(t_m_c, n)
        self.state = NodeState(air=air, furniture=air.copy(), mass=mass, water=water,
                               surface=_b(ss["surface"], n))
        self.control = ControlState.idle(n)
        self.sensors.reset(air)
        self.sensed_air = air.copy()
        self.sensed_out = _b(t_out_c, n)

    # --- one step ------------------------------------------------------------------------
    def step(self, dt: float, t_out_c: Array, setpoint_c: Array, enabled: NDArray[np.bool_],
             phi_int: Array, phi_sol: Array, dhw: NDArray[np.bool_],
             force_defrost: NDArray[np.bool_] | None = None,
             want: frozenset[str] | None = None) -> dict[str, Array]:
        """Advance all houses by ``dt`` seconds; returns this step's outputs (:data:`OUTPUTS`,
        or only those in ``want``). ``setpoint_c`` must be finite (any value where not
        ``enabled``)."""
        st = self.state
        g_em = em.secant_conductance(self.k_w, self.exponent, st.water, st.air)
        air_free, k_air = self.solver.prepare(st, dt, t_out_c, phi_int, phi_sol, self.c_em, g_em)
        ctl = self.controller.step(self.control, dt, enabled, setpoint_c, self.sensed_air,
                                   self.sensed_out, t_out_c, st.water, st.air, dhw,
                                   force_defrost)
        power = ctl.power_w
        comp = ctl.compressor_on
        demand = ctl.demand
        if self.any_ideal:
            # Annex C C.13: θ_air is affine in P, so the setpoint power is exact.
            need = np.where(enabled & ~dhw, (setpoint_c - air_free) / k_air, 0.0)
            ideal_p = np.minimum(np.maximum(need, 0.0), self.ideal_max_w)
            power = np.where(self.ideal, ideal_p, power)
            comp = np.where(self.ideal, power > 0, comp)
            demand = np.where(self.ideal, power > 0, demand)
        sol = self.solver.finish(st, air_free, k_air, power)
        self.sensed_air, self.sensed_out, meter = self.sensors.read(dt, sol.air, t_out_c, power)
        out = {
            "t_air_c": sol.air, "t_air_sensed_c": self.sensed_air, "t_out_c": t_out_c,
            "t_out_sensed_c": self.sensed_out, "t_mass_c": sol.mass, "t_surface_c": sol.surface,
            "t_furniture_c": sol.furniture, "t_water_c": sol.water,
            "t_water_target_c": ctl.target_water_c, "heat_pump_w": power,
            "emitter_w": sol.emitter_w, "heat_meter_w": meter, "compressor_on": comp,
            "defrost": ctl.defrost, "dhw": dhw, "heat_demand": demand,
        }
        if want is None or "loss_w" in want or "gains_w" in want:
            out["loss_w"], out["gains_w"] = sol.loss_w, sol.gains_w
        if want is None or not want.isdisjoint(_HYDRAULIC):
            dhw_w = self.nominal_w * dhw
            water = sol.water + np.maximum(power, 0.0) / self.g_pipe
            half = power / (2.0 * self.flow_w_per_k)
            t_hot = np.where(dhw, 50.0, water + half)
            c = cop(t_hot, t_out_c, self.cop_eta)
            out.update({
                "t_supply_c": water + half, "t_return_c": water - half, "dhw_w": dhw_w,
                "electric_w": (np.abs(power) + dhw_w) / c * comp + self.standby_w,
                "pump_on": enabled | comp,
            })
        return out


_HYDRAULIC = frozenset({"t_supply_c", "t_return_c", "dhw_w", "electric_w", "pump_on"})


#: Output names of a step (units in the names; booleans for compressor/pump/defrost/dhw).
OUTPUTS = ("t_air_c", "t_air_sensed_c", "t_out_c", "t_out_sensed_c", "t_mass_c", "t_surface_c",
           "t_furniture_c", "t_water_c", "t_supply_c", "t_return_c", "t_water_target_c",
           "heat_pump_w", "emitter_w", "heat_meter_w", "dhw_w", "electric_w", "compressor_on",
           "pump_on", "defrost", "dhw", "loss_w", "gains_w", "heat_demand")


def _n_of(params: PlantParams) -> int | None:
    sizes = [np.size(getattr(sec, f.name)) for sec in (getattr(params, s.name)
                                                       for s in fields(params))
             for f in fields(sec)]
    big = [s for s in sizes if s > 1]
    return max(big) if big else None


@dataclass(frozen=True)
class PlantRun:
    """Result of :func:`simulate_plant`: each output (:data:`OUTPUTS`) of shape
    (n_records, n_houses) in ``outputs``; ``time_s`` (n_records,) the end of each recorded step
    since the start [s]; ``split`` the capacity split."""

    time_s: Array
    outputs: dict[str, NDArray]
    split: CapacitySplit

    def __getitem__(self, name: str) -> NDArray:
        return self.outputs[name]


def _inputs(name: str, value: ArrayLike | None, n_steps: int | None, n: int,
            default: float) -> NDArray:
    arr = np.asarray(default if value is None else value, dtype=float)
    if arr.ndim == 0:
        if n_steps is None:
            raise ValueError(f"{name}: cannot infer the number of steps from a scalar")
        return np.broadcast_to(arr, (n_steps, n))
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[1] not in (1, n) or (n_steps and arr.shape[0] != n_steps):
        raise ValueError(f"{name}: shape {np.shape(value)} fits neither (n_steps,) nor "
                         f"(n_steps, {n})")
    return np.broadcast_to(arr, (arr.shape[0], n))


def simulate_plant(
    house: HouseParameters,
    params: PlantParams,
    t_out_c: ArrayLike,
    dt_s: float,
    *,
    setpoint_c: ArrayLike | None = None,
    internal_gains_w: ArrayLike = 0.0,
    solar_gains_w: ArrayLike = 0.0,
    dhw: ArrayLike | None = None,
    t_init_c: ArrayLike = 20.0,
    t_m_init_c: ArrayLike | None = None,
    seed: int | np.random.Generator = 0,
    record_every: int = 1,
    outputs: tuple[str, ...] = OUTPUTS,
    core: PlantCore | None = None,
) -> PlantRun:
    """Simulate many houses on the realistic plant, one Python loop over time steps.

    Parameters
    ----------
    house : HouseParameters
        One house or many (arrays over n houses).
    params : PlantParams
        Realism options, floats or arrays over the same houses.
    t_out_c : array (n_steps,) or (n_steps, n)
        Outdoor temperature per step [°C].
    dt_s : float
        Time step [s].
    setpoint_c : array, optional
        Room setpoint per step [°C]; NaN = space heating off (loop off). Default: off.
    internal_gains_w, solar_gains_w : float or array
        Φ_int and transmitted Φ_sol [W] (:mod:`impctl.plant.building.gains` builds realistic ones).
    dhw : bool array, optional
        Steps with a DHW charge (space heating paused).
    t_init_c, t_m_init_c : float or array (n,)
        Start from the steady state holding ``t_init_c`` at the first T_out [°C];
        ``t_m_init_c`` overrides the mass temperature [°C].
    seed : int or Generator
        Sensor noise.
    record_every : int
        Keep every k-th step (the last of each block of k).
    outputs : names to keep (:data:`OUTPUTS`).
    core : PlantCore, optional
        Continue from this core's state instead of a new steady start (``t_init_c`` ignored).

    Returns
    -------
    PlantRun
    """
    if not dt_s > 0:
        raise ValueError("dt_s must be > 0")
    if core is None:
        core = PlantCore(house, params, seed)
        t_e0 = np.asarray(t_out_c, dtype=float)
        t_e0 = t_e0[0] if t_e0.ndim else t_e0
        core.start_steady(t_init_c, t_e0, t_m_init_c)
    n = core.n
    te = _inputs("t_out_c", t_out_c, None, n, 0.0)
    n_steps = te.shape[0]
    sp = _inputs("setpoint_c", setpoint_c, n_steps, n, math.nan)
    phi_int = _inputs("internal_gains_w", internal_gains_w, n_steps, n, 0.0)
    phi_sol = _inputs("solar_gains_w", solar_gains_w, n_steps, n, 0.0)
    # Per-step rows, not whole (n_steps, n) arrays: a population run is n_steps × 900 houses,
    # and full-size temporaries cost more than the per-row work.
    no_dhw = np.zeros(n, bool)
    dhw_in = None if dhw is None else _inputs("dhw", dhw, n_steps, n, 0.0)
    want = frozenset(outputs)
    n_rec = n_steps // record_every
    keep = {k: np.empty((n_rec, n), dtype=bool if k in _BOOL else float) for k in outputs}
    dt = float(dt_s)
    for i in range(n_steps):
        sp_i = sp[i]
        enabled = ~np.isnan(sp_i)
        out = core.step(dt, te[i], np.where(enabled, sp_i, 20.0), enabled, phi_int[i],
                        phi_sol[i], no_dhw if dhw_in is None else dhw_in[i] > 0.5, None, want)
        if (i + 1) % record_every == 0 and (i + 1) // record_every <= n_rec:
            r = (i + 1) // record_every - 1
            for k in outputs:
                keep[k][r] = out[k]
    time_s = (np.arange(1, n_rec + 1) * record_every) * float(dt_s)
    return PlantRun(time_s, keep, core.split)


_BOOL = {"compressor_on", "pump_on", "defrost", "dhw", "heat_demand"}
