"""bench/curve.py's simulation: the validation households on the realistic plant through a
stretch of winter, day by day (so that 200 houses × months fit in memory), with the
installer's curve or a two-point curve per house, and what each stretch costs and gives.

* weather: :func:`impctl.weather.winter_weather`, one seed per household and stretch, hourly,
  interpolated to the step;
* gains: the plant's internal and solar gains (:mod:`impctl.plant.building.gains`) over the
  local day, drawn at 10-minute steps and held within them;
* the owner's setpoint all day and night (:data:`SETPOINT_C`), no hot water (the same under
  both curves; the electricity compared is the space heating's);
* the fit: the household's IMP campaign of ``bench/fit.py`` (the gateway's nights on the same
  plant, seed 20260), fitted as ``impctl fit`` fits (:func:`fit_json`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from impctl.curve.data.synth import SYNTH_OUTPUTS, rows_from_run
from impctl.imp.protocol import DEFAULT_BAND_K
from impctl.plant import PlantCore, simulate_plant
from impctl.plant.building.gains import internal_gains_w, solar_gains_w
from impctl.plant.hydronics.flow_curve import flow_for_node
from impctl.weather import DEFAULT_TZ, winter_weather

#: The owner's setpoint [°C] (the validation schedule's day setpoint).
SETPOINT_C = 21.0
#: The comfort floor of a constrained night, T_set − the band [°C].
T_MIN_C = SETPOINT_C - DEFAULT_BAND_K
#: Gains drawn at this step [s].
GAIN_STEP_S = 600.0
#: A step this far below the setpoint counts as cold [K].
COLD_K = 0.5


@dataclass
class Stretch:
    """What one stretch of winter cost and gave, per house (arrays over houses)."""

    electricity_kwh: np.ndarray
    heat_kwh: np.ndarray
    cold_h: np.ndarray
    hours: float
    coldest_c: np.ndarray
    coldest_night_c: np.ndarray
    mean_t_air_c: np.ndarray
    night_gain_w: np.ndarray
    #: hours the room sensor (what the owner and the heat pump see) read below sp − 0.5 K
    cold_sensed_h: np.ndarray = None  # type: ignore[assignment]
    #: the comfort watch's raises per house (:class:`Watch`)
    raises: np.ndarray = None  # type: ignore[assignment]
    rows: list[list[pd.DataFrame]] = field(default_factory=list)

    def house_rows(self, j: int) -> pd.DataFrame:
        """House ``j``'s recorded rows, all days."""
        return pd.concat(self.rows[j], ignore_index=True)


def weather(n: int, days: float, seed: int, start: str) -> np.ndarray:
    """Hourly outdoor temperatures (n_hours, n) [°C], one seed per house."""
    cols = [winter_weather(start, days=days + 1, step_s=3600, seed=seed * 1000 + j,
                           tz=DEFAULT_TZ).to_numpy() for j in range(n)]
    return np.column_stack(cols)


@dataclass
class Watch:
    """The daemon's comfort watch over a two-point curve (``[curve]`` short_k, short_h,
    raise_k; :mod:`impctl.daemon.curve.watch`): a room sensed on average more than
    ``short_k`` below the setpoint over a window of ``short_h`` raises both points by
    ``raise_k`` — the sensed room read at every step, a raise made at the end of the simulated
    hour it falls in (the daemon raises at
    once, so this watch is a little slower); a curve raised to the owner's
    points (``owner``: flows at −15 and +15 °C [°C]), or past the write bounds, is the
    owner's again (the house's built-in curve) for the rest of the winter, as the daemon
    keeps it until asked again."""

    owner: tuple[np.ndarray, np.ndarray]
    #: the houses running impctl's curve (the others run the installer's and are not watched)
    houses: np.ndarray
    #: the owner's curve is the plant's built-in one (given back as NaN), else ``owner``'s line
    owner_builtin: bool = True
    short_k: float = 0.5
    short_h: float = 1.0
    raise_k: float = 1.0
    # the sliding window's state (the last short_h of shortfalls per house)
    _buf: np.ndarray | None = field(default=None, repr=False)
    _seen: np.ndarray | None = field(default=None, repr=False)
    _total: np.ndarray | None = field(default=None, repr=False)
    _step: int = 0


