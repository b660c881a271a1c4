"""How the IMP is run on virtual households, and on which nights of the weather.

:class:`ImpSimConfig` holds the protocol (plans, band, window, pre-heat, spin-up, sampling,
noise); :func:`usable_nights` picks the weather's nights that fit it and need heating. Both
simulations of the virtual population read them: the ideal 5R1C
(:mod:`.ideal`) and the realistic plant (:mod:`.realistic`).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from ...errors import InputError
from ...imp import (
    DEFAULT_BAND_K,
    DEFAULT_CONSTRAINED_SETPOINT_C,
    DEFAULT_PREHEAT_H,
    DEFAULT_SETPOINTS_C,
    DEFAULT_WINDOW,
    EMISSION_LAG_H,
    NIGHT_KINDS,
    NightPlan,
    imp_plans,
)
from ...imp.protocol import ANTICIPATE_S, ANTICIPATE_WITHIN_K, MIN_NIGHT_H, TREND_WINDOW_S
from ...weather import DEFAULT_TZ, winter_weather


@dataclass(frozen=True)
class ImpSimConfig:
    """How the IMP is run on virtual households (module docstring); units in the names.

    ``days`` weather days per household, each with every plan of :func:`~impctl.imp.imp_plans`:
    a constrained night at ``constrained_setpoint_c`` and a normal night at each of
    ``setpoints_c`` (the gateway's ``[campaign]`` defaults; ``constrained_setpoint_c=None``:
    every kind at every setpoint, the population before branch h14q).
    Only nights whose mean T_out is below ``max_t_out_c`` are used (they need heating demand).
    ``day_setpoint_c``: (low, high) of the households' normal daytime setpoint [°C].
    ``constrained_per_day`` constrained plans run on every weather day, each constrained night's
    T_set drawn uniformly within ``constrained_jitter_k`` [K] of ``constrained_setpoint_c``
    (domain randomisation: a gateway's owner may configure it). Default one, at the gateway's
    T_set: three replays a day measured no better on realistic held-out houses (README
    "Accuracy", branch h14r). ``stop_at_t_min``: constrained nights end at T_min = T_set −
    ``band_k`` (the gateway's controller does); :meth:`for_plant` sets it as the gateway
    records nights on each plant. On the realistic plant they end as the gateway's controller
    ends them — T_air ≤ T_min, or its trend over ``trend_window_s`` [s] reaching T_min within
    ``anticipate_s`` [s] while within ``anticipate_within_k`` [K] of it (``[night]``'s
    defaults) — and one with less than ``min_usable_h`` [h] after the emitter lag is invalid
    as the gateway judges it: its features are NaN (never classified); the ideal 5R1C stops
    at T_min after the lag only.
    """

    days: int = 15
    setpoints_c: tuple[float, ...] = DEFAULT_SETPOINTS_C
    constrained_setpoint_c: float | None = DEFAULT_CONSTRAINED_SETPOINT_C
    kinds: tuple[str, ...] = NIGHT_KINDS
    band_k: float = DEFAULT_BAND_K
    window: tuple[dt.time, dt.time] = DEFAULT_WINDOW
    preheat_h: float = DEFAULT_PREHEAT_H
    spinup_days: float = 2.0
    step_s: float = 600.0
    spinup_step_s: float = 3600.0
    emitter_lag_h: float = EMISSION_LAG_H
    quantum_k: float = 0.1
    noise_t_air_k: float = 0.05
    noise_q_rel: float = 0.05
    max_t_out_c: float = 12.0
    day_setpoint_c: tuple[float, float] = (20.0, 22.0)
    stop_at_t_min: bool = False
    anticipate_s: float = ANTICIPATE_S
    anticipate_within_k: float = ANTICIPATE_WITHIN_K
    trend_window_s: float = TREND_WINDOW_S
    min_usable_h: float = MIN_NIGHT_H
    constrained_per_day: int = 1
    constrained_jitter_k: float = 0.0
    tz: str = DEFAULT_TZ

    def __post_init__(self) -> None:
        if self.days < 1:
            raise InputError("days must be >= 1", place="days")
        if not self.step_s > 0 or not self.spinup_step_s > 0:
            raise InputError("time steps must be > 0 s", place="step_s")
        if self.preheat_h * 3600.0 < self.step_s:
            raise InputError("preheat_h must cover at least one step", place="preheat_h")
        if self.quantum_k < 0 or self.noise_t_air_k < 0 or self.noise_q_rel < 0:
            raise InputError("quantum and noise must be >= 0", place="noise")
        if self.constrained_per_day < 1 or self.constrained_jitter_k < 0:
            raise InputError("constrained_per_day must be >= 1 and constrained_jitter_k >= 0",
                             place="constrained_per_day")

    @classmethod
    def for_plant(cls, plant: str, **kw) -> ImpSimConfig:
        """The population's nights as the gateway records them on ``plant`` ("realistic" or
        "iso"); ``kw`` as the constructor's.

        Realistic plant: constrained nights stop at T_min (``stop_at_t_min``), as the gateway's
        controller ends them. Classifiers trained so score better than or equal to those
        trained on nights cooling to the window's end, on the gateway's nights (Brier −0.015…
        +0.004 per class on two seeds; bench/RESULTS.md "Issue 14: classes on stopped nights",
        branch h14x). Ideal 5R1C: they cool to the window's end; its massless air node drops at
        switch-off and would end them right after the lag (module docstring), an artefact no
        real house shows.
        """
        return cls(**{"stop_at_t_min": plant == "realistic", **kw})

    def plans(self) -> list[NightPlan]:
        """The night plans run on every weather day (before the T_set draw)."""
        plans = imp_plans(self.setpoints_c, self.band_k, self.kinds,  # type: ignore[arg-type]
                          constrained_setpoint_c=self.constrained_setpoint_c,
                          window_start=self.window[0], window_end=self.window[1],
                          preheat_h=self.preheat_h, stop_at_t_min=self.stop_at_t_min)
        if self.constrained_setpoint_c is None:
            return plans
        extra = [p for p in plans if p.kind == "constrained"] * (self.constrained_per_day - 1)
        return extra + plans

    def setpoint_shift_k(self, plans: list[NightPlan], n_columns: int,
                         rng: np.random.Generator) -> np.ndarray:
        """T_set shift [K] of every (household, day, plan) column: uniform within
        ``constrained_jitter_k`` on constrained nights, 0 on normal nights."""
        cons = np.tile([p.kind == "constrained" for p in plans], n_columns // len(plans))
        if self.constrained_jitter_k == 0:
            return np.zeros(n_columns)
        k = self.constrained_jitter_k
        return np.where(cons, rng.uniform(-k, k, n_columns), 0.0)

    def as_dict(self) -> dict:
        """Plain-JSON form for manifests."""
        out = asdict(self)
        out["window"] = [t.strftime("%H:%M") for t in self.window]
        return {k: list(v) if isinstance(v, tuple) else v for k, v in out.items()}


def default_weather(seed: int = 0, tz: str = DEFAULT_TZ) -> pd.Series:
    """The built-in winter weather for the population: 130 days from 10 Nov at 10-min steps [°C].

    The season ends before the spring DST change; nights across a DST change are still handled
    (their windows are 6 or 8 h) when a weather file covers one.
    """
    return winter_weather("2025-11-10 00:00", days=130, step_s=600, seed=seed, tz=tz)


def _epoch_s(index: pd.DatetimeIndex) -> np.ndarray:
    return (index - pd.Timestamp(0, tz="UTC")).total_seconds().to_numpy()


def usable_nights(weather: pd.Series, config: ImpSimConfig) -> pd.DataFrame:
    """The weather's nights that fit (with spin-up and pre-heat) and need heating.

    Returns
    -------
    DataFrame
        ``date`` (local ISO date of the window start), ``start`` (tz-aware), ``start_s``
        (epoch s), ``duration_s`` [s], ``t_out_mean_c`` [°C].
    """
    w_t = _epoch_s(pd.DatetimeIndex(weather.index))
    w_v = weather.to_numpy(dtype=float)
    plan = NightPlan("normal", window_start=config.window[0], window_end=config.window[1],
                     preheat_h=config.preheat_h)
    local = pd.DatetimeIndex(weather.index).tz_convert(config.tz)
    dates = pd.date_range(local[0].date(), local[-1].date(), freq="D")
    lead_s = config.preheat_h * 3600.0 + config.spinup_days * 86400.0
    rows = []
    for day in dates:
        start, end = plan.window(day.date(), config.tz)
        s0, s1 = _epoch_s(pd.DatetimeIndex([start, end]))
        if s0 - lead_s < w_t[0] or s1 > w_t[-1]:
            continue
        mean = float(np.mean(np.interp(np.arange(s0, s1, config.step_s), w_t, w_v)))
        if mean < config.max_t_out_c:
            rows.append((day.strftime("%Y-%m-%d"), start, s0, s1 - s0, mean))
    return pd.DataFrame(rows, columns=["date", "start", "start_s", "duration_s", "t_out_mean_c"])


@dataclass
class SynthSchedule:
    """The simulated schedule, kept so a fitted house can be replayed on the same inputs.

    Attributes
    ----------
    index : DatetimeIndex of the simulation steps
    dt_s : simulation step [s]
    t_out_c : (n_steps, n_houses) outdoor temperature [°C]
    setpoint_c : (n_steps, n_houses) heating setpoint [°C], NaN = off
    windows : per night (night_id, kind, first step, end step (exclusive), T_set)
    t_m_init_c : mass temperature before the first step [°C]; also the day setpoint
    band_k : comfort band ΔT [K] of the constrained nights (T_max = T_set + ΔT for the pre-heat,
        T_min = T_set − ΔT for the stop)
    n_spare : the last ``n_spare`` windows are spare constrained nights, run by a gateway only
        to repeat an invalid one (:func:`.gateway.gateway_constrained_nights`)
    """

    index: pd.DatetimeIndex
    dt_s: float
    t_out_c: np.ndarray
    setpoint_c: np.ndarray
    windows: list[tuple[str, str, int, int, float]]
    t_m_init_c: float
    band_k: float = DEFAULT_BAND_K
    n_spare: int = 0
