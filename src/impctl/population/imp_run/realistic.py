"""The IMP on virtual households living on the realistic plant (:mod:`impctl.plant`).

Same nights, plans, weather days and outputs as :func:`~.ideal.simulate_imp` (one column per
(household, weather day, plan), one Python loop over time steps), but each household is a real
heat-pump house: its realism options (``plant_params``, drawn by
:func:`impctl.population.realism.sample_params`) give it air and furniture capacity, radiators or
underfloor heating, a weather-curve or thermostat controlled heat pump that cycles, defrosts,
night-time internal gains and the afternoon's sun stored in the mass, and imperfect sensors.

1. **Spin-up** (``spinup_days``, 900 s steps): the days before the night at the household's day
   setpoint under ideal control (the building's thermal state matters here, not the cycling),
   with day/night internal gains and solar gains (a random clearness per day).
2. **Pre-heat** (``preheat_h``) and **window** at 60 s with the real controller: pre-heat at
   T_max (constrained) or T_set (normal); in the window a constrained night switches the heating
   loop off, a normal night holds T_set. With ``stop_at_t_min`` a constrained night ends where
   the gateway's controller ends it (:class:`_GatewayStop`: polled every plant step from the
   switch-off, sensed T_air ≤ T_min or its trend anticipated there), the night's samples end
   with that poll and the owner's day setpoint is restored; a night with less than
   ``min_usable_h`` after the emission lag is invalid, as the gateway judges it (NaN features).

Observed samples every ``step_s``: the room sensor's T_air and the outdoor sensor's T_out at the
sample instant, and the heat meter's mean power over the sample interval (an energy counter
differenced; the instantaneous power of a cycling heat pump is a pulse train). No extra noise is
added: the plant's sensors carry it.
"""

from __future__ import annotations

from math import ceil

import numpy as np
import pandas as pd

from ...errors import InputError
from ...imp import features_from_arrays
from ...imp.protocol import MIN_TREND_SPAN_S, anticipates_t_min
from ...model import HouseParameters
from ...plant import PlantCore, PlantParams
from ...plant.building.envelope import NodeState
from ...plant.building.gains import internal_gains_w, solar_gains_w
from ..realism import take_params
from .ideal import ImpResult, _repeat, night_result
from .setup import ImpSimConfig, _epoch_s, default_weather, usable_nights

#: Steps of the realistic plant [s]: spin-up (ideal control) and pre-heat + window.
SPINUP_STEP_S = 900.0
PLANT_STEP_S = 60.0


