"""Vectorised comfort screen of constrained nights on the realistic plant (no Modbus).

All houses at once on :class:`impctl.plant.PlantCore` (one loop over time steps): a day at the
owner's setpoint, an hour's preheat at T_max, heating off; the controller's end rule (restore at
the first sample whose room reading is ≤ T_min) applied to what the room sensor shows (lag,
noise, resolution), sampled every ``interval_s`` at every sampling phase; then the heating is
back (the owner's setpoint and mode, with the heat pump's own anti-short-cycle timer, ramp and
emitter warm-up) and the lowest true air temperature until 3 h after the restore is the house's
result.

The floor is T_min − 0.3 K, or − 0.3 K below the lowest the owner's own heating lets the room go
(12 h at the owner's setpoint before the night), whichever is lower: an on/off heat pump with a
room thermostat, a 0.5 K sensor and defrosts swings the room by a kelvin or two on its own, and
the experiment is not to blame for that. The undershoot is measured in the room sensor's frame:
true T_air + the sensor's placement offset. The owner's setpoint, T_min and the comfort they
are used to are all on that sensor, so a constant offset moves them together; the sensor's lag,
noise and resolution, the sampling and the plant's inertia after the restore are what can take
the room below the floor, and they count.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from impctl.model import HouseParameters
from impctl.plant import PlantCore, PlantParams

#: Restore delay after the deciding sample: the write and its read-back [s].
LATENCY_S = 10.0
#: real-houses.md §3: the first defrost comes after ≥ ~35 min of run [s].
EARLIEST_DEFROST_S = 2100.0


@dataclass(frozen=True)
class ScreenResult:
    """Per house (arrays of length n)."""

    reaches_t_min: np.ndarray      # the sensor reaches T_min with the heating off
    hours_to_t_min: np.ndarray     # from switch-off to the latest restoring sample [h]
    lowest_c: np.ndarray           # lowest T_air (sensor frame) from switch-off to the end [°C]
    owner_low_c: np.ndarray        # lowest T_air over 12 h of the owner's own heating [°C]
    undershoot_k: np.ndarray       # min(T_min, owner_low) − lowest (≤ 0: never below) [K]
    drop_after_restore_k: np.ndarray  # air at the restore − lowest after it [K]
    early_defrost: np.ndarray      # a defrost within 35 min of the restart


def night_realism(realism: PlantParams) -> PlantParams:
    """The night's realism: the sampled options with steady gains (night level all day, no
    sun, no drift), so that the screen and the real simulator see the same house."""
    g = realism.gains
    return realism.with_section("gains", day_w=g.night_w, drift_w=np.zeros_like(
        np.asarray(g.night_w, float)), solar_peak_w=np.zeros_like(np.asarray(g.night_w, float)))


def end_rule(readings: np.ndarray, t_min_c: float, interval_s: float, anticipate_s: float,
             window_s: float, within_k: float = 1.0) -> np.ndarray:
    """Where the controller ends the night: readings (samples × houses) ≤ T_min, or (with
    ``anticipate_s`` > 0) the least-squares trend of the readings over ``window_s`` reaching
    T_min within ``anticipate_s`` (:func:`impctl.controller.plan.anticipated_end`, vectorised)."""
    hit = readings <= t_min_c
    if anticipate_s <= 0:
        return hit
    from impctl.controller.plan import MIN_TREND_SPAN_S

    m = int(round(window_s / interval_s)) + 1
    need = int(round(MIN_TREND_SPAN_S / interval_s)) + 1
    k = readings.shape[0]
    slope = np.zeros_like(readings)
    for i in range(need - 1, k):
        w = readings[max(0, i - m + 1): i + 1]
        t = np.arange(len(w), dtype=float) * interval_s
        t -= t.mean()
        slope[i] = (t @ (w - w.mean(axis=0))) / (t @ t)
    near = readings <= t_min_c + within_k
    return hit | (near & (readings + np.minimum(slope, 0.0) * anticipate_s <= t_min_c))


def holding_t_out_c(houses: HouseParameters, realism: PlantParams, t_hold_c: float,
                    margin: float = 1.15) -> np.ndarray:
    """Per house, the lowest outdoor temperature [°C] at which its heat pump still holds
    ``t_hold_c``: capacity, less what defrosts take in the frost band (the lost run time and the
    heat drawn from the water), ≥ ``margin`` × the load less the gains; from a grid of
    −25…+10 °C (+10 if it never does). Colder than that the owner's own heating falls behind,
    and a constrained night would measure the heat pump, not the experiment."""
    from impctl.plant.hydronics.heatpump import DEFROST_RANGE_C

    n = houses.n_houses or 1
    core = PlantCore(houses, realism, 0, n=n)
    hp = realism.heat_pump

    def per_house(v) -> np.ndarray:
        return np.broadcast_to(np.asarray(v, float), (n,))

    gains, hlc = per_house(realism.gains.night_w), per_house(houses.hlc_w_per_k)
    share = per_house(hp.defrost_duration_s) / (per_house(hp.defrost_duration_s)
                                                + per_house(hp.defrost_interval_s))
    draw = per_house(hp.defrost_draw) * core.nominal_w * share * (per_house(hp.defrost) > 0)
    grid = np.arange(-25.0, 10.01, 0.5)
    ok = []
    for t in grid:
        p_max = core.controller.p_max_w(np.full(n, t))
        if DEFROST_RANGE_C[0] <= t <= DEFROST_RANGE_C[1]:
            p_max = p_max * (1.0 - share * (per_house(hp.defrost) > 0)) - draw
        ok.append(p_max >= margin * hlc * (t_hold_c - t) - gains)
    ok = np.array(ok)
    return np.where(ok.any(axis=0), grid[np.argmax(ok, axis=0)], 10.0)


def screen(houses: HouseParameters, realism: PlantParams, t_out_c: np.ndarray, *,
           t_set_c: float, band_k: float, interval_s: float, dt_s: float = 20.0,
           window_h: float = 7.0, after_h: float = 3.0, seed: int = 0,
           anticipate_s: float = 0.0, slope_window_s: float = 1800.0,
           anticipate_within_k: float = 1.0) -> ScreenResult:
    """Screen ``n`` houses (arrays over houses); see the module docstring."""
    n = len(t_out_c)
    t_min, t_max = t_set_c - band_k, t_set_c + band_k
    realism = night_realism(realism)
    core = PlantCore(houses, realism, seed, n=n)
    core.start_steady(np.full(n, t_set_c), t_out_c)
    gains = np.broadcast_to(np.asarray(realism.gains.night_w, float), (n,)).copy()
    zero, off = np.zeros(n), np.zeros(n, bool)
    on = np.ones(n, bool)

    offset = np.broadcast_to(np.asarray(realism.sensors.t_air_offset_k, float), (n,))
    owner_low = np.full(n, np.inf)

    def run(steps: int, dt: float, setpoint: float, enabled, watch_from: int) -> None:
        nonlocal owner_low
        sp = np.full(n, setpoint)
        for i in range(steps):
            out = core.step(dt, t_out_c, sp, enabled, gains, zero, off,
                            want=frozenset({"t_air_c"}))
            if i >= watch_from:
                owner_low = np.minimum(owner_low, out["t_air_c"] + offset)

    # A day at the owner's setpoint (its second half shows how low the owner's own heating
    # lets the room go), then the preheat.
    run(int(86400 / 120), 120.0, t_set_c, on, int(43200 / 120))
    run(int(3600 / dt_s), dt_s, t_max, on, 10**9)
    at_switch_off = copy.deepcopy(core)
    sensed_at_switch_off = core.sensed_air.copy()

    # 1. Heating off all window: when does each sampling phase see T_min?
    steps = int(window_h * 3600 / dt_s)
    sensed = np.empty((steps, n))
    for i in range(steps):
        out = core.step(dt_s, t_out_c, np.full(n, t_set_c), off, gains, zero, off,
                        want=frozenset({"t_air_sensed_c"}))
        sensed[i] = out["t_air_sensed_c"]
    reading = np.round(sensed * 10.0) / 10.0            # the register's 0.1 K
    every = max(1, int(round(interval_s / dt_s)))
    restore = np.full(n, -1)
    for phase in range(every):
        hit = end_rule(reading[phase::every], t_min, interval_s, anticipate_s, slope_window_s,
                       anticipate_within_k)
        first = np.where(hit.any(axis=0), np.argmax(hit, axis=0) * every + phase, -1)
        restore = np.maximum(restore, first)
    # The controller does not switch off a house the preheat left within
    # NightPolicy.switch_off_min_k of T_min (preheat_short): its heating stays on.
    from impctl.controller.plan import NightPolicy

    at_start = np.round(sensed_at_switch_off * 10.0) / 10.0
    kept_on = at_start < t_min + NightPolicy().switch_off_min_k
    restore = np.where(kept_on, -1, restore)
    reaches = restore >= 0
    lag = int(np.ceil(LATENCY_S / dt_s))
    # A house that never reads T_min is restored at the window's end.
    restore_step = np.where(reaches, restore, steps) + lag
    restore_step = np.where(kept_on, 0, restore_step)

    # 2. The same night again, each house restored at its latest restoring sample.
    core = at_switch_off
    total = int((window_h + after_h) * 3600 / dt_s)
    lowest = np.full(n, np.inf)
    at_restore = np.full(n, np.nan)
    low_after = np.full(n, np.inf)
    early_defrost = np.zeros(n, bool)
    first_run = int(EARLIEST_DEFROST_S / dt_s)
    for i in range(total):
        enabled = i >= restore_step
        out = core.step(dt_s, t_out_c, np.full(n, t_set_c), enabled, gains, zero, off,
                        want=frozenset({"t_air_c"}))
        early_defrost |= enabled & (i < restore_step + first_run) & out["defrost"]
        air = out["t_air_c"] + offset
        lowest = np.minimum(lowest, air)
        at_restore = np.where(i == restore_step, air, at_restore)
        low_after = np.where(enabled, np.minimum(low_after, air), low_after)
    return ScreenResult(
        reaches_t_min=reaches,
        hours_to_t_min=np.where(reaches, restore * dt_s / 3600.0, np.inf),
        lowest_c=lowest, owner_low_c=owner_low,
        undershoot_k=np.minimum(t_min, owner_low) - lowest,
        drop_after_restore_k=np.where(reaches, at_restore - low_after, 0.0),
        early_defrost=early_defrost)
