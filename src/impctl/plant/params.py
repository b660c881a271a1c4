"""Parameters of the realistic plant: one frozen dataclass per physical concept.

Every field is a float (one house) or an array over houses, in the unit its name or its docstring
gives. Each class lists its documented range in ``RANGES`` (name → (low, high)); the population
draws every field uniformly from that range (:func:`impctl.plant.sample_params`) and the house
TOML sections are checked against it. Sources: ``/work/shared/reference/real-houses.md`` (cited
as RH §n); "[own choice]" marks a value the reference does not give.

Defaults describe a typical heat-pump house (radiators, modulating weather-compensated air-source
heat pump, two sleepers, a 0.1 K room sensor). :meth:`PlantParams.ideal` switches every effect
off: the plant then reproduces ISO 13790 Annex C.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any, ClassVar

import numpy as np

from ..errors import InputError

#: Emitter kinds (field ``Emitter.kind``: 0 = radiators, 1 = underfloor heating).
RADIATORS, UNDERFLOOR = 0, 1
#: Heat-pump control modes (field ``HeatPump.control``).
CONTROL_CURVE, CONTROL_THERMOSTAT, CONTROL_IDEAL = 0, 1, 2


class _Ranged:
    """Mixin: range checks of every field against ``RANGES`` (InputError naming the key)."""

    RANGES: ClassVar[dict[str, tuple[float, float]]] = {}
    SECTION: ClassVar[str] = ""
    #: Coded fields (kinds, modes, switches): whole numbers only.
    CODES: ClassVar[frozenset[str]] = frozenset()

    def __post_init__(self) -> None:
        for f in fields(self):  # type: ignore[arg-type]
            lo, hi = self.RANGES[f.name]
            v = np.asarray(getattr(self, f.name), dtype=float)
            place = f"key '{self.SECTION}.{f.name}'"
            if not np.all(np.isfinite(v)) or not np.all((v >= lo) & (v <= hi)):
                raise InputError(f"must lie in {lo:g}–{hi:g}", place=place)
            if f.name in self.CODES and not np.all(v == np.round(v)):
                raise InputError(f"must be a whole number {lo:g}–{hi:g}", place=place)


@dataclass(frozen=True)
class Capacities(_Ranged):
    """Air and furniture heat capacity taken out of the ISO C_m (RH §1).

    Parameters
    ----------
    air_j_per_m3k : float, default 1200
        ρ·c of indoor air [J/(m³K)] (ISO 13790 ρ_a·c_a); × the house volume. 0 = massless air.
    furniture_j_per_m2k : float, default 20000
        Furniture and contents [J/(m²K) of floor]; RH §1: 10–30 kJ/(m²K) (ISO 52016 10 kJ,
        Japanese code 12.6 kJ/(m³K) ≈ 31 kJ/(m²K)). Range 0–31000.
    furniture_rate_per_s : float, default 0.00022
        Furniture–air conductance per furniture capacity [1/s]: G = rate·C_fur, time constant
        1/rate ≈ 76 min (RH §1, Japanese code). Range 1e-4–1e-3.
    max_share : float, default 0.6
        Cap on (air + furniture + emitter) / C_m [-] [own choice]: above it all three are scaled
        down so the mass keeps ≥ 40 % of C_m. Range 0–0.8.
    """

    SECTION: ClassVar[str] = "plant.capacities"
    RANGES: ClassVar[dict[str, tuple[float, float]]] = {
        "air_j_per_m3k": (0.0, 1200.0), "furniture_j_per_m2k": (0.0, 31000.0),
        "furniture_rate_per_s": (1e-4, 1e-3), "max_share": (0.0, 0.8)}

    air_j_per_m3k: Any = 1200.0
    furniture_j_per_m2k: Any = 20000.0
    furniture_rate_per_s: Any = 0.00022
    max_share: Any = 0.6


@dataclass(frozen=True)
class Emitter(_Ranged):
    """Hydronic emitter: capacity and output K·(θ_w − θ_air)^n into the air node (RH §2).

    The emitter is sized so that at the design outdoor temperature it delivers the house's
    HLC·(20 °C − θ_design) at the design mean water temperature.

    Parameters
    ----------
    kind : 0 radiators, 1 underfloor
    exponent : float, default 1.3
        n [-]; radiators 1.3 ± 0.1 (EN 442), underfloor ≈ 1.1 (RH §2). Range 1.0–1.4.
    design_water_c : float, default 45
        Mean water temperature at design conditions [°C]; heat-pump radiators 40–55, underfloor
        28–38 (RH §2: UFH water 25–45 °C) [ranges own choice]. Range 28–55. Sizes the radiators;
        for underfloor (sized by its floor area) it sets only the water-to-screed gap.
    design_t_out_c : float, default −10
        Design outdoor temperature [°C] [own choice]. Range −20…−5.
    radiator_j_per_k_per_w : float, default 36
        Radiator water + steel per EN 442 rated watt (ΔT 50 K) [J/K per W] (RH §2: ≈ 36 kJ/K
        per kW). Range 0–50 (0 = massless emitter, the ideal limit).
    screed_j_per_m2k : float, default 130000
        Underfloor screed [J/(m²K)] (RH §2: 130–250 kJ/(m²K), 65 mm screed to 125 mm slab).
    ufh_area_share : float, default 0.6
        Floor share with underfloor loops [-] [own choice]. Range 0.3–1. Output
        8.92·Δθ^n W per heated m² (RH §2).
    buffer_l_per_kw : float, default 0
        Buffer tank [L per kW of heat-pump nominal] (RH §3: 10–20 L/kW when fitted). Range 0–20.
    """

    SECTION: ClassVar[str] = "plant.emitter"
    CODES: ClassVar[frozenset[str]] = frozenset({"kind"})
    RANGES: ClassVar[dict[str, tuple[float, float]]] = {
        "kind": (0, 1), "exponent": (1.0, 1.4), "design_water_c": (28.0, 55.0),
        "design_t_out_c": (-20.0, -5.0), "radiator_j_per_k_per_w": (0.0, 50.0),
        "screed_j_per_m2k": (130000.0, 250000.0), "ufh_area_share": (0.3, 1.0),
        "buffer_l_per_kw": (0.0, 20.0)}

    kind: Any = RADIATORS
    exponent: Any = 1.3
    design_water_c: Any = 45.0
    design_t_out_c: Any = -10.0
    radiator_j_per_k_per_w: Any = 36.0
    screed_j_per_m2k: Any = 130000.0
    ufh_area_share: Any = 0.6
    buffer_l_per_kw: Any = 0.0

    @classmethod
    def underfloor(cls, **kw: Any) -> Emitter:
        """Typical underfloor heating: n = 1.1, 33 °C mean water, 65 mm screed (RH §2)."""
        return cls(**{"kind": UNDERFLOOR, "exponent": 1.1, "design_water_c": 33.0, **kw})


@dataclass(frozen=True)
class HeatPump(_Ranged):
    """Air-source heat pump and its control (RH §3).

    Parameters
    ----------
    control : 0 weather curve with room influence, 1 room thermostat (on/off by the sensed
        room temperature), 2 ideal (the Annex C demand at the air node, no limits but the
        house's ``max_heating_power``).
    sizing : float, default 1.2
        Integrated capacity at the design outdoor temperature / design heat load
        HLC·(20 − θ_design) [-] [own choice]. Range 0.9–1.8. Installers size on the capacity
        at the design point; below +5 °C rated capacities are integrated over defrost cycles
        (EN 14511), so the nominal (+7 °C) output is set such that the mean output at
        θ_design, defrosts included, is ``sizing`` × the design load
        (:func:`impctl.plant.hydronics.heatpump.nominal_output_w`).
    min_modulation : float, default 0.4
        Minimum output / nominal [-]; RH §3: 0.3–0.5 for inverters; 1.0 = on/off unit.
        Range 0.3–1.
    capacity_per_k : float, default 0.015
        Capacity change per K of outdoor temperature around +7 °C [1/K] [own choice, typical
        air-source data, unverified]. Range 0–0.04 (fixed-speed units ≈ 0.025–0.04; inverters,
        which speed up in the cold, less). The default was 0.025 until the heat pump was sized
        on its design point; with 0.025 and a 0.5 defrost draw the default unit came out at
        2.8 × the design load at +7 °C and could not modulate at any temperature.
    curve_gain : float, default 1.1
        Heating curve / exactly matched curve [-] (installers set curves high) [own choice,
        consistent with the field: EN 12831 calculations over-estimated the measured heat
        loss of 59 % of 56 UK homes, by 35 % on mean absolute difference (Build Test
        Solutions, Veritherm, Elmhurst Energy 2024); a curve set for f × the true heat loss
        runs at f^(1/n) × the matched curve's excess: 1.11–1.26 for f = 1.15–1.35, n = 1.3].
        Range 0.9–1.3.
    room_influence_k_per_k : float, default 2
        Water-temperature shift per K of room error [K/K] [own choice]. Range 0–5.
    water_hysteresis_k : float, default 3
        Water temperature above / below target that stops / starts the compressor when the
        demand is below the minimum output [K] [own choice]. Range 1–6.
    room_hysteresis_k : float, default 0.5
        Room thermostat band (total) [K] [own choice]. Range 0.2–1.
    min_on_s, min_off_s : float, default 600, 600
        Anti-short-cycle timers [s]; RH §3: cycles ≥ 5–15 min, 300 s minimum runtime.
        Range 300–1200.
    ramp_s : float, default 300
        Time from 0 to nominal output at start [s] (loop transit, condenser warm-up; RH §3).
        Range 60–600.
    control_tau_s : float, default 600
        Time in which the controller drives the water to its target [s] [own choice].
        Range 120–1800.
    defrost : 0/1, default 1
        Defrost cycles at outdoor −12…+5 °C (RH §3 and §6).
    defrost_interval_s : float, default 2700
        Compressor run time between defrosts [s]; RH §3: ≥ 35 min, timers 45/90 min.
        Range 2100–5400.
    defrost_min_run_s : float, default 2100
        Minimum compressor run since its last start before a defrost [s]; RH §3: the first
        defrost comes after ≥ ~35 min of run (a unit restarted after a stop does not defrost
        in its first minutes, whatever run time it had before). Range 1200–3600.
    defrost_duration_s : float, default 420
        [s]; RH §3: 5–10 min. Range 300–600.
    defrost_draw : float, default 0.3
        Heat drawn from the water during defrost / nominal output [-] [own choice]. Range 0.2–1.
        With the default interval and duration a unit running flat out at −10 °C loses 19 % of
        its capacity to defrosts (RH §3: field 10 % of energy over a season, lab 2–8 %); the
        default was 0.5 (25 %) before the design-point sizing.
    cop_eta : float, default 0.45
        Fraction of the Carnot COP [-] (as the simulator's plant). Range 0.3–0.6.
    flow_w_per_k : float, default 0
        Loop flow ṁ·c_p [W/K]; 0 = sized for a 5 K supply–return spread at nominal output
        [own choice]. Range 0–5000.
    standby_w : float, default 20
        Electrical draw while the system is on [W]. Range 0–100.
    """

    SECTION: ClassVar[str] = "plant.heat_pump"
    CODES: ClassVar[frozenset[str]] = frozenset({"control", "defrost"})
    RANGES: ClassVar[dict[str, tuple[float, float]]] = {
        "control": (0, 2), "sizing": (0.9, 1.8), "min_modulation": (0.3, 1.0),
        "capacity_per_k": (0.0, 0.04), "curve_gain": (0.9, 1.3),
        "room_influence_k_per_k": (0.0, 5.0), "water_hysteresis_k": (1.0, 6.0),
        "room_hysteresis_k": (0.2, 1.0), "min_on_s": (300.0, 1200.0),
        "min_off_s": (300.0, 1200.0), "ramp_s": (60.0, 600.0), "control_tau_s": (120.0, 1800.0),
        "defrost": (0, 1), "defrost_interval_s": (2100.0, 5400.0),
        "defrost_min_run_s": (1200.0, 3600.0),
        "defrost_duration_s": (300.0, 600.0), "defrost_draw": (0.2, 1.0),
        "cop_eta": (0.3, 0.6), "flow_w_per_k": (0.0, 5000.0), "standby_w": (0.0, 100.0)}

    control: Any = CONTROL_CURVE
    sizing: Any = 1.2
    min_modulation: Any = 0.4
    capacity_per_k: Any = 0.015
    curve_gain: Any = 1.1
    room_influence_k_per_k: Any = 2.0
    water_hysteresis_k: Any = 3.0
    room_hysteresis_k: Any = 0.5
    min_on_s: Any = 600.0
    min_off_s: Any = 600.0
    ramp_s: Any = 300.0
    control_tau_s: Any = 600.0
    defrost: Any = 1
    defrost_interval_s: Any = 2700.0
    defrost_duration_s: Any = 420.0
    defrost_draw: Any = 0.3
    cop_eta: Any = 0.45
    flow_w_per_k: Any = 0.0
    standby_w: Any = 20.0
    defrost_min_run_s: Any = 2100.0


@dataclass(frozen=True)
class Gains(_Ranged):
    """Internal and solar gains the fit does not know (RH §4).

    Parameters
    ----------
    night_w : float, default 230
        Internal gains 22:00–07:00 [W]: ≈ 70–80 W per sleeper + 80–180 W base load; RH §4
        total 100–400 W.
    day_w : float, default 400
        Internal gains 07:00–22:00 [W] [own choice]. Range 100–800.
    drift_w : float, default 30
        SD of a slow random walk on the gains (per √h, clipped at ±100 %) [W] [own choice].
        Range 0–80.
    solar_peak_w : float, default 800
        Transmitted solar gains at solar noon on a clear winter day [W] [own choice; RH §4:
        stored afternoon solar matters]. Range 0–3000; each day draws a cloudiness in 0–1.
    """

    SECTION: ClassVar[str] = "plant.gains"
    RANGES: ClassVar[dict[str, tuple[float, float]]] = {
        "night_w": (100.0, 400.0), "day_w": (100.0, 800.0), "drift_w": (0.0, 80.0),
        "solar_peak_w": (0.0, 3000.0)}

    night_w: Any = 230.0
    day_w: Any = 400.0
    drift_w: Any = 30.0
    solar_peak_w: Any = 800.0


@dataclass(frozen=True)
class Sensors(_Ranged):
    """What the gateway reads (RH §5).

    Parameters
    ----------
    t_air_noise_k : float, default 0.05
        SD of the room-sensor noise [K] [own choice]. Range 0–0.3.
    t_air_quantum_k : float, default 0.1
        Room-sensor resolution [K]; 0.1 common, some room units 0.5 (RH §5). Range 0–0.5.
    t_air_lag_s : float, default 600
        Sensor-housing time constant [s]; RH §5: 5–15 min [unverified]. Range 0–900.
    t_air_offset_k : float, default 0
        Placement / calibration offset [K]; RH §5: ±0.2–1 K. Range −1…1.
    t_out_noise_k : float, default 0.2
        SD of the outdoor-sensor noise [K] [own choice]. Range 0–0.5.
    t_out_offset_k : float, default 0
        Outdoor-sensor bias (sun, wall) [K] (RH §5). Range −2…2.
    meter_gain_error : float, default 0
        Systematic relative error of the heat meter [-]; RH §5: class 2/3 MPE ±2…5 %.
        Range −0.05…0.05.
    meter_noise : float, default 0.02
        SD of the per-sample relative meter error [-] [own choice]. Range 0–0.1.
    meter_positive_only : 0/1, default 1
        The meter integrates positive heat only (defrost reads 0) (RH §3 [unverified]).
    """

    SECTION: ClassVar[str] = "plant.sensors"
    CODES: ClassVar[frozenset[str]] = frozenset({"meter_positive_only"})
    RANGES: ClassVar[dict[str, tuple[float, float]]] = {
        "t_air_noise_k": (0.0, 0.3), "t_air_quantum_k": (0.0, 0.5), "t_air_lag_s": (0.0, 900.0),
        "t_air_offset_k": (-1.0, 1.0), "t_out_noise_k": (0.0, 0.5),
        "t_out_offset_k": (-2.0, 2.0), "meter_gain_error": (-0.05, 0.05),
        "meter_noise": (0.0, 0.1), "meter_positive_only": (0, 1)}

    t_air_noise_k: Any = 0.05
    t_air_quantum_k: Any = 0.1
    t_air_lag_s: Any = 600.0
    t_air_offset_k: Any = 0.0
    t_out_noise_k: Any = 0.2
    t_out_offset_k: Any = 0.0
    meter_gain_error: Any = 0.0
    meter_noise: Any = 0.02
    meter_positive_only: Any = 1


@dataclass(frozen=True)
class PlantParams:
    """All realism options of a plant (each section one dataclass; fields float or array).

    Build the ideal limit with :meth:`ideal`; randomised populations with
    :func:`impctl.plant.sample_params`.
    """

    capacities: Capacities = field(default_factory=Capacities)
    emitter: Emitter = field(default_factory=Emitter)
    heat_pump: HeatPump = field(default_factory=HeatPump)
    gains: Gains = field(default_factory=Gains)
    sensors: Sensors = field(default_factory=Sensors)

    @classmethod
    def ideal(cls) -> PlantParams:
        """No air/furniture/emitter capacity, ideal control, perfect sensors: ISO Annex C.

        Gains are *not* switched off here; the batch simulation takes gains as inputs.
        """
        return cls(
            capacities=Capacities(air_j_per_m3k=0.0, furniture_j_per_m2k=0.0),
            emitter=Emitter(radiator_j_per_k_per_w=0.0, buffer_l_per_kw=0.0),
            heat_pump=HeatPump(control=CONTROL_IDEAL, defrost=0),
            sensors=Sensors(t_air_noise_k=0.0, t_air_quantum_k=0.0, t_air_lag_s=0.0,
                            t_out_noise_k=0.0, meter_noise=0.0, meter_positive_only=0),
        )

    def section(self, name: str) -> Any:
        """One section by its field name (``"emitter"`` …)."""
        return getattr(self, name)

    def with_section(self, name: str, **values: Any) -> PlantParams:
        """A copy with some fields of one section replaced."""
        return replace(self, **{name: replace(getattr(self, name), **values)})

    def take(self, index: int) -> PlantParams:
        """The ``index``-th house of array-valued parameters, as floats."""
        def one(sec: Any) -> Any:
            return type(sec)(**{f.name: float(np.ravel(getattr(sec, f.name))[index]
                                              if np.ndim(getattr(sec, f.name)) else
                                              getattr(sec, f.name)) for f in fields(sec)})
        return PlantParams(**{f.name: one(getattr(self, f.name)) for f in fields(self)})


#: Section name → class, as in the house TOML (``[plant.<name>]``).
SECTIONS = {"capacities": Capacities, "emitter": Emitter, "heat_pump": HeatPump, "gains": Gains,
            "sensors": Sensors}
