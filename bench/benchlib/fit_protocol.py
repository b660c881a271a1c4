"""bench/fit.py's validation protocol (imported by it, and through it by the other bench
scripts): the validation houses' class ranges, the IMP schedule, the simulation on the ideal 5R1C
or the realistic plant (once per population), the heat-demand truth, and the fit's assumed night
gain per plant. The protocol itself is described in bench/fit.py's docstring.
"""

from __future__ import annotations

import numpy as np

from impctl.config import CampaignConfig
from impctl.fit.ode.parameters import PARAM_NAMES
from impctl.imp.protocol import MIN_NIGHT_H
from impctl.model import HouseParameters
from impctl.population.imp_run.gateway import gateway_constrained_nights
from impctl.population.imp_run.synth import (
    PlantSchedule,
    imp_schedule,
    run_schedule,
    run_schedule_plant,
)
from impctl.population.realism import sample_params

VAL_SEED = 20260
CLASS_RANGES = {
    "floor_area": ((60.0, 100.0), (100.0, 200.0), (200.0, 300.0)),
    "c_f": ((0.8, 1.65), (1.65, 3.7)),
    "u_walls": ((0.2, 1.0), (1.0, 2.0)),
}
ACH = (0.0, 0.01)


def true_ranges(house: HouseParameters) -> dict[str, tuple[float, float]]:
    out = {}
    for name, rs in CLASS_RANGES.items():
        v = float(getattr(house, name))
        out[name] = next((r for r in rs if r[0] <= v < r[1]), rs[-1])
    return out


def classifier_ranges(nights, model_dir, probabilities: bool = False):
    """The classified ranges; with ``probabilities`` also {name: {label: p}} (the fit's
    population prior mixes the classes by them, as ``impctl fit`` does)."""
    from impctl.classifiers import classify_nights

    res = classify_nights(nights, model_dir)
    ranges = {k: tuple(v.fit_range) for k, v in res.items()}   # as impctl fit searches
    if probabilities:
        return ranges, {k: dict(v.probabilities) for k, v in res.items()}
    return ranges


def house_from(params: dict[str, float]) -> HouseParameters:
    return HouseParameters(**{n: params[n] for n in PARAM_NAMES}, ach_vent=ACH[0],
                           ach_infl=ACH[1])


def demand_eps(houses: list[HouseParameters], sched, truth_energy: np.ndarray) -> np.ndarray:
    """Mean |E − E_true|/E_true [%] over the normal nights, per household (NaN if no house)."""
    ok = [h is not None for h in houses]
    out = np.full(len(houses), np.nan)
    if not any(ok):
        return out
    idx = np.flatnonzero(ok)
    sub = HouseParameters.stack([houses[i] for i in idx])
    sched_sub = _sub_schedule(sched, idx)
    sim, _ = run_schedule(sub, sched_sub)
    e = window_energy(sim, sched_sub)
    out[idx] = 100.0 * np.mean(np.abs(e - truth_energy[:, idx]) / truth_energy[:, idx], axis=0)
    return out


def val_schedule(n: int, args=None):
    """The validation schedule of ``n`` households, with ``args``' pre-heat lengths if given."""
    kw = {}
    if args is not None and getattr(args, "preheat_h", None) is not None:
        kw = {"constrained_preheat_h": args.preheat_h, "normal_preheat_h": args.preheat_h}
    if args is not None and getattr(args, "preheat_h_normal", None) is not None:
        kw["normal_preheat_h"] = args.preheat_h_normal
    if args is not None and getattr(args, "setpoints", None):
        kw["setpoints_c"] = tuple(float(x) for x in args.setpoints.split(","))
    c_sp = getattr(args, "constrained_setpoint", None) if args is not None else None
    if c_sp is not None:
        kw["constrained_setpoint_c"] = None if c_sp == "cycle" else float(c_sp)
    if args is not None and getattr(args, "band_k", None) is not None:
        kw["band_k"] = float(args.band_k)
    if args is not None and getattr(args, "stop_at_t_min", False):
        # The gateway repeats an invalid constrained night, up to campaign.max_invalid_nights
        # invalid nights a campaign: spare constrained nights after the plan (issue 14, h14w).
        kw["n_spare_constrained"] = CampaignConfig().max_invalid_nights
    return imp_schedule(n, seed=VAL_SEED, **kw)


