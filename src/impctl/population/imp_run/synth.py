"""Simulated IMP nights for testing and benchmarking the fit (no torch).

The protocol is the gateway's (:class:`impctl.controller.plan.NightPolicy`, ``night.preheat_h``)
and the virtual population's (:data:`impctl.imp.plan.DEFAULT_PREHEAT_H`): days held at
``day_setpoint_c``; a *normal* night holds T_set (the gateway's normal setpoints in turn, 22, 23,
24 °C) from ``normal_preheat_h`` before the 22:00 window (default 2 h: 20:00) to 05:00; a
*constrained* night (T_set = the gateway's constrained setpoint, 21 °C) heats to T_max = T_set +
ΔT ``constrained_preheat_h`` before the window (default 2 h), switches off
at 22:00 and cools until 05:00 (the paper's case study: a predefined period).
With ``stop_at_t_min`` it ends as the gateway ends it (:mod:`.gateway`): at T_min = T_set −
ΔT, or earlier where the T_air trend reaches T_min within half an hour, then back at the day
setpoint (the owner's, restored); not switched off at all where the pre-heat left T_air less
than :data:`~impctl.imp.protocol.SWITCH_OFF_MIN_K` above T_min. The T_min test waits for the
emission lag because the 5R1C air node is massless: T_air drops 2–5 K the instant the heating
stops, which would end most nights at once (identifiability.md §11.2); a night that ends within
the lag is too short to be valid either way. The schedule carries its comfort band
(``SynthSchedule.band_k``), so the band of the pre-heat and of the stop cannot differ.
Houses are simulated with the Annex C model at a fine step (vectorised over houses); samples are
instants for temperatures and interval means for the heat power (``q_hc`` at a sample = mean
power until the next sample). Measurement model: T_air and T_out rounded to ``quantise_k``; each
power sample × (1 + ``power_noise``·N(0, 1)).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ...imp.features import Q_ON_W
from ...imp.files.extras import defrost_fields
from ...imp.night import NightSamples
from ...imp.plan import (
    DEFAULT_BAND_K,
    DEFAULT_CONSTRAINED_SETPOINT_C,
    DEFAULT_PREHEAT_H,
    DEFAULT_SETPOINTS_C,
)
from ...model import HouseParameters, simulate
from ...weather import DEFAULT_TZ, winter_weather
from .gateway import with_gateway_stops
from .setup import SynthSchedule


def night_plan(n_constrained: int, n_normal: int) -> list[str]:
    """Kinds in night order: constrained nights spread among the normal ones."""
    kinds = ["normal"] * n_normal
    for j in range(n_constrained):
        kinds.insert(min(len(kinds), 1 + j * (n_normal // max(1, n_constrained) + 1)),
                     "constrained")
    return kinds


def imp_schedule(
    n_houses: int,
    *,
    n_constrained: int = 2,
    n_normal: int = 6,
    setpoints_c: tuple[float, ...] = DEFAULT_SETPOINTS_C,
    constrained_setpoint_c: float | None = DEFAULT_CONSTRAINED_SETPOINT_C,
    band_k: float = DEFAULT_BAND_K,
    day_setpoint_c: float = 21.0,
    spinup_days: int = 2,
    start: str = "2026-01-05",
    sim_step_s: float = 60.0,
    seed: int = 0,
    tz: str = DEFAULT_TZ,
    constrained_preheat_h: float = DEFAULT_PREHEAT_H,
    normal_preheat_h: float = DEFAULT_PREHEAT_H,
    n_spare_constrained: int = 0,
    order: Sequence[str] | None = None,
) -> SynthSchedule:
    """Weather and setpoints for ``n_houses`` houses (own weather per house, seeded).

    ``constrained_preheat_h`` / ``normal_preheat_h`` [h]: how long before the 22:00 window the
    setpoint is T_max (constrained) or T_set (normal) instead of ``day_setpoint_c`` (default:
    the gateway's 2 h; until branch h14p this schedule used 4 h and 0 h, see bench/RESULTS.md
    "Issue 14: the pre-heat length").

    Normal night k (k-th of its kind) holds ``setpoints_c[k % len(setpoints_c)]`` [°C]; every
    constrained night has T_set = ``constrained_setpoint_c`` [°C] (T_max = T_set + ``band_k``),
    as the gateway's ``[campaign]``. ``constrained_setpoint_c=None`` is the schedule before
    branch h14q: night j of either kind at ``setpoints_c[j % len(setpoints_c)]`` (with 2 + 6
    nights and 22/23/24 °C: constrained nights at 23 and 24 °C, normal nights 3 × 22, 2 × 23,
    1 × 24 °C).

    ``n_spare_constrained``: that many more constrained nights after the plan (the gateway
    repeats an invalid constrained night; the planned nights and their weather are unchanged).

    ``order``: the nights' kinds in night order instead (e.g. a campaign's own order;
    ``n_constrained`` and ``n_normal`` must count them). Night j's weather is the same date's
    in any order: only the schedule's length changes the daily amplitudes.
    """
    kinds = (list(order) if order is not None
             else night_plan(n_constrained, n_normal) + ["constrained"] * n_spare_constrained)
    if order is not None and (kinds.count("constrained"), kinds.count("normal")) != (
            n_constrained, n_normal) or set(kinds) - {"constrained", "normal"}:
        raise ValueError(f"order {kinds!r} does not hold {n_constrained} constrained and "
                         f"{n_normal} normal nights")
    days = spinup_days + len(kinds) + 1
    series = [winter_weather(start, days, sim_step_s, seed=seed * 1000 + h, tz=tz)
              for h in range(n_houses)]
    index = series[0].index
    t_out = np.stack([s.to_numpy() for s in series], axis=1)
    sp = np.full(t_out.shape, day_setpoint_c)
    per_day = int(round(86400 / sim_step_s))
    hour = int(round(3600 / sim_step_s))
    windows = []
    k_normal = 0
    for j, kind in enumerate(kinds):
        day0 = (spinup_days + j) * per_day
        w0, w1 = day0 + 22 * hour, day0 + 29 * hour
        if constrained_setpoint_c is None:
            t_set = setpoints_c[j % len(setpoints_c)] if j < n_constrained + n_normal \
                else setpoints_c[0]
        elif kind == "constrained":
            t_set = constrained_setpoint_c
        else:
            t_set = setpoints_c[k_normal % len(setpoints_c)]
        k_normal += kind == "normal"
        if kind == "normal":
            sp[w0 - int(round(normal_preheat_h * hour)):w1] = t_set
        else:
            sp[w0 - int(round(constrained_preheat_h * hour)):w0] = t_set + band_k
            sp[w0:w1] = np.nan
        night_id = str(index[w0].date())
        windows.append((night_id, kind, w0, w1, t_set))
    return SynthSchedule(index, sim_step_s, t_out, sp, windows, day_setpoint_c, band_k,
                         n_spare_constrained)


def _schedule_band(sched: SynthSchedule, band_k: float | None) -> None:
    if band_k is not None and abs(band_k - sched.band_k) > 1e-9:
        raise ValueError(f"band_k {band_k:g} K differs from the schedule's {sched.band_k:g} K "
                         "(imp_schedule(band_k=…) sets both the pre-heat and the stop)")


def run_schedule(house: HouseParameters, sched: SynthSchedule, band_k: float | None = None,
                 stop_at_t_min: bool = False, emission_lag_h: float = 1.0,
                 anticipate: bool = True):
    """Simulate houses through the schedule (closed loop on T_min if ``stop_at_t_min``: each
    constrained night ends as the gateway ends it, see :func:`run_schedule_plant`).

    ``band_k`` [K]: None (the schedule's ``band_k``); a value other than the schedule's is an
    error. Returns the :class:`~impctl.model.Simulation` and the setpoints actually used.
    """
    _schedule_band(sched, band_k)

    def _run(sp):
        return simulate(house, sched.t_out_c, sched.dt_s, setpoint_c=sp,
                        t_m_init_c=sched.t_m_init_c)

    if not stop_at_t_min:
        sp = sched.setpoint_c.copy()
        return _run(sp), sp
    return with_gateway_stops(_run, lambda sim: sim.t_air_c, sched, emission_lag_h, anticipate)


@dataclass
class PlantSchedule:
    """What the gateway logs from :func:`run_schedule_plant` (arrays (n_steps, n_houses)):
    ``t_air_c`` the room sensor, ``phi_hc_w`` the heat meter, ``t_out_c`` the outdoor sensor;
    ``run`` the full :class:`impctl.plant.PlantRun` (true temperatures and powers)."""

    t_air_c: np.ndarray
    phi_hc_w: np.ndarray
    t_out_c: np.ndarray
    run: object
    #: the internal gains the plant was given [W] (n_steps, n_houses); None without gains
    internal_gains_w: np.ndarray | None = None


def run_schedule_plant(houses: HouseParameters, sched: SynthSchedule, params,
                       seed: int = 0, outputs: tuple[str, ...] | None = None,
                       gains: bool = True, stop_at_t_min: bool = False,
                       band_k: float | None = None, emission_lag_h: float = 1.0,
                       anticipate: bool = True) -> tuple[PlantSchedule, np.ndarray]:
    """Simulate houses through the schedule on the realistic plant (:mod:`impctl.plant`).

    ``params`` are the houses' realism options (:func:`impctl.population.realism.sample_params`);
    internal and solar gains follow their ``gains`` section over the schedule's local time. The
    plant starts in the steady state at the day setpoint. Returns what the gateway logs and the
    setpoints used (the schedule's, open loop). ``outputs``: the plant outputs to keep (default
    the logged ones and the true T_air and heat output). ``gains=False``: no internal or solar
    gains (their ranges exclude zero); they are still drawn, so the sensor noise is the same
    as with gains. ``stop_at_t_min``: a constrained night ends as the gateway ends it — at the
    first step after ``emission_lag_h`` [h] where the room sensor reads ≤ T_min = T_set −
    ΔT [°C] or (``anticipate``) its trend reaches T_min within half an hour
    (:func:`.gateway.gateway_end`); the setpoint is back at the day setpoint from there
    (nights in order, one re-simulation each: the plant and its noise are causal, so what
    precedes is unchanged). ΔT is the schedule's ``band_k``; the ``band_k`` argument [K] is kept for
    callers that pass it and must equal it.
    """
    _schedule_band(sched, band_k)
    from ...plant import simulate_plant
    from ...plant.building.gains import internal_gains_w, solar_gains_w

    n = sched.t_out_c.shape[1]
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x6A1]))
    local = sched.index.tz_convert(sched.index.tz) if sched.index.tz else sched.index
    hours = (local.hour + local.minute / 60.0).to_numpy()
    day = (local.normalize().tz_localize(None).asi8 // 86_400_000_000_000)
    g_int = internal_gains_w(hours, params.gains, n, rng, sched.dt_s)
    g_sol = solar_gains_w(hours, day, params.gains, n, rng)
    if not gains:
        g_int, g_sol = 0.0, 0.0
    plant_seed = int(rng.integers(2**31))
    keep = outputs or ("t_air_sensed_c", "t_out_sensed_c", "heat_meter_w", "heat_pump_w", "t_air_c",
                       "defrost")
    if stop_at_t_min and "t_air_sensed_c" not in keep:
        keep = (*keep, "t_air_sensed_c")

    def _run(sp):
        return simulate_plant(houses, params, sched.t_out_c, sched.dt_s, setpoint_c=sp,
                              internal_gains_w=g_int, solar_gains_w=g_sol,
                              t_init_c=sched.t_m_init_c, seed=plant_seed, outputs=keep)

    if stop_at_t_min:
        run, sp = with_gateway_stops(_run, lambda r: r["t_air_sensed_c"], sched,
                                      emission_lag_h, anticipate)
    else:
        sp = sched.setpoint_c.copy()
        run = _run(sp)
    logged = PlantSchedule(run["t_air_sensed_c"], run["heat_meter_w"], run["t_out_sensed_c"], run,
                           g_int if gains else None)
    return logged, sp


def sample_nights(
    sim,
    sp: np.ndarray,
    sched: SynthSchedule,
    house_index: int,
    *,
    sample_step_s: float = 300.0,
    quantise_k: float = 0.1,
    power_noise: float = 0.05,
    seed: int = 0,
    p_house: bool = False,
) -> list[NightSamples]:
    """Cut one house's simulation into measured nights (see the module docstring).

    ``sim`` is an Annex C :class:`~impctl.model.Simulation` or a :class:`PlantSchedule` (then
    T_out comes from its outdoor sensor; pass ``power_noise=0``: the meter has its own).
    ``p_house``: the nights carry ``p_house_w``, the household electricity a meter would log
    (:func:`house_meter`) — from a :class:`PlantSchedule`'s internal gains only.
    """
    rng = np.random.default_rng(seed)
    gains = getattr(sim, "internal_gains_w", None) if p_house else None
    meter = house_meter(seed) if gains is not None else None
    stride = int(round(sample_step_s / sched.dt_s))
    t_air = np.atleast_2d(sim.t_air_c.T).T[:, house_index]
    phi = np.atleast_2d(sim.phi_hc_w.T).T[:, house_index]
    t_out = (sim.t_out_c if isinstance(sim, PlantSchedule) else sched.t_out_c)[:, house_index]
    run = getattr(sim, "run", None) if isinstance(sim, PlantSchedule) else None
    defrost = (np.asarray(run["defrost"])[:, house_index].astype(bool)
               if run is not None and "defrost" in run.outputs else None)
    spc = sp[:, house_index]
    nights = []
    for night_id, kind, w0, w1, t_set in sched.windows:
        # The sample at 05:00 already belongs to the day regime: the window is [22:00, 05:00).
        steps = np.arange(w0, w1, stride)
        if kind == "constrained":
            # The cooling only: samples before the step where heating resumes at T_min.
            on = ~np.isnan(spc[w0:w1])
            end = w0 + (int(on.argmax()) if on.any() else w1 - w0)
            steps = steps[steps < end]
        if not len(steps):   # never switched off (pre-heat short): a night without samples
            q = np.zeros(0)
        elif steps[0] + len(steps) * stride <= len(phi):   # the same means, without a loop
            q = phi[steps[0]:steps[0] + len(steps) * stride].reshape(-1, stride).mean(axis=1)
        else:
            q = np.array([phi[s:s + stride].mean() for s in steps])
        q = q * (1.0 + power_noise * rng.standard_normal(len(q)))

        def quant(x):
            return np.round(x / quantise_k) * quantise_k if quantise_k > 0 else x

        extra = {}
        if defrost is not None and kind == "normal" and len(steps):
            # the heat pump's defrost flag (register 2011) as the gateway logs it: a sample
            # stands for its interval, defrosting when the plant defrosted in any of its steps
            flag = np.array([defrost[s:s + stride].any() for s in steps], float)
            extra |= defrost_fields({"defrost": flag}, np.arange(len(steps)),
                                    (steps - w0) * sched.dt_s, q, Q_ON_W)
        if meter is not None and len(steps):
            g = np.atleast_2d(gains.T).T[steps[0]:steps[-1] + stride, house_index]
            extra["p_house_w"] = float(g.mean()) * meter
        nights.append(NightSamples(
            night_id=night_id, kind=kind, start=sched.index[w0],
            time_s=(steps - w0) * sched.dt_s, t_air_c=quant(t_air[steps]),
            t_out_c=quant(t_out[steps]), q_hc_w=q, setpoint_c=t_set,
            **extra,
        ))
    return nights


def house_meter(seed: int) -> float:
    """What a household electricity meter logs per W of the plant's internal gain [W/W]: the
    gain is the indoor share of the electricity (uniform over
    :data:`impctl.imp.gain.INDOOR_SHARE`: the rest leaves as outdoor loads, drained warm
    water), read with a systematic meter error uniform within
    ±:data:`~impctl.imp.gain.HOUSE_METER_ERROR` — one draw per house (``seed``), what the
    fit's measured gain (:func:`impctl.imp.gain.measured_sd_w`) states as its uncertainty."""
    from ...imp.gain import HOUSE_METER_ERROR, INDOOR_SHARE

    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x9A1]))
    share = rng.uniform(*INDOOR_SHARE)
    error = rng.uniform(-HOUSE_METER_ERROR, HOUSE_METER_ERROR)
    return (1.0 + error) / share


def synth_nights(house: HouseParameters, *, seed: int = 0, sample_step_s: float = 300.0,
                 quantise_k: float = 0.1, power_noise: float = 0.05, **schedule_kw
                 ) -> list[NightSamples]:
    """One house's IMP nights, ready for the fit (convenience for tests and examples)."""
    sched = imp_schedule(1, seed=seed, **schedule_kw)
    sim, sp = run_schedule(house, sched)
    return sample_nights(sim, sp, sched, 0, sample_step_s=sample_step_s, quantise_k=quantise_k,
                         power_noise=power_noise, seed=seed)
