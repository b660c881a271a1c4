"""A heating season on the realistic plant: the IMP campaign and the owner's own nights (no torch).

The gateway sits beside the heat pump all winter. :func:`simulate_season` runs households through
a season in one pass at 60 s, closed loop where the gateway decides:

* **Weather**: :func:`impctl.weather.winter_weather` per household (cold and mild spells: an AR(1)
  daily mean) around a seasonal mean that is coldest mid-season (:attr:`SeasonConfig.seasonal_c`).
* **The owner**: a day setpoint per household; a share of owners set the night back by 1–3 K
  (:attr:`SeasonConfig.setback_share`); hot-water charges every morning and evening and on some
  nights (space heating paused while the tank charges); now and then the owner changes the setpoint
  in the night, or the heating stays off a whole night.
* **The campaign**: the gateway's plan (2 constrained and 6 normal IMP nights, every other night
  from the first) with spare constrained slots; a constrained night pre-heats to T_set + ΔT,
  switches off at 22:00 unless the pre-heat fell short and ends as the gateway ends it (T_min or
  its trend, :class:`.realistic._GatewayStop`); a spare slot runs only while a household still
  lacks its valid constrained nights and has invalid nights to spare, else it is an owner night.
* **Owner nights**: every other night, recorded read-only.
* **A change to the house** (optional, ``hlc_step_w_k`` and ``step_night``): from local noon
  before a given night on, a household's HLC is changed by a given amount [W/K] and stays so —
  a rise through the air path to outside (H_ve: a window left open), a fall through the opaque
  envelope's outer conductance (H_tr,em: loft insulation added); the rest of the network, the
  heat pump's curve and its controller are left as they were (:func:`step_network`).

Every 300 s the gateway's log is kept for whole days — the room sensor's T_air, the outdoor
sensor's T_out, the heat meter's interval mean, the setpoint and the hot-water and defrost flags,
the household electricity a meter would read — so a fit may take the window it needs
(:func:`.nights.household_nights`). Units: °C, W, s.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from ...imp.plan import EMISSION_LAG_H
from ...imp.protocol import (
    DEFAULT_BAND_K,
    DEFAULT_CONSTRAINED_SETPOINT_C,
    DEFAULT_PREHEAT_H,
    DEFAULT_SETPOINTS_C,
    MIN_NIGHT_H,
    SWITCH_OFF_MIN_K,
)
from ...model import HouseParameters
from ...plant import PlantCore, PlantParams
from ...plant.building.envelope import Network, Solver
from ...plant.building.gains import internal_gains_w, solar_gains_w
from ...plant.instruments.water import water_sensors
from ...weather import DEFAULT_TZ, WinterClimate, winter_weather
from ..imp_run.realistic import _GatewayStop
from ..imp_run.setup import ImpSimConfig
from ..imp_run.synth import house_meter, night_plan

#: Plant step [s].
STEP_S = 60.0
#: Local hour the night window opens [h] and its length [h] (22:00–05:00).
WINDOW_START_H, WINDOW_H = 22.0, 7.0


@dataclass(frozen=True)
class SeasonConfig:
    """How a season is simulated (module docstring); units in the names.

    ``nights`` nights in all after ``spinup_days``; the campaign's ``n_constrained`` +
    ``n_normal`` planned nights and ``n_spare`` spare constrained slots take every
    ``campaign_every``-th night from the first, every other night is the owner's.
    """

    nights: int = 72
    spinup_days: int = 3
    start: str = "2026-11-20"
    n_constrained: int = 2
    n_normal: int = 6
    n_spare: int = 3
    max_invalid: int = 3
    campaign_every: int = 2
    setpoints_c: tuple[float, ...] = DEFAULT_SETPOINTS_C
    constrained_setpoint_c: float = DEFAULT_CONSTRAINED_SETPOINT_C
    band_k: float = DEFAULT_BAND_K
    preheat_h: float = DEFAULT_PREHEAT_H
    emission_lag_h: float = EMISSION_LAG_H
    min_usable_h: float = MIN_NIGHT_H
    sample_s: float = 300.0
    day_setpoint_c: tuple[float, float] = (20.0, 22.5)
    setback_share: float = 0.5
    setback_k: tuple[float, float] = (1.0, 3.0)
    setback_hours: tuple[float, float] = (22.0, 6.0)
    #: daily hot-water charges: (earliest start [h], latest start [h], min, max length [min])
    dhw_charges: tuple[tuple[float, float, float, float], ...] = (
        (5.5, 7.5, 30.0, 60.0), (18.0, 21.0, 30.0, 50.0))
    night_dhw_p: float = 0.12
    owner_change_p: float = 0.03
    heating_off_p: float = 0.01
    #: seasonal mean outdoor temperature: (at the start and end, mid-season) [°C]
    seasonal_c: tuple[float, float] = (4.0, -2.0)
    tz: str = DEFAULT_TZ
    #: the heat pump's flow and return sensors each read off by up to ± this, per household
    #: [K] [own choice: sensors in pockets, ±0.2–0.5 K]
    water_offset_k: float = 0.5
    #: the circulation's flow from day to day: SD of its log, an AR(1) over days (variable-
    #: speed circulators, valves) [-] [own choice]
    flow_wander: float = 0.1
    #: the flow and return sensors' time constant [s] [own choice: in a pocket or clamped on
    #: the pipe, 0.5–3 min]
    water_lag_s: float = 120.0
    climate: WinterClimate = field(default_factory=lambda: WinterClimate(mean_c=0.0))

    def slots(self) -> list[str]:
        """Kind of each night in order: "constrained", "normal", "spare" or "owner"."""
        camp = night_plan(self.n_constrained, self.n_normal) + ["spare"] * self.n_spare
        kinds = ["owner"] * self.nights
        for j, kind in enumerate(camp):
            if j * self.campaign_every < self.nights:
                kinds[j * self.campaign_every] = kind
        return kinds


@dataclass
class Season:
    """A simulated season (arrays (n_samples, n) at ``sample_s``, the gateway's log).

    Attributes
    ----------
    index : DatetimeIndex of the samples (each sample stands for the interval it starts)
    t_air_c, t_out_c : room and outdoor sensors, means over the interval [°C]
    q_hc_w : heat meter, mean over the interval [W]
    setpoint_c : the loop-1 setpoint as read [°C]; NaN where the heating loop is off
    dhw, defrost : a hot-water charge / a defrost in the interval
    p_house_w : household electricity a meter reads, interval mean [W]
    t_flow_c, t_return_c : the heating water leaving and coming back, interval means [°C]
        (None in a season simulated before they were recorded)
    t_air_true_c, t_mass_c : the truth (room air, the building mass) [°C]
    nights : per night (date, kind per household (n,), first sample, end sample (exclusive))
        — kinds "constrained", "normal", "owner", and the constrained nights' gateway verdicts in
        ``valid`` / ``stop_sample``
    labels : per night and household, why an owner night is not a plain held night ("" if it is)
    houses, params : the simulated households
    """

    index: pd.DatetimeIndex
    sample_s: float
    t_air_c: np.ndarray
    t_out_c: np.ndarray
    q_hc_w: np.ndarray
    setpoint_c: np.ndarray
    dhw: np.ndarray
    defrost: np.ndarray
    p_house_w: np.ndarray
    t_air_true_c: np.ndarray
    t_mass_c: np.ndarray
    nights: list[tuple[str, np.ndarray, int, int]]
    valid: np.ndarray
    stop_sample: np.ndarray
    labels: np.ndarray
    t_set_c: np.ndarray
    q_true_w: np.ndarray
    gains_w: np.ndarray
    houses: HouseParameters
    params: PlantParams
    config: SeasonConfig
    t_flow_c: np.ndarray | None = None
    t_return_c: np.ndarray | None = None


def _local(index: pd.DatetimeIndex) -> tuple[np.ndarray, np.ndarray]:
    hours = (index.hour + index.minute / 60.0 + index.second / 3600.0).to_numpy()
    days = index.normalize().tz_localize(None).asi8 // 86_400_000_000_000
    return hours, days.astype(np.int64)


def _weather(n: int, days: int, cfg: SeasonConfig, seed: int) -> pd.DataFrame:
    cols = {}
    lo, mid = cfg.seasonal_c
    for h in range(n):
        s = winter_weather(cfg.start, days, STEP_S, seed=seed * 1000 + h, tz=cfg.tz,
                           climate=cfg.climate)
        frac = np.arange(len(s)) / max(1, len(s) - 1)
        cols[h] = s.to_numpy() + lo + (mid - lo) * np.sin(np.pi * frac)
    return pd.DataFrame(cols, index=s.index)


def step_network(net: Network, delta_w_per_k: np.ndarray) -> Network:
    """``net`` with each house's steady-state HLC changed by ``delta_w_per_k`` [W/K] (0: as it
    was): a rise on H_ve (the air path to outside), a fall on H_tr,em (the opaque envelope's
    outer conductance, solved so the series network loses exactly that much). Raises ValueError
    for a fall the opaque path cannot give (more than its whole conductance)."""
    d = np.asarray(delta_w_per_k, float)
    h_ve = net.h_ve + np.maximum(d, 0.0)
    # HLC = H_ve + H_is·A/(H_is + A), A = H_w + H_ms·H_em/(H_ms + H_em): invert for H_em.
    a_old = net.h_w + net.h_ms * net.h_em / (net.h_ms + net.h_em)
    tr_new = net.h_is * a_old / (net.h_is + a_old) + np.minimum(d, 0.0)
    b_new = net.h_is * tr_new / (net.h_is - tr_new) - net.h_w
    if np.any((d < 0) & ~((b_new > 0) & (b_new < net.h_ms))):
        raise ValueError("an HLC fall larger than the opaque envelope's conductance")
    h_em = np.where(d < 0, 1.0 / (1.0 / np.where(d < 0, b_new, 1.0) - 1.0 / net.h_ms),
                    net.h_em)
    return replace(net, h_ve=h_ve, h_em=h_em)


def simulate_season(houses: HouseParameters, params: PlantParams,
                    config: SeasonConfig | None = None, seed: int = 0,
                    gains: bool = True, hlc_step_w_k=0.0, step_night=None) -> Season:
    """Run ``houses`` (arrays over n) on the realistic plant through a season (module
    docstring); ``gains=False`` runs them without internal and solar gains.

    ``hlc_step_w_k`` (a number or one per household [W/K]; 0: no change) changes a household's
    HLC from local noon before its night ``step_night`` (a number or one per household; 0 =
    the first night after the spin-up) to the season's end (:func:`step_network`). Nothing
    else in the run depends on them: the same seed gives the same weather, owner and campaign
    with or without a change."""
    cfg = config or SeasonConfig()
    n = houses.n_houses or 1
    step_w = np.broadcast_to(np.asarray(hlc_step_w_k, float), (n,))
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5EA5]))
    days = cfg.spinup_days + cfg.nights + 1
    weather = _weather(n, days, cfg, seed)
    index = weather.index
    te = weather.to_numpy()
    n_steps = len(index)
    hours, dayno = _local(index)
    g_int = internal_gains_w(hours, params.gains, n, rng, STEP_S)
    g_sol = solar_gains_w(hours, dayno, params.gains, n, rng)
    if not gains:
        g_int, g_sol = g_int * 0.0, g_sol * 0.0
    meter = np.array([house_meter(seed * 100_003 + h) for h in range(n)])

    # The owner: day setpoint, night setback, hot water, changes, nights off.
    sp_day = rng.uniform(*cfg.day_setpoint_c, n)
    setback = np.where(rng.random(n) < cfg.setback_share, rng.uniform(*cfg.setback_k, n), 0.0)
    sb0, sb1 = cfg.setback_hours
    in_setback = (hours >= sb0) | (hours < sb1)
    owner_sp = sp_day[None, :] - np.where(in_setback[:, None], setback[None, :], 0.0)
    dhw = np.zeros((n_steps, n), bool)
    per_day = int(round(86400 / STEP_S))
    first_midnight = int(np.argmax(hours < hours[0])) if hours[0] > 0 else 0
    for d in range(days):
        d0 = first_midnight + d * per_day
        for h0, h1, m0, m1 in cfg.dhw_charges:
            start = d0 + (rng.uniform(h0, h1, n) * 3600 / STEP_S).astype(int)
            length = (rng.uniform(m0, m1, n) * 60 / STEP_S).astype(int)
            for h in range(n):
                dhw[start[h]:start[h] + length[h], h] = True
    slots = cfg.slots()
    win0 = [first_midnight + (cfg.spinup_days + j) * per_day
            + int(round(WINDOW_START_H * 3600 / STEP_S)) for j in range(cfg.nights)]
    win_len = int(round(WINDOW_H * 3600 / STEP_S))
    labels = np.full((cfg.nights, n), "", dtype=object)
    for j, w0 in enumerate(win0):
        night_dhw = rng.random(n) < cfg.night_dhw_p
        at = w0 + (rng.uniform(0.5, 6.0, n) * 3600 / STEP_S).astype(int)
        length = (rng.uniform(20.0, 45.0, n) * 60 / STEP_S).astype(int)
        for h in np.flatnonzero(night_dhw):
            dhw[at[h]:at[h] + length[h], h] = True
        if slots[j] == "owner" or slots[j] == "spare":
            change = rng.random(n) < cfg.owner_change_p
            off = rng.random(n) < cfg.heating_off_p
            when = w0 + (rng.uniform(0.5, 6.0, n) * 3600 / STEP_S).astype(int)
            delta = rng.choice([-1.5, -1.0, 1.0, 1.5], n)
            for h in np.flatnonzero(change):
                owner_sp[when[h]:w0 + 2 * per_day, h] += delta[h]
                sp_day[h] += delta[h]
                owner_sp[w0 + 2 * per_day:, h] += delta[h]
            for h in np.flatnonzero(off & ~change):
                owner_sp[w0:w0 + win_len, h] = np.nan
            labels[j, change] = "owner changed the setpoint"
            labels[j, off & ~change] = "heating off"

    core = PlantCore(houses, params, int(rng.integers(2**31)))
    core.start_steady(sp_day, te[0])
    # The change to the house: per plant step, the households whose HLC changes there.
    changes: dict[int, np.ndarray] = {}
    if np.any(step_w != 0):
        at_night = np.broadcast_to(np.asarray(0 if step_night is None else step_night, int),
                                   (n,))
        noon = int(round((WINDOW_START_H - 12.0) * 3600 / STEP_S))
        for h in np.flatnonzero(step_w != 0):
            at = win0[int(at_night[h])] - noon
            changes[at] = changes.get(at, np.zeros(n, bool)) | (np.arange(n) == h)
    stride = int(round(cfg.sample_s / STEP_S))
    n_samp = n_steps // stride
    rec = {k: np.zeros((n_samp, n)) for k in ("t_air_c", "t_out_c", "q_hc_w", "setpoint_c",
                                               "p_house_w", "t_air_true_c", "t_mass_c",
                                               "q_true_w", "gains_w", "t_flow_c",
                                               "t_return_c")}
    flags = {k: np.zeros((n_samp, n), bool) for k in ("dhw", "defrost")}

    # Campaign state per household.
    kinds = np.array([[s] * n for s in slots], dtype=object)
    valid_c = np.zeros(n, int)
    invalid_c = np.zeros(n, int)
    valid = np.zeros((cfg.nights, n), bool)
    stop_sample = np.full((cfg.nights, n), -1)
    t_set = np.full((cfg.nights, n), np.nan)
    k_normal = 0
    sim_cfg = ImpSimConfig(band_k=cfg.band_k)
    preheat = int(round(cfg.preheat_h * 3600 / STEP_S))
    # Per step: the setpoint and loop state each household runs; decided night by night.
    sp_run = owner_sp.copy()
    enabled_run = ~np.isnan(sp_run)
    j_of_step = np.full(n_steps, -1)
    for j, w0 in enumerate(win0):
        j_of_step[w0 - preheat:w0 + win_len] = j
    night_j = -1
    stop: _GatewayStop | None = None
    cons = np.zeros(n, bool)
    started = np.zeros(n, bool)
    want = frozenset({"t_air_sensed_c", "t_out_sensed_c", "heat_meter_w", "t_air_c",
                      "t_mass_c", "defrost", "heat_pump_w", "t_supply_c", "t_return_c"})
    sensed_air = core.sensed_air
    # the flow and return sensors' own lag (first order, exact per plant step)
    a_water = 1.0 - np.exp(-STEP_S / cfg.water_lag_s) if cfg.water_lag_s > 0 else 1.0
    sensed_water: list[np.ndarray] = []
    for i in range(n_steps):
        if i in changes:
            core.network = step_network(core.network, np.where(changes[i], step_w, 0.0))
            core.solver = Solver(core.network)
        j = j_of_step[i]
        if j >= 0 and j != night_j:   # the pre-heat of night j begins: the gateway decides
            night_j = j
            w0 = win0[j]
            slot = slots[j]
            if slot == "spare":
                run_it = (valid_c < cfg.n_constrained) & (invalid_c < cfg.max_invalid)
                kinds[j] = np.where(run_it, "constrained", "owner")
            elif slot == "constrained":
                kinds[j] = np.where(invalid_c < cfg.max_invalid, "constrained", "owner")
            cons = kinds[j] == "constrained"
            if slot == "normal":
                sp_n = cfg.setpoints_c[k_normal % len(cfg.setpoints_c)]
                k_normal += 1
                t_set[j] = sp_n
                sp_run[w0 - preheat:w0 + win_len] = sp_n
                enabled_run[w0 - preheat:w0 + win_len] = True
            elif cons.any():
                t_set[j, cons] = cfg.constrained_setpoint_c
                sp_run[w0 - preheat:w0, cons] = cfg.constrained_setpoint_c + cfg.band_k
                enabled_run[w0 - preheat:w0, cons] = True
            stop = _GatewayStop(cons.copy(), np.full(n, cfg.constrained_setpoint_c - cfg.band_k),
                                sim_cfg)
            started = np.zeros(n, bool)
        if night_j >= 0 and stop is not None and i >= win0[night_j] and cons.any():
            w0 = win0[night_j]
            k = i - w0
            if k == 0:
                # Not switched off where the pre-heat fell short (the gateway's rule).
                started = cons & (sensed_air >= cfg.constrained_setpoint_c - cfg.band_k
                                  + SWITCH_OFF_MIN_K)
                stop.active = started.copy()
                stop_sample[night_j, cons & ~started] = w0 // stride
            if k < win_len:
                stop.poll(k, sensed_air)
                off_now = started & ~stop.stopped
                enabled = np.where(off_now, False, enabled_run[i])
                sp = np.where(off_now, 20.0, sp_run[i])
            else:
                enabled, sp = enabled_run[i], sp_run[i]
        else:
            enabled, sp = enabled_run[i], sp_run[i]
        sp_c = np.where(enabled, np.nan_to_num(sp, nan=20.0), 20.0)
        out = core.step(STEP_S, te[i], sp_c, enabled, g_int[i], g_sol[i], dhw[i], None, want)
        sensed_air = out["t_air_sensed_c"]
        r, q = divmod(i, stride)
        if r < n_samp:
            # The gateway's rows are means of its 60-s snapshots; the setpoint as read at the
            # row's start.
            rec["t_air_c"][r] += sensed_air / stride
            rec["t_out_c"][r] += out["t_out_sensed_c"] / stride
            rec["t_air_true_c"][r] += out["t_air_c"] / stride
            rec["t_mass_c"][r] += out["t_mass_c"] / stride
            if q == 0:
                rec["setpoint_c"][r] = np.where(enabled, sp_c, np.nan)
            rec["q_hc_w"][r] += out["heat_meter_w"] / stride
            if not sensed_water:
                sensed_water = [out["t_supply_c"].copy(), out["t_return_c"].copy()]
            for sensed, true in zip(sensed_water, (out["t_supply_c"], out["t_return_c"]),
                                    strict=True):
                sensed += a_water * (true - sensed)
            rec["t_flow_c"][r] += sensed_water[0] / stride
            rec["t_return_c"][r] += sensed_water[1] / stride
            rec["q_true_w"][r] += out["heat_pump_w"] / stride
            rec["gains_w"][r] += (g_int[i] + g_sol[i]) / stride
            rec["p_house_w"][r] += g_int[i] * meter / stride
            flags["dhw"][r] |= dhw[i]
            flags["defrost"][r] |= out["defrost"]
        # A constrained night's end: validity as the gateway judges it.
        if night_j >= 0 and i == win0[night_j] + win_len - 1 and cons.any():
            end = np.where(stop.stopped, stop.at_step, win_len)
            usable_h = end * STEP_S / 3600.0 - cfg.emission_lag_h
            ok = started & (usable_h >= cfg.min_usable_h - 1e-9)
            valid[night_j] = ok
            stop_sample[night_j, started] = (win0[night_j] + end[started]) // stride
            valid_c += ok
            invalid_c += cons & ~ok
            cons = np.zeros(n, bool)
    samp_index = index[::stride][:n_samp]
    rec["t_flow_c"], rec["t_return_c"] = water_sensors(
        rec["t_flow_c"], rec["t_return_c"], samp_index, cfg.tz, cfg.water_offset_k,
        cfg.flow_wander, seed)
    nights = [(str(samp_index[w0 // stride].date()), kinds[j], w0 // stride,
               (w0 + win_len) // stride) for j, w0 in enumerate(win0)]
    return Season(samp_index, cfg.sample_s, rec["t_air_c"], rec["t_out_c"], rec["q_hc_w"],
                  rec["setpoint_c"], flags["dhw"], flags["defrost"], rec["p_house_w"],
                  rec["t_air_true_c"], rec["t_mass_c"], nights, valid, stop_sample, labels,
                  t_set, rec["q_true_w"], rec["gains_w"], houses, params, cfg,
                  rec["t_flow_c"], rec["t_return_c"])
