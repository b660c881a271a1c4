"""Recorded rows from the realistic plant: what a gateway logs on a house's heated nights and
days, for the tests, the bench and the examples.

Each row is one sampling interval: temperatures are what the sensors read at its end (room and
outdoor sensors of the plant, rounded to 0.1 °C as the Kronoterm's registers are), the heat
the meter's mean over the interval, the electricity its mean, ``dhw`` the share of the
interval spent on hot water, ``defrost`` 1 when the heat pump defrosted in it. The flow target
is what the heat pump's curve asks for (:attr:`PlantCore.controller.flow_target_c` where a
two-point curve runs, else the steady flow of the built-in curve's water target).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

#: Plant outputs the rows are made of (:func:`impctl.plant.simulate_plant` ``outputs``).
SYNTH_OUTPUTS = ("t_air_c", "t_air_sensed_c", "t_out_sensed_c", "heat_meter_w", "heat_pump_w",
                 "electric_w", "t_supply_c", "t_return_c", "t_water_target_c", "defrost",
                 "dhw", "compressor_on")


def flow_target_c(run, core, setpoint_c: np.ndarray) -> np.ndarray:
    """The flow target of every step (n_steps, n) [°C]: the built-in curve's water target as
    its steady flow (:meth:`impctl.plant.hydronics.heatpump.Controller.steady_flow_c`)."""
    return core.controller.steady_flow_c(np.asarray(run["t_water_target_c"]),
                                         np.asarray(setpoint_c), core.flow_lag_k_per_w)


def rows_from_run(run, index: pd.DatetimeIndex, house: int, *, setpoint_c: np.ndarray,
                  flow_target: np.ndarray, sample_step_s: float, dt_s: float,
                  kind: str | np.ndarray = "owner", night: np.ndarray | None = None,
                  quantum_k: float = 0.1) -> pd.DataFrame:
    """The rows of house ``house`` of a plant run (module docstring).

    ``index``: the time at the end of each simulated step; ``setpoint_c``: (n_steps, n) or
    (n_steps,) [°C] (NaN: heating off); ``flow_target``: (n_steps, n) [°C]; ``kind`` per row
    or one for all; ``night``: a night id per step (kept in a ``night`` column).
    """
    stride = int(round(sample_step_s / dt_s))
    n = len(index) // stride
    last = np.arange(1, n + 1) * stride - 1

    def col(name):
        return np.asarray(run[name])[:, house] if np.ndim(run[name]) == 2 else np.asarray(
            run[name])

    def mean(x):
        return x[:n * stride].reshape(n, stride).mean(axis=1)

    def q(x):
        return np.round(np.round(x / quantum_k) * quantum_k, 3)

    sp = np.asarray(setpoint_c)
    sp = sp[:, house] if sp.ndim == 2 else sp
    ft = np.asarray(flow_target)
    ft = ft[:, house] if ft.ndim == 2 else ft
    frame = pd.DataFrame({
        "timestamp": index[last],
        "t_air": q(col("t_air_sensed_c")[last]),
        "t_out": q(col("t_out_sensed_c")[last]),
        "q_hc": np.round(mean(col("heat_meter_w")), 0),
        "setpoint": sp[last],
        "heating": np.isfinite(sp[last]).astype(int),
        "kind": kind if isinstance(kind, str) else np.asarray(kind)[last],
        "t_flow_c": q(col("t_supply_c")[last]),
        "t_return_c": q(col("t_return_c")[last]),
        "t_flow_target_c": q(ft[last]),
        "p_el_w": np.round(mean(col("electric_w")), 0),
        "dhw": np.round(mean(col("dhw").astype(float)), 3),
        "defrost": (mean(col("defrost").astype(float)) > 0).astype(int),
    })
    if night is not None:
        frame.insert(1, "night", np.asarray(night)[last])
    return frame


def owner_rows(house, params, days: float, *, seed: int = 0, setpoint_c: float = 21.0,
               start: str = "2026-12-01 00:00", tz: str = "Europe/Ljubljana",
               dt_s: float = 60.0, sample_step_s: float = 300.0, night_gain_w: float = 230.0,
               day_gain_w: float = 400.0) -> tuple[pd.DataFrame, object]:
    """``days`` of one house's owner days and nights on the realistic plant (built-in winter
    weather of ``seed``, the owner's setpoint day and night, internal gains ``night_gain_w``
    22:00–07:00 and ``day_gain_w`` else [W], no sun, no hot water): its recorded rows
    (timestamps as ISO 8601 text, as a CSV holds them) and the plant core (its truth)."""
    from ...plant import PlantCore, simulate_plant
    from ...weather import winter_weather

    weather = winter_weather(start, days=days + 1, step_s=3600, seed=seed, tz=tz)
    n_steps = int(round(days * 86400 / dt_s))
    index = pd.Timestamp(start, tz=tz) + pd.to_timedelta(dt_s * np.arange(1, n_steps + 1),
                                                         unit="s")
    t_out = np.interp((index - index[0]).total_seconds().to_numpy() + dt_s,
                      (weather.index - index[0]).total_seconds().to_numpy() + dt_s,
                      weather.to_numpy())
    hours = (index.hour + index.minute / 60.0).to_numpy()
    gains = np.where((hours >= 22) | (hours < 7), night_gain_w, day_gain_w)
    core = PlantCore(house, params, seed=seed, n=1)
    core.start_steady(setpoint_c, t_out[0])
    sp = np.full(n_steps, float(setpoint_c))
    run = simulate_plant(house, params, t_out, dt_s, setpoint_c=sp, internal_gains_w=gains,
                         outputs=SYNTH_OUTPUTS, core=core)
    rows = rows_from_run(run, index, 0, setpoint_c=sp,
                         flow_target=flow_target_c(run, core, sp[:, None]),
                         sample_step_s=sample_step_s, dt_s=dt_s)
    rows["timestamp"] = [t.isoformat() for t in rows["timestamp"]]
    return rows, core