def campaign_cost(heat, sched) -> tuple[float, float, float, float]:
    """What the campaign costs the household: mean heat [kWh per household] the heating
    delivers over the whole schedule (spin-up days and the day after the last night included,
    so heat stored by a pre-heat and given back later is netted out; compare runs); the hours
    per night held above the day setpoint outside the windows (the evening pre-heat) and inside
    them (normal nights above the owner's setpoint); the degree-hours per night the setpoint is
    above the day setpoint, evening and window together [K·h] (a constrained window, heating
    off, counts 0)."""
    phi = np.atleast_2d(heat.phi_hc_w.T).T
    n_nights = len(sched.windows)
    kwh = phi.sum(axis=0) * sched.dt_s / 3.6e6
    inside = np.zeros(len(sched.index), bool)
    for _, _, w0, w1, _ in sched.windows:
        inside[w0:w1] = True
    excess = np.nan_to_num(sched.setpoint_c - sched.t_m_init_c, nan=0.0)
    above = excess > 1e-9
    per_night_h = sched.dt_s / 3600.0 / n_nights
    return (float(np.mean(kwh)), float(np.median(above[~inside].sum(axis=0)) * per_night_h),
            float(np.median(above[inside].sum(axis=0)) * per_night_h),
            float(np.median(np.clip(excess, 0.0, None).sum(axis=0)) * per_night_h))


def _sub_schedule(sched, idx):
    from dataclasses import replace

    return replace(sched, t_out_c=sched.t_out_c[:, idx], setpoint_c=sched.setpoint_c[:, idx])


def window_energy(sim, sched) -> np.ndarray:
    """Heat delivered in each normal-night window [kWh], (n_normal, n_houses)."""
    phi = np.atleast_2d(sim.phi_hc_w.T).T
    rows = [phi[w0:w1].sum(axis=0) * sched.dt_s / 3.6e6
            for _, kind, w0, w1, _ in sched.windows if kind == "normal"]
    return np.array(rows)


class _TrueHeat:
    """The realistic plant's true heat-pump output, for the demand truth (not the meter)."""

    def __init__(self, logged):
        self.phi_hc_w = logged.run["heat_pump_w"]


_SIMULATED: dict = {}


def simulate_schedule(houses_arr: HouseParameters, sched, plant: str, realism=None,
                      stop_at_t_min: bool = False, anticipate: bool = True):
    """(what the gateway logs, setpoints, object whose phi_hc_w is the true heat output);
    simulated once per population size and plant, so every sample step and range source
    reads the same nights. ``realism``: (name, PlantParams, gains on) in place of the drawn
    realism (``bench/fit_budget.py``'s ablation; same seeds otherwise). ``stop_at_t_min``:
    constrained nights end as the gateway's (issue 14, branches h14t, h14w; ``anticipate``: also
    where the T_air trend reaches T_min within half an hour, as the gateway)."""
    key = (houses_arr.n_houses, plant, realism[0] if realism else None,
           hash(np.nan_to_num(sched.setpoint_c, nan=-1.0).tobytes()), stop_at_t_min,
           sched.band_k, anticipate)
    if key not in _SIMULATED:
        _SIMULATED[key] = _simulate_schedule(houses_arr, sched, plant, realism, stop_at_t_min,
                                             anticipate)
    return _SIMULATED[key]


def _simulate_schedule(houses_arr: HouseParameters, sched, plant: str, realism=None,
                       stop_at_t_min: bool = False, anticipate: bool = True):
    if plant == "iso":
        sim, sp = run_schedule(houses_arr, sched, stop_at_t_min=stop_at_t_min,
                               anticipate=anticipate)
        return sim, sp, sim
    _, params, gains = realism or (None, sample_params(houses_arr.n_houses, VAL_SEED), True)
    logged, sp = run_schedule_plant(houses_arr, sched, params, seed=VAL_SEED, gains=gains,
                                    stop_at_t_min=stop_at_t_min, anticipate=anticipate)
    return logged, sp, _TrueHeat(logged)


