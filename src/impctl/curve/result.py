"""The curve result: the JSON ``impctl curve --json`` writes and the words a house owner reads.

The words say what to do in plain terms — how much hotter the heating water runs than the
house needs, what to set instead, what it saves — and no abbreviation an owner would have to
look up.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .cop import CopModel
from .emitter import EmitterFit
from .need import CONFIDENCE, HeatNeed, Line, NeedCurve
from .running import RunningCurve
from .savings import Climate, Savings

SCHEMA = "impctl-curve/1"
#: A running curve within this of the recommended one at 0 °C is "about right" [K].
ABOUT_RIGHT_K = 0.5
#: A mean room this far above the setpoint is said in the advice [K].
WARM_ROOM_K = 0.3


@dataclass(frozen=True)
class CurveResult:
    """Everything ``impctl curve`` found (docs/reference/curve-json.md)."""

    setpoint_c: float
    setpoint_source: str
    margin_k: float
    emitter: EmitterFit
    need: HeatNeed
    need_curve: NeedCurve
    recommended: Line
    running: RunningCurve | None
    cop: CopModel
    climate: Climate
    savings: Savings | None
    notes: list[str] = field(default_factory=list)
    cold_hours: int = 0
    heated_hours: int = 0

    # -- what it means -------------------------------------------------------------------
    @property
    def hotter_at_0_k(self) -> float | None:
        """How much hotter the running curve is than the recommended one at 0 °C [K]."""
        if self.running is None:
            return None
        return float(self.running.line.at(0.0) - self.recommended.at(0.0))

    @property
    def lowers(self) -> bool:
        """The recommended curve is lower than the running one where the winter needs most."""
        hot = self.hotter_at_0_k
        return hot is not None and hot >= ABOUT_RIGHT_K and (
            self.savings is None or self.savings.saving_kwh > 0)

    def suggested_flow_c(self, t_out_c: float) -> float:
        """The recommended curve's flow temperature at ``t_out_c`` [°C]."""
        return round(float(self.recommended.at(t_out_c)), 1)

    def advice(self) -> str:
        """What the owner should do, in plain words (a few sentences)."""
        rec = self.recommended
        setting = (f"{rec.flow_a_c:.0f} °C at −15 °C outside and {rec.flow_b_c:.0f} °C at "
                   f"+15 °C")
        if self.running is None:
            return ("impctl could not tell which heating curve your heat pump runs (no flow "
                    f"temperatures recorded). This house needs about {setting}; compare it "
                    "with the heating curve set in your heat pump.")
        hot = self.hotter_at_0_k
        parts = []
        if self.running.constant:
            parts.append(f"Your heat pump holds its water at about "
                         f"{self.running.line.at(0.0):.0f} °C whatever the weather outside: a "
                         "constant flow temperature, not a heating curve. Set it to follow the "
                         "weather (its heating curve) to use what follows.")
        if self.lowers:
            s = self.savings
            parts.append(f"Your heating runs its water {hot:.0f} K hotter than this house "
                         f"needs at 0 °C outside. Setting the heating curve to {setting} "
                         "keeps the rooms at "
                         f"{self.setpoint_c:.1f} °C, the water still {self.margin_k:g} K warmer "
                         "than the least it needs,")
            if s is not None:
                parts[-1] += (f" and would save about {_kwh(s.saving_kwh)} of electricity "
                              f"over {self.climate.describe()} (between "
                              f"{_kwh(max(s.saving_low_kwh, 0.0))} and "
                              f"{_kwh(s.saving_high_kwh)}; {s.percent:.0f} % of the heating's)")
            parts[-1] += "."
            if s is not None and s.room_excess_k >= WARM_ROOM_K:
                parts.append(f"Your rooms run {s.room_excess_k:.1f} K above "
                             f"{self.setpoint_c:.1f} °C on average: part of the saving is the "
                             "heat that warmth costs.")
        elif hot is not None and hot <= -ABOUT_RIGHT_K:
            parts.append(f"Your heating runs its water {-hot:.0f} K cooler than impctl would "
                         f"set it at 0 °C outside ({setting}, {self.margin_k:g} K warmer than "
                         "the least the house needs). Keep it unless the rooms get cold: "
                         "lowering it saves nothing.")
        else:
            parts.append("Your heating curve is already about as low as this house allows "
                         f"(within {ABOUT_RIGHT_K:g} K of {setting} at 0 °C outside): "
                         "lowering it further would save little and risk cold rooms.")
        if self.cold_hours:
            parts.append(f"On {self.cold_hours} of {self.heated_hours} recorded heated hours "
                         f"the room was more than 0.5 K below {self.setpoint_c:.1f} °C.")
        return " ".join(parts)

    # -- JSON ----------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """The ``impctl-curve/1`` JSON object."""
        nc = self.need_curve
        out = {
            "schema": SCHEMA,
            "setpoint_c": {"value": self.setpoint_c, "source": self.setpoint_source},
            "margin_k": self.margin_k,
            "confidence": CONFIDENCE,
            "emitter": self.emitter.to_dict(),
            "heat_need": self.need.to_dict(),
            "need": {"t_out_c": [round(float(v), 1) for v in nc.t_out_c],
                     "flow_c": [round(float(v), 2) for v in nc.central_c],
                     "flow_upper_c": [round(float(v), 2) for v in nc.upper_c],
                     "heat_w": [round(float(v), 0) for v in nc.q_w]},
            "recommended": self.recommended.to_dict(),
            "running": None if self.running is None else self.running.to_dict(),
            "hotter_at_0_k": (None if self.hotter_at_0_k is None
                              else round(self.hotter_at_0_k, 1)),
            "lowers": self.lowers,
            "cop": self.cop.to_dict(),
            "savings": None,
            "comfort": {"cold_hours": self.cold_hours, "heated_hours": self.heated_hours},
            "advice": self.advice(),
            "notes": list(self.notes),
        }
        if self.savings is not None:
            out["savings"] = {**self.savings.to_dict(),
                              "climate": self.climate.to_dict(self.setpoint_c)}
        return out

    def lines(self) -> list[str]:
        """The console text: the advice, then the numbers behind it."""
        rec = self.recommended
        out = [self.advice(), ""]
        out.append(f"  the curve this house needs:  {rec.flow_a_c:5.1f} °C at −15 °C, "
                   f"{rec.at(0.0):5.1f} °C at 0 °C, {rec.flow_b_c:5.1f} °C at +15 °C "
                   f"(room {self.setpoint_c:.1f} °C, {self.setpoint_source}; "
                   f"{self.margin_k:g} K margin, {CONFIDENCE:.0%} sure)")
        if self.running is not None:
            r = self.running.line
            what = ("the heat pump's flow target" if self.running.source == "target"
                    else "the measured flow temperature")
            out.append(f"  the curve it runs:           {r.flow_a_c:5.1f} °C at −15 °C, "
                       f"{r.at(0.0):5.1f} °C at 0 °C, {r.flow_b_c:5.1f} °C at +15 °C "
                       f"(from {what}, {self.running.hours} h)")
        e = self.emitter.interval()
        out.append(f"  radiators/floor measured:    {e['k_w_per_k_n']['value']:.1f} W/K^n, "
                   f"n = {e['exponent']['value']:.2f} ({e['exponent']['low']:.2f}–"
                   f"{e['exponent']['high']:.2f}) from {self.emitter.blocks} blocks "
                   f"of {self.emitter.nights} nights")
        n = self.need
        out.append(f"  heat loss:                   {n.hlc_w_per_k:.0f} W/K "
                   f"({n.hlc_low:.0f}–{n.hlc_high:.0f}, {n.hlc_source}); other heat "
                   f"{n.gain_w:.0f} W, ± {n.gain_sd_w:.0f} W from night to night ({n.gain_source})")
        c = self.cop
        out.append(f"  efficiency:                  {c.eta:.2f} of the ideal (Carnot) "
                   + ("— ASSUMED, the nights carry no electrical power" if c.assumed else
                      f"± {c.eta_sd:.2f}, fitted to {c.blocks} blocks"))
        if self.savings is not None:
            s = self.savings
            out.append(f"  electricity over the winter: {s.running_kwh:.0f} kWh now, "
                       f"{s.recommended_kwh:.0f} kWh with the curve above "
                       f"({self.climate.describe()})")
        out.extend(f"  note: {note}" for note in self.notes)
        return out


def _kwh(x: float) -> str:
    return f"{x:,.0f} kWh" if abs(x) >= 10 else f"{x:.0f} kWh"

