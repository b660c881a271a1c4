"""Random realism for a virtual population: every option drawn over its documented range.

Uniform draws over the ranges of :mod:`impctl.plant.params` except where a field is tied to
another (by emitter kind) or is a choice:

* emitter kind: underfloor with probability 0.4, else radiators (RH §2: ~60 % of heat-pump
  retrofits mainly on radiators; ~30 % of new homes with UFH [weak]);
* exponent: radiators 1.2–1.4, underfloor 1.0–1.2 (RH §2: 1.3 ± 0.1, ≈ 1.1);
  design mean water: radiators 40–55 °C, underfloor 28–38 °C;
* control: weather curve 0.7, room thermostat 0.3 [own choice];
* heat pump: on/off unit (min_modulation 1) with probability 0.3, else an inverter with
  min_modulation 0.3–0.5 (RH §3);
* buffer: none with probability 0.5, else 10–20 L/kW (RH §3);
* room sensor resolution: 0.5 K with probability 0.2, else 0.1 K (RH §5);
* heat-meter systematic error within ±5 % (class 3 MPE, RH §5);
* ``defrost_min_run_s`` over its range, drawn after everything else (so adding it changed no
  earlier draw);
* fixed: air ρc 1200 J/(m³K), max_share 0.6, defrost on (it acts only at −12…+5 °C),
  cop_eta 0.45, standby 20 W, flow sized for 5 K.

The same seed gives the same parameters.
"""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pandas as pd

from ..plant.params import (
    CONTROL_CURVE,
    CONTROL_THERMOSTAT,
    RADIATORS,
    UNDERFLOOR,
    Capacities,
    Emitter,
    Gains,
    HeatPump,
    PlantParams,
    Sensors,
)

#: Probabilities of the discrete choices (module docstring).
P_UNDERFLOOR = 0.4
P_THERMOSTAT = 0.3
P_ON_OFF = 0.3
P_BUFFER = 0.5
P_COARSE_SENSOR = 0.2


def sample_params(n: int, seed: int | np.random.SeedSequence = 0) -> PlantParams:
    """Draw the realism options of ``n`` houses (arrays of length n)."""
    rng = np.random.default_rng(seed if isinstance(seed, np.random.SeedSequence)
                                else np.random.SeedSequence([int(seed), 0x91A7]))

    def u(cls, name: str) -> np.ndarray:
        lo, hi = cls.RANGES[name]
        return rng.uniform(lo, hi, n)

    ufh = rng.random(n) < P_UNDERFLOOR
    kind = np.where(ufh, UNDERFLOOR, RADIATORS)
    emitter = Emitter(
        kind=kind,
        exponent=np.where(ufh, rng.uniform(1.0, 1.2, n), rng.uniform(1.2, 1.4, n)),
        design_water_c=np.where(ufh, rng.uniform(28.0, 38.0, n), rng.uniform(40.0, 55.0, n)),
        design_t_out_c=u(Emitter, "design_t_out_c"),
        radiator_j_per_k_per_w=rng.uniform(25.0, 50.0, n),
        screed_j_per_m2k=u(Emitter, "screed_j_per_m2k"),
        ufh_area_share=u(Emitter, "ufh_area_share"),
        buffer_l_per_kw=np.where(rng.random(n) < P_BUFFER, 0.0, rng.uniform(10.0, 20.0, n)),
    )
    on_off = rng.random(n) < P_ON_OFF
    heat_pump = HeatPump(
        control=np.where(rng.random(n) < P_THERMOSTAT, CONTROL_THERMOSTAT, CONTROL_CURVE),
        sizing=u(HeatPump, "sizing"),
        min_modulation=np.where(on_off, 1.0, rng.uniform(0.3, 0.5, n)),
        **{name: u(HeatPump, name) for name in (
            "capacity_per_k", "curve_gain", "room_influence_k_per_k", "water_hysteresis_k",
            "room_hysteresis_k", "min_on_s", "min_off_s", "ramp_s", "control_tau_s",
            "defrost_interval_s", "defrost_duration_s", "defrost_draw")},
    )
    capacities = Capacities(furniture_j_per_m2k=rng.uniform(10000.0, 31000.0, n),
                            furniture_rate_per_s=u(Capacities, "furniture_rate_per_s"))
    gains = Gains(**{f.name: u(Gains, f.name) for f in fields(Gains)})
    sensors = Sensors(
        t_air_noise_k=u(Sensors, "t_air_noise_k"),
        t_air_quantum_k=np.where(rng.random(n) < P_COARSE_SENSOR, 0.5, 0.1),
        t_air_lag_s=u(Sensors, "t_air_lag_s"),
        t_air_offset_k=u(Sensors, "t_air_offset_k"),
        t_out_noise_k=u(Sensors, "t_out_noise_k"),
        t_out_offset_k=u(Sensors, "t_out_offset_k"),
        meter_gain_error=u(Sensors, "meter_gain_error"),
        meter_noise=u(Sensors, "meter_noise"),
        meter_positive_only=np.ones(n),
    )
    # Drawn last so that adding it left every earlier draw (and so every house) unchanged.
    heat_pump = replace(heat_pump, defrost_min_run_s=u(HeatPump, "defrost_min_run_s"))
    return PlantParams(capacities, emitter, heat_pump, gains, sensors)


def params_table(params: PlantParams, n: int) -> pd.DataFrame:
    """One row per house, columns ``<section>.<field>`` (units as in :mod:`.params`)."""
    cols = {}
    for sec in fields(params):
        section = getattr(params, sec.name)
        for f in fields(section):
            cols[f"{sec.name}.{f.name}"] = np.broadcast_to(
                np.asarray(getattr(section, f.name), dtype=float), (n,))
    return pd.DataFrame(cols)


def params_from_table(table: pd.DataFrame) -> PlantParams:
    """Inverse of :func:`params_table`."""
    sections = {}
    for sec in fields(PlantParams):
        cls = sec.default_factory()  # type: ignore[misc]
        sections[sec.name] = type(cls)(**{
            f.name: table[f"{sec.name}.{f.name}"].to_numpy(dtype=float)
            for f in fields(cls)})
    return PlantParams(**sections)


def take_params(params: PlantParams, index: np.ndarray, n: int) -> PlantParams:
    """Houses ``index`` (integer array) of array-valued ``params`` over ``n`` houses."""
    return params_from_table(params_table(params, n).iloc[np.asarray(index)]
                             .reset_index(drop=True))