def simulate(houses, params, days: int, seed: int, start: str = "2026-12-01 00:00", *,
             dt_s: float = 60.0, curve: tuple[np.ndarray, np.ndarray] | None = None,
             row_step_s: float | None = None, watch: Watch | None = None) -> Stretch:
    """Simulate ``days`` days from ``start`` (local) on the realistic plant, day by day.

    ``curve``: flows at −15 and +15 °C per house [°C] (NaN: the house keeps its built-in
    curve); ``row_step_s``: also keep each house's recorded rows at this step (owner nights,
    :func:`impctl.curve.data.synth.rows_from_run`); ``watch``: the comfort watch over ``curve``
    (the day then runs an hour at a time; :attr:`Stretch.raises` counts its raises).
    """
    n = houses.n_houses
    t_hour = weather(n, days, seed, start)
    begin = pd.Timestamp(start, tz=DEFAULT_TZ)
    core = PlantCore(houses, params, seed=seed)
    core.start_steady(SETPOINT_C, t_hour[0])
    if curve is not None:
        curve = (np.array(curve[0], float), np.array(curve[1], float))
        core.set_flow_curve(curve[0], curve[1], SETPOINT_C)
    raises = np.zeros(n, int)
    per_gain = int(round(GAIN_STEP_S / dt_s))
    g_index = begin + pd.to_timedelta(np.arange(int(days * 86400 / GAIN_STEP_S)) * GAIN_STEP_S,
                                      unit="s")
    hours = (g_index.hour + g_index.minute / 60.0).to_numpy()
    day_no = (g_index.normalize().tz_localize(None).asi8 // 86_400_000_000_000)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x6A1]))
    g_int = internal_gains_w(hours, params.gains, n, rng, GAIN_STEP_S)
    g_sol = solar_gains_w(hours, day_no, params.gains, n, rng)
    steps = int(86400 / dt_s)
    out = Stretch(*(np.zeros(n) for _ in range(3)), 0.0, np.full(n, np.inf),
                  np.full(n, np.inf), np.zeros(n), np.zeros(n))
    night_gain, night_n = np.zeros(n), 0
    sp = np.full(steps, SETPOINT_C)
    keep = SYNTH_OUTPUTS if row_step_s else ("t_air_c", "t_air_sensed_c", "electric_w",
                                             "heat_pump_w")
    out.cold_sensed_h = np.zeros(n)
    for d in range(days):
        t0 = d * 86400.0
        t_end = t0 + dt_s * np.arange(1, steps + 1)
        t_mid = t_end - dt_s / 2
        t_out = np.column_stack([np.interp(t_mid / 3600.0, np.arange(len(t_hour)), t_hour[:, j])
                                 for j in range(n)])
        gi = np.repeat(g_int[d * steps // per_gain:(d + 1) * steps // per_gain], per_gain, axis=0)
        gs = np.repeat(g_sol[d * steps // per_gain:(d + 1) * steps // per_gain], per_gain, axis=0)
        chunk = int(round(3600.0 / dt_s)) if watch is not None and curve is not None else steps
        parts = []
        for c0 in range(0, steps, chunk):
            c = slice(c0, c0 + chunk)
            part = simulate_plant(houses, params, t_out[c], dt_s, setpoint_c=sp[c],
                                  internal_gains_w=gi[c], solar_gains_w=gs[c],
                                  outputs=keep, core=core)
            parts.append(part)
            if chunk < steps:
                _look(watch, core, curve, part["t_air_sensed_c"], dt_s, raises)
        run = parts[0] if len(parts) == 1 else {
            k: np.concatenate([np.asarray(p[k]) for p in parts]) for k in keep}
        index = begin + pd.to_timedelta(t_end, unit="s")
        local_h = index.hour.to_numpy()
        night = (local_h >= 22) | (local_h < 6)
        t_air = run["t_air_c"]
        out.electricity_kwh += run["electric_w"].sum(axis=0) * dt_s / 3.6e6
        out.heat_kwh += np.maximum(run["heat_pump_w"], 0.0).sum(axis=0) * dt_s / 3.6e6
        out.cold_h += (t_air < SETPOINT_C - COLD_K).sum(axis=0) * dt_s / 3600.0
        out.cold_sensed_h += (run["t_air_sensed_c"] < SETPOINT_C - COLD_K).sum(axis=0) \
            * dt_s / 3600.0
        out.coldest_c = np.minimum(out.coldest_c, t_air.min(axis=0))
        out.coldest_night_c = np.minimum(out.coldest_night_c, t_air[night].min(axis=0))
        out.mean_t_air_c += t_air.mean(axis=0) / days
        night_gain += gi[night].sum(axis=0)
        night_n += int(night.sum())
        if row_step_s:
            target = core.controller.steady_flow_c(run["t_water_target_c"],
                                                   np.full((steps, 1), SETPOINT_C),
                                                   core.flow_lag_k_per_w)
            if not d:
                out.rows = [[] for _ in range(n)]
            for j in range(n):
                out.rows[j].append(rows_from_run(run, index, j, setpoint_c=sp,
                                                 flow_target=target, sample_step_s=row_step_s,
                                                 dt_s=dt_s))
    out.hours = days * 24.0
    out.night_gain_w = night_gain / max(night_n, 1)
    out.raises = raises
    return out


def _look(watch: Watch, core: PlantCore, curve: tuple[np.ndarray, np.ndarray],
          sensed: np.ndarray, dt_s: float, raises: np.ndarray) -> None:
    """The watch after an hour (:class:`Watch`): updates ``curve`` and the plant in place."""
    from impctl.heatpump.config import CURVE_FLOW_BOUNDS_C

    fa, fb = curve
    fire = np.zeros(len(fa), bool)
    # the daemon's rule: the sensed room's mean shortfall over the last short_h, sliding,
    # once a whole window has been seen since the last raise
    need = int(round(watch.short_h * 3600.0 / dt_s))
    if watch._buf is None:
        watch._buf = np.zeros((need, len(fa)))
        watch._seen, watch._total = np.zeros(len(fa), int), np.zeros(len(fa))
    buf, seen, total = watch._buf, watch._seen, watch._total
    for row in SETPOINT_C - np.asarray(sensed):
        slot = watch._step % need
        total += row - buf[slot]
        buf[slot] = row
        watch._step += 1
        seen += 1
        now = (seen >= need) & (total / need > watch.short_k) & watch.houses
        seen[now], total[now], buf[:, now] = 0, 0.0, 0.0  # a new window after a raise
        fire |= now
    if not fire.any():
        return
    raises += fire
    fa[fire] += watch.raise_k
    fb[fire] += watch.raise_k
    oa, ob = watch.owner
    hi = CURVE_FLOW_BOUNDS_C[1]
    back = fire & (((fa >= oa) & (fb >= ob)) | (fa > np.maximum(hi, oa))
                   | (fb > np.maximum(hi, ob)))
    fa[back] = np.nan if watch.owner_builtin else oa[back]
    fb[back] = np.nan if watch.owner_builtin else ob[back]
    watch.houses[back] = False
    core.set_flow_curve(fa, fb, SETPOINT_C)


def true_flow_c(core: PlantCore, night_gain_w: np.ndarray, t_out_c: float,
                setpoint_c: float = SETPOINT_C) -> np.ndarray:
    """The flow the true house needs at ``t_out_c`` [°C]: its heat loss less its mean night
    gain, through its true emitter (Q = K·dⁿ, the flow Q/(2ṁc) above the mean water, an
    underfloor screed's water Q/G_pipe above the screed)."""
    q = np.maximum(core.hlc * (setpoint_c - t_out_c) - night_gain_w, 0.0)
    node = setpoint_c + (q / core.k_w) ** (1.0 / core.exponent)
    return flow_for_node(node, setpoint_c, core.k_w, core.exponent, core.flow_lag_k_per_w)


def installer_flow_c(core: PlantCore, t_out_c, setpoint_c: float = SETPOINT_C
                     ) -> np.ndarray:
    """The installer's curve (the plant's own, curve_gain) as the steady flow at ``t_out_c``
    [°C] (one for all houses, or one per house)."""
    node = core.controller.target_water_c(np.full(core.n, setpoint_c),
                                          np.full(core.n, setpoint_c),
                                          np.broadcast_to(np.asarray(t_out_c, float),
                                                          (core.n,)).copy())
    return core.controller.steady_flow_c(node, setpoint_c, core.flow_lag_k_per_w)