def _local_hours(epoch_s: np.ndarray, tz: str) -> tuple[np.ndarray, np.ndarray]:
    """Local hour of day [h] and local day number for epoch seconds (any shape)."""
    flat = pd.DatetimeIndex(pd.to_datetime(epoch_s.reshape(-1), unit="s", utc=True)
                            ).tz_convert(tz)
    hours = (flat.hour + flat.minute / 60.0 + flat.second / 3600.0).to_numpy()
    days = (flat.normalize().tz_localize(None).asi8 // 86_400_000_000_000).astype(np.int64)
    return hours.reshape(epoch_s.shape), days.reshape(epoch_s.shape)


class _GatewayStop:
    """Where the gateway's controller ends each constrained night (impctl.controller: "reached
    T_min", "T_min anticipated"), polled every plant step from the switch-off.

    A night ends at the first poll whose sensed T_air is ≤ T_min, or whose least-squares trend
    over the last ``trend_window_s`` (at least :data:`impctl.imp.protocol.MIN_TREND_SPAN_S`)
    reaches T_min within ``anticipate_s`` while T_air is within ``anticipate_within_k`` of T_min.
    """

    def __init__(self, active: np.ndarray, t_min: np.ndarray, cfg: ImpSimConfig):
        self.active, self.t_min, self.cfg = active, t_min, cfg
        n_trend = int(round(cfg.trend_window_s / PLANT_STEP_S)) + 1
        self._trend = np.empty((n_trend, active.size))
        self.stopped = np.zeros(active.size, bool)
        self.at_step = np.full(active.size, -1)

    def poll(self, j: int, sensed_air: np.ndarray) -> None:
        """Poll ``j`` plant steps after the switch-off, reading ``sensed_air`` [°C]."""
        if not self.active.any():
            return
        trend, cfg = self._trend, self.cfg
        trend[j % len(trend)] = sensed_air
        ended = sensed_air <= self.t_min
        count = min(j + 1, len(trend))
        if cfg.anticipate_s > 0 and (count - 1) * PLANT_STEP_S >= MIN_TREND_SPAN_S:
            rows = trend if count == len(trend) else trend[:count]
            order = (np.arange(count) - (j + 1)) % len(trend) if count == len(trend) \
                else np.arange(count)
            t = order * PLANT_STEP_S   # ring-buffer rows' times, up to a shared offset
            t = t - t.mean()
            slope = (t @ (rows - rows.mean(axis=0))) / (t @ t)   # K/s
            ended |= anticipates_t_min(sensed_air, slope, self.t_min, cfg.anticipate_within_k,
                                       cfg.anticipate_s)
        new = ended & self.active & ~self.stopped
        self.stopped |= new
        self.at_step[new] = j


def simulate_imp_plant(
    houses: HouseParameters,
    plant_params: PlantParams,
    weather: pd.Series | None = None,
    config: ImpSimConfig | None = None,
    seed: int | np.random.SeedSequence | np.random.Generator = 0,
    *,
    keep_samples: bool = True,
) -> ImpResult:
    """Run the IMP on many households on the realistic plant (module docstring).

    Parameters
    ----------
    houses : HouseParameters
        Array-valued over n households.
    plant_params : PlantParams
        Realism options, arrays over the same n households.
    weather, config, seed, keep_samples
        As :func:`~.ideal.simulate_imp`.

    Returns
    -------
    ImpResult
    """
    cfg = config or ImpSimConfig()
    if weather is None:
        weather = default_weather(seed if isinstance(seed, int) else 0, cfg.tz)
    rng = np.random.default_rng(seed)
    if houses.n_houses is None:
        houses = _repeat(houses, 1)
    n, days = houses.n_houses, cfg.days
    cand = usable_nights(weather, cfg)
    if len(cand) < days:
        raise InputError(f"the weather holds {len(cand)} usable nights; {days} are needed",
                         place="weather")
    w_t = _epoch_s(pd.DatetimeIndex(weather.index))
    w_v = weather.to_numpy(dtype=float)
    plans = cfg.plans()
    n_p = len(plans)

    pick = np.argsort(rng.random((n, len(cand))), axis=1)[:, :days]
    start_s = cand["start_s"].to_numpy()[pick].reshape(-1)
    duration_s = cand["duration_s"].to_numpy()[pick].reshape(-1)
    preheat_s = cfg.preheat_h * 3600.0
    day_sp = np.repeat(rng.uniform(*cfg.day_setpoint_c, n), days)
    noise_seed = int(rng.integers(2**31))

    # 1. spin-up under ideal control, one column per (household, day)
    cols = np.repeat(np.arange(n), days)
    su_params = take_params(plant_params, cols, n)
    su_core = PlantCore(_repeat(houses, days), su_params, noise_seed)
    n_su = int(round(cfg.spinup_days * 86400.0 / SPINUP_STEP_S))
    t_su = (start_s - preheat_s - n_su * SPINUP_STEP_S)[None, :] \
        + (np.arange(n_su)[:, None] + 0.5) * SPINUP_STEP_S
    te = np.interp(t_su, w_t, w_v)
    hours, dayno = _local_hours(t_su, cfg.tz)
    g_int = internal_gains_w(hours, su_params.gains, len(cols), rng, SPINUP_STEP_S)
    g_sol = solar_gains_w(hours, dayno, su_params.gains, len(cols), rng)
    su_core.start_steady(day_sp, te[0])
    su_core.ideal[:] = True
    su_core.any_ideal = True
    on = np.ones(len(cols), bool)
    off = np.zeros(len(cols), bool)
    want = frozenset({"t_air_c"})
    for i in range(n_su):
        su_core.step(SPINUP_STEP_S, te[i], day_sp, on, g_int[i], g_sol[i], off, None, want)

    # 2. pre-heat and window at 60 s, one column per (household, day, plan)
    n_cols = n * days * n_p
    core = PlantCore(_repeat(houses, days * n_p),
                     take_params(plant_params, np.repeat(np.arange(n), days * n_p), n),
                     noise_seed + 1)
    core.start_steady(np.repeat(day_sp, n_p), np.repeat(te[-1], n_p))
    core.state = NodeState(*(np.repeat(getattr(su_core.state, f), n_p) for f in
                             ("air", "furniture", "mass", "water", "surface")))
    core.sensors.reset(core.state.air)
    core.sensed_air = core.state.air.copy()
    stride = int(round(cfg.step_s / PLANT_STEP_S))
    n_w = int(ceil(cand["duration_s"].max() / cfg.step_s))
    n_ph = int(round(preheat_s / PLANT_STEP_S))
    n_steps = n_ph + n_w * stride
    t0 = np.repeat(start_s - preheat_s, n_p)
    t_abs = t0[None, :] + (np.arange(n_steps)[:, None] + 0.5) * PLANT_STEP_S
    te = np.interp(t_abs, w_t, w_v)
    hours, dayno = _local_hours(t_abs[::stride], cfg.tz)
    g_int = np.repeat(internal_gains_w(hours, core.params.gains, n_cols, rng, cfg.step_s),
                      stride, axis=0)
    g_sol = np.repeat(solar_gains_w(hours, dayno, core.params.gains, n_cols, rng), stride, axis=0)
    cons = np.tile([p.kind == "constrained" for p in plans], n * days)
    shift = cfg.setpoint_shift_k(plans, n_cols, rng)
    sp_pre = np.tile([p.preheat_setpoint_c for p in plans], n * days) + shift
    sp_night = np.tile([p.setpoint_c for p in plans], n * days) + shift
    t_min = sp_night - cfg.band_k
    stop = _GatewayStop(cons & cfg.stop_at_t_min, t_min, cfg)
    owner_sp = np.repeat(day_sp, n_p)
    t_air = np.empty((n_w, n_cols))
    t_out = np.empty((n_w, n_cols))
    q_obs = np.zeros((n_w, n_cols))
    no_dhw = np.zeros(n_cols, bool)
    all_on = np.ones(n_cols, bool)
    want = frozenset({"t_air_sensed_c", "t_out_sensed_c", "heat_meter_w"})
    sensed_air, sensed_out = core.sensed_air, core.sensed_out
    for i in range(n_steps):
        k, r = divmod(i - n_ph, stride)
        if i < n_ph:
            sp, enabled = sp_pre, all_on
        else:
            if r == 0:
                t_air[k], t_out[k] = sensed_air, sensed_out
            stop.poll(i - n_ph, sensed_air)
            # Heating off on constrained nights until the stop; then the owner's setpoint is
            # restored, as the gateway does.
            sp = np.where(cons, owner_sp, sp_night)
            enabled = ~cons | stop.stopped
        out = core.step(PLANT_STEP_S, te[i], sp, enabled, g_int[i], g_sol[i], no_dhw, None,
                        want)
        sensed_air, sensed_out = out["t_air_sensed_c"], out["t_out_sensed_c"]
        if i >= n_ph:
            q_obs[k] += out["heat_meter_w"] / stride

    time_s = np.arange(n_w) * cfg.step_s
    night_s = np.repeat(duration_s, n_p)
    # The night's last sample is the one that ended it (the gateway stores it, then restores).
    end_s = np.where(stop.stopped, stop.at_step * PLANT_STEP_S, night_s)
    valid = (time_s[:, None] < night_s[None, :]) & (time_s[:, None] <= end_s[None, :])
    feats = features_from_arrays(time_s, t_air, t_out, q_obs, constrained=cons,
                                 setpoint_c=sp_night, valid=valid,
                                 emission_lag_h=cfg.emitter_lag_h)
    if cfg.stop_at_t_min:
        # The gateway's verdict (impctl.controller.assess): a constrained night with less than
        # min_usable_h after the emission lag is invalid — never exported, never classified.
        usable_h = np.minimum(end_s, night_s) / 3600.0 - cfg.emitter_lag_h
        short = cons & (usable_h < cfg.min_usable_h - 1e-9)
        for name, values in feats.items():
            if name != "is_constrained":
                values[short] = np.nan
    return night_result(pick, cand, plans, n, days, sp_night, duration_s, feats,
                        (time_s, t_air, t_out, q_obs, valid) if keep_samples else None)