def night_gain(args) -> dict:
    """The fit's assumed night gain from ``--night-gain-w`` / ``--night-gain-sd-w``: 0 W on the
    ideal 5R1C unless given (it has no gains), the fit's default on the realistic plant."""
    w = getattr(args, "night_gain_w", None)
    if w is None and args.plant == "iso":
        w = 0.0
    out = {} if w is None else {"night_gain_w": w}
    if getattr(args, "night_gain_sd_w", None) is not None:
        out["night_gain_sd_w"] = args.night_gain_sd_w
    return out


def coheating_eps(hlc, sched, sim, truth_e):
    t_air = np.atleast_2d(sim.t_air_c.T).T[:, :len(hlc)]
    rows = [((t_air[w0:w1] - sched.t_out_c[w0:w1]).sum(axis=0) * sched.dt_s / 3.6e6)
            for _, kind, w0, w1, _ in sched.windows if kind == "normal"]
    e = np.array(rows) * np.asarray(hlc)[None, :]
    return 100.0 * np.mean(np.abs(e - truth_e) / truth_e, axis=0)


def _safe_house(params):
    try:
        return house_from(params)
    except Exception:  # a parameter set outside the model's domain cannot be replayed
        return None


def gateway_campaign(sp, sched, need_h: float = MIN_NIGHT_H) -> dict:
    """The constrained nights a gateway runs and keeps, per household
    (:func:`impctl.population.imp_run.gateway.gateway_constrained_nights` with the gateway's
    ``[campaign]`` defaults: 2 valid constrained nights wanted, at most
    ``campaign.max_invalid_nights`` invalid ones; valid = ≥ ``need_h`` [h] after the 1 h lag)."""
    cfg = CampaignConfig()
    return gateway_constrained_nights(sp, sched, n_needed=cfg.constrained_nights,
                                      max_invalid=cfg.max_invalid_nights, need_h=need_h)


def comfort_cost(sim, sched, run: np.ndarray, after_h: float = 3.0) -> dict:
    """What the constrained nights the household ran cost it in comfort, from the true room
    temperature (the plant's T_air, not the sensor): per household the coldest T_air [°C] and
    the degree-hours below the day setpoint [K·h] per night run, from the window's start to
    ``after_h`` [h] after its end (the recovery counted). ``run``: (n_constrained, n_houses)."""
    t_air = sim.run["t_air_c"] if isinstance(sim, PlantSchedule) else sim.t_air_c
    t_air = np.atleast_2d(np.asarray(t_air).T).T
    extra = int(round(after_h * 3600 / sched.dt_s))
    cold, dh = [], []
    for _, kind, w0, w1, _ in sched.windows:
        if kind != "constrained":
            continue
        seg = t_air[w0:min(len(t_air), w1 + extra)]
        cold.append(seg.min(axis=0))
        dh.append(np.clip(sched.t_m_init_c - seg, 0.0, None).sum(axis=0) * sched.dt_s / 3600.0)
    cold, dh = np.array(cold), np.array(dh)
    n_run = np.maximum(run.sum(axis=0), 1)
    return {"coldest_c": np.where(run, cold, np.inf).min(axis=0),
            "kh_per_night": np.where(run, dh, 0.0).sum(axis=0) / n_run,
            "kh_total": np.where(run, dh, 0.0).sum(axis=0)}


def short_constrained(sp, sched, lag_h: float = 1.0, need_h: float = MIN_NIGHT_H) -> np.ndarray:
    """(n_constrained, n_houses) True where a constrained night ended (heating back on) with
    less than ``need_h`` [h] after switch-off + ``lag_h`` [h]: the gateway's validity rule
    (:func:`impctl.controller.assess`), such a night is invalid and would be repeated."""
    return gateway_constrained_nights(sp, sched, lag_h=lag_h, need_h=need_h)["usable_h"] \
        < need_h - 1e-9
