"""What a lower curve saves over a winter, in kWh of electricity.

Hour by hour over a winter's outdoor temperatures: the heat the house needs (:mod:`.need`,
central) divided by the COP (:mod:`.cop`) at the flow of the curve it runs, and at the flow
of the recommended curve; the saving is the difference, with an interval from draws of the
heat loss, the other heat and η. The heat itself is taken as unchanged: a room that no longer
overheats under a curve set too high saves more, which this does not count.

**The winter.** The house's own recorded outdoor temperatures where they span a season
(:data:`RECORDED_MIN_DAYS` days of hours), else :data:`ASSUMED_DAYS` days of the built-in
winter climate (:func:`impctl.weather.winter_weather`: daily mean −0.5 °C, a continental
December–January), labelled as assumed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .cop import CopModel, carnot_cop
from .need import COLD_QUANTILE, GRID_T_OUT_C, HeatNeed, Line

#: Days of hourly outdoor temperatures that make a recorded season.
RECORDED_MIN_DAYS = 90
#: Length of the assumed winter [days].
ASSUMED_DAYS = 120
#: Seed of the assumed winter's weather.
ASSUMED_SEED = 0
#: Draws of the saving's interval.
DRAWS = 500


@dataclass(frozen=True)
class Climate:
    """Hourly outdoor temperatures of a winter [°C], and where they come from."""

    t_out_c: np.ndarray
    source: str  # "recorded" | "assumed"
    days: float

    def describe(self) -> str:
        """One phrase for people."""
        mean = float(np.mean(self.t_out_c))
        if self.source == "recorded":
            return (f"this house's own outdoor temperatures over {self.days:.0f} days "
                    f"(mean {mean:.1f} °C)")
        return (f"an assumed winter of {self.days:.0f} days of the built-in climate "
                f"(mean {mean:.1f} °C)")

    def to_dict(self, setpoint_c: float) -> dict:
        """The JSON block ``savings.climate``."""
        return {"source": self.source, "days": round(self.days, 1),
                "mean_t_out_c": round(float(np.mean(self.t_out_c)), 2),
                "degree_hours_kh": round(float(np.sum(np.maximum(setpoint_c - self.t_out_c,
                                                                 0.0))), 0),
                "description": self.describe()}

    def cold_c(self) -> float:
        """The winter's :data:`~impctl.curve.need.COLD_QUANTILE` outdoor temperature [°C]."""
        return float(np.quantile(self.t_out_c, COLD_QUANTILE))

    def weights(self, need: HeatNeed, setpoint_c: float) -> np.ndarray:
        """Heat [W·h] of the winter's hours at each grid temperature (the nearest)."""
        idx = np.clip(np.rint((self.t_out_c - GRID_T_OUT_C[0]) / 0.5), 0,
                      len(GRID_T_OUT_C) - 1).astype(int)
        q = need.q_w(setpoint_c, self.t_out_c)
        return np.bincount(idx, weights=q, minlength=len(GRID_T_OUT_C))


def winter_climate(rows: pd.DataFrame) -> Climate:
    """The recorded season if the rows span one, else the assumed winter (module docstring)."""
    t = rows.set_index("timestamp")["t_out"]
    hours = t.resample("1h").mean().dropna()
    if len(hours) >= RECORDED_MIN_DAYS * 24:
        return Climate(hours.to_numpy(dtype=float), "recorded", len(hours) / 24.0)
    from ..weather import winter_weather

    w = winter_weather(days=ASSUMED_DAYS, step_s=3600, seed=ASSUMED_SEED)
    return Climate(w.to_numpy(dtype=float), "assumed", float(ASSUMED_DAYS))


@dataclass(frozen=True)
class Savings:
    """Electricity over the winter at the running and the recommended curve [kWh], the
    saving (value, 95 % interval) [kWh] and in % of the running curve's."""

    running_kwh: float
    recommended_kwh: float
    saving_kwh: float
    saving_low_kwh: float
    saving_high_kwh: float
    heat_kwh: float

    @property
    def percent(self) -> float:
        """Saving in % of the running curve's electricity."""
        return 100.0 * self.saving_kwh / self.running_kwh if self.running_kwh > 0 else 0.0

    def to_dict(self) -> dict:
        """The JSON block ``savings`` (without its climate)."""
        return {"electricity_kwh": {"running": round(self.running_kwh, 0),
                                    "recommended": round(self.recommended_kwh, 0)},
                "saving_kwh": {"value": round(self.saving_kwh, 0),
                               "low": round(self.saving_low_kwh, 0),
                               "high": round(self.saving_high_kwh, 0)},
                "saving_percent": round(self.percent, 1),
                "heat_kwh": round(self.heat_kwh, 0)}


def season_savings(need: HeatNeed, cop: CopModel, running: Line, recommended: Line,
                   climate: Climate, setpoint_c: float,
                   rng: np.random.Generator, draws: int = DRAWS) -> Savings:
    """The winter's electricity and saving (module docstring)."""
    t = climate.t_out_c
    f_run, f_new = running.at(t), recommended.at(t)

    def electricity(q: np.ndarray, eta: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        run = np.sum(q / carnot_cop(f_run, t, eta), axis=-1) / 1000.0
        new = np.sum(q / carnot_cop(f_new, t, eta), axis=-1) / 1000.0
        return run, new

    q = need.q_w(setpoint_c, t)
    run, new = electricity(q, cop.eta)
    hlc, gain = need.draws(rng, draws)
    eta = cop.draws(rng, draws)
    qd = np.maximum(hlc[:, None] * (setpoint_c - t[None, :]) - gain[:, None], 0.0)
    run_d, new_d = electricity(qd, eta[:, None])
    lo, hi = np.quantile(run_d - new_d, [0.025, 0.975])
    return Savings(float(run), float(new), float(run - new), float(lo), float(hi),
                   float(np.sum(q) / 1000.0))
