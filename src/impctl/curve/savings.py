"""What a lower curve saves over a winter, in kWh of electricity.

Hour by hour over a winter's outdoor temperatures: the heat the house needs (:mod:`.need`,
central) divided by the COP (:mod:`.cop`) at the flow of the curve it runs, and at the flow
of the recommended curve; the saving is the difference, with an interval from draws of the
heat loss, the other heat and η.

**A room kept too warm.** A curve set too high on a heat pump that follows it (no room
thermostat to stop it) warms the rooms above the setpoint, and the house loses that heat too.
The rows tell by how much: the mean room above the owner's setpoint over the recorded heated
hours (``room_excess_k``, measured). The heat at the running curve holds that room; at the
recommended one, the excess shrinks in proportion to how much closer the curve comes to the
central need at the nights' own outdoor temperature (a curve at the need holds the setpoint).
A room held at its setpoint by a thermostat shows no excess, and no heat is counted saved.

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
from .need import COLD_QUANTILE, GRID_T_OUT_C, HeatNeed, Line, heat_w

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
    #: the room above the setpoint at the running curve (measured) and at the recommended
    #: one (estimated) [K]
    room_excess_k: float = 0.0
    room_excess_new_k: float = 0.0

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
                "heat_kwh": round(self.heat_kwh, 0),
                "room_above_setpoint_k": {"running": round(self.room_excess_k, 2),
                                          "recommended": round(self.room_excess_new_k, 2)}}


def season_savings(need: HeatNeed, cop: CopModel, running: Line, recommended: Line,
                   climate: Climate, setpoint_c: float,
                   rng: np.random.Generator, draws: int = DRAWS, *,
                   room_excess_k: float = 0.0, need_at_anchor_c: float | None = None
                   ) -> Savings:
    """The winter's electricity and saving (module docstring).

    ``room_excess_k``: the recorded room's mean above the setpoint on heated hours [K];
    ``need_at_anchor_c``: the central need's flow at the nights' outdoor temperature [°C]
    (without it no excess is counted)."""
    t = climate.t_out_c
    f_run, f_new = running.at(t), recommended.at(t)
    ex_run, ex_new = 0.0, 0.0
    if need_at_anchor_c is not None and room_excess_k > 0.0:
        at = need.anchor_t_out_c if need.anchor_t_out_c is not None else 0.0
        gap_run = float(running.at(at)) - need_at_anchor_c
        if gap_run > 0.0:
            ex_run = float(room_excess_k)
            gap_new = float(recommended.at(at)) - need_at_anchor_c
            ex_new = ex_run * float(np.clip(gap_new / gap_run, 0.0, 1.0))

    def electricity(hlc, gain, eta) -> tuple[np.ndarray, np.ndarray]:
        q_run = heat_w(hlc, gain, setpoint_c + ex_run, t)
        q_new = heat_w(hlc, gain, setpoint_c + ex_new, t)
        run = np.sum(q_run / carnot_cop(f_run, t, eta), axis=-1) / 1000.0
        new = np.sum(q_new / carnot_cop(f_new, t, eta), axis=-1) / 1000.0
        return run, new

    run, new = electricity(need.hlc_w_per_k, need.gain_w, cop.eta)
    hlc, gain = need.draws(rng, draws)
    eta = cop.draws(rng, draws)
    run_d, new_d = electricity(hlc[:, None], gain[:, None], eta[:, None])
    lo, hi = np.quantile(run_d - new_d, [0.025, 0.975])
    return Savings(float(run), float(new), float(run - new), float(lo), float(hi),
                   float(np.sum(need.q_w(setpoint_c, t)) / 1000.0), ex_run, ex_new)
