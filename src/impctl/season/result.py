"""The season fit's result: HLC, τ and C_m with their 95 % intervals and what they rest on —
the owner and IMP nights, the emitter, the defrosts' draw, the change test — as JSON
(:meth:`SeasonFit.as_dict`) and as the report's lines (:func:`format_season`). Units in every
name."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..change import Change
from .emitter import REFERENCE_DT_K, decay_decides, emitter_kind, tau_e_max_s
from .projection.columns import THETA
from .projection.uncertainty import LUMPED


@dataclass
class SeasonFit:
    """The season model's result (:func:`~.fit.fit_season`).

    Attributes
    ----------
    values : HLC [W/K], τ [h], C_m [J/K] (keys of :data:`~.projection.uncertainty.LUMPED`)
    low, high : their 95 % interval bounds, same keys and units
    owner_nights : owner nights (local days) with rows the likelihood used
    imp_nights : IMP nights with rows it used
    used_h : hours of rows in the likelihood [h]
    left_out_h : hours left out, by reason [h]
    theta : the nonlinear parameters (τ_mm [s], w [-], τ_e [s], f_sun [-], τ_r [s])
    beta : the fixed linear parameters (K_ao, K_am [W/K], gains levels [W], defrost [W])
    signature_hlc_w_per_k : the energy signature's slope on the same owner nights [W/K]
        (NaN with fewer than three)
    change : the change test on the owner nights (:mod:`.change`), None when not run
    convergence : the estimate against the number of owner nights
        (:func:`~.convergence.convergence`), empty when not computed
    missing : why a quantity is not given (NaN), when it is for a reason other than the fit's
        own (τ and C_m without the IMP nights: :data:`NEEDS_IMP`)
    emitter : "radiators" or "underfloor": declared (``emitter_declared``) or read from the
        heating water (:mod:`.emitter`); None when neither tells it
    water_excess_k : the water's excess over the room at the reference load [K] (NaN: unknown)
    water_decay_h : how fast the water's excess fades after a switch-off [h] (NaN: not read)
    lag_bound_s : the bound the emitter's lag was searched under [s]
    emitter_declared : True when the emitter was declared (known), not read from the water
    warm_start : the search started only from an earlier fit's θ (``start``); False when it
        ran in full, also when a start was given and the full search had to decide
    defrost_read : whether the record holds the heat the defrosts drew from the water
        (:meth:`~.record.SeasonRecord.meter_reads_defrosts`: True, measured; False, the draw
        estimated, ``beta["defrost_w"]``; None, no defrost recorded)
    defrost_from_spread : that heat was read from the flow–return spread, the meter reading
        positive heat only (:mod:`.defrost`)
    spread_unread : why the spread did not give it where it is estimated ("" else)
    """

    values: dict[str, float]
    low: dict[str, float]
    high: dict[str, float]
    owner_nights: int
    imp_nights: int
    used_h: float
    left_out_h: dict[str, float] = field(default_factory=dict)
    theta: tuple[float, ...] = ()
    beta: dict[str, float] = field(default_factory=dict)
    signature_hlc_w_per_k: float = float("nan")
    change: Change | None = None
    convergence: list[dict] = field(default_factory=list)
    missing: dict[str, str] = field(default_factory=dict)
    emitter: str | None = None
    water_excess_k: float = float("nan")
    water_decay_h: float = float("nan")
    lag_bound_s: float = float("nan")
    emitter_declared: bool = False
    warm_start: bool = False
    defrost_read: bool | None = None
    defrost_from_spread: bool = False
    spread_unread: str = ""

    def defrost_by(self) -> str | None:
        """What gave the heat the defrosts drew from the water: "heat meter" or
        "flow-return spread" (measured), "estimated" (fitted); None without a defrost."""
        if self.defrost_read is None:
            return None
        if not self.defrost_read:
            return "estimated"
        return "flow-return spread" if self.defrost_from_spread else "heat meter"

    def defrost_source(self) -> str:
        """:meth:`defrost_by` in words, measured or estimated first; "" without a defrost."""
        by = self.defrost_by()
        if by == "estimated":
            return ("estimated: the heat meter reads no heat drawn while defrosting"
                    + (f"; {self.spread_unread}" if self.spread_unread else ""))
        if by == "flow-return spread":
            return ("measured: read from the flow–return spread, scaled by the meter's "
                    "heating around each defrost (the meter reads positive heat only)")
        return "measured: the heat meter reads it" if by else ""

    def as_dict(self) -> dict:
        """JSON-ready, units in the names."""
        return {
            "model": "season 5R1C, demand form (variable projection)",
            **{k: {"value": _num(self.values[k]), "low": _num(self.low[k]),
                   "high": _num(self.high[k]),
                   **({"why_missing": self.missing[k]} if k in self.missing else {})}
               for k in LUMPED},
            "owner_nights": self.owner_nights,
            "imp_nights": self.imp_nights,
            "used_h": round(self.used_h, 2),
            "left_out_h": {k: round(v, 2) for k, v in self.left_out_h.items()},
            "baseline_signature_hlc_w_per_k": (None if not math.isfinite(
                self.signature_hlc_w_per_k) else self.signature_hlc_w_per_k),
            "emitter": self.emitter_dict(),
            **({} if self.defrost_read is None else {"defrost_draw": {
                "source": self.defrost_source()}}),
            "interval": "95 %: day-clustered sandwich, scaled, with a model-error floor, both "
                        "estimated on simulated seasons",
            # the search's own coordinates: a later fit of the same house starts from them
            **({"theta": dict(zip(THETA, self.theta, strict=True))}
               if len(self.theta) == len(THETA) else {}),
            **({"change": {**self.change.as_dict(), "fit_reads": "all nights"}}
               if self.change is not None else {}),
            **({"convergence": self.convergence} if self.convergence else {}),
        }


    def _bound_h(self) -> float:
        """The bound the emitter's lag was searched under [h]."""
        if math.isfinite(self.lag_bound_s):
            return round(self.lag_bound_s / 3600.0, 2)
        return tau_e_max_s(self.emitter) / 3600.0

    def emitter_dict(self) -> dict:
        """The emitter the lag's bound was chosen for, and whether declared, measured or
        assumed."""
        if self.emitter_declared:
            read = emitter_kind(self.water_excess_k, self.water_decay_h)
            return {"kind": self.emitter, "water_excess_k": _num(round(self.water_excess_k, 1)),
                    "water_decay_h": _num(round(self.water_decay_h, 1)),
                    "tau_e_max_h": self._bound_h(),
                    "source": "declared", **({"water_reads": read} if read not in
                                             (None, self.emitter) else {})}
        if self.emitter is None:
            return {"kind": None, "tau_e_max_h": self._bound_h(),
                    "source": "assumed: no heating-water temperatures recorded and none "
                              "declared, a bound between the radiators' and the screed's"}
        decay = decay_decides(self.water_excess_k, self.water_decay_h)
        return {"kind": self.emitter, "water_excess_k": round(self.water_excess_k, 1),
                "water_decay_h": _num(round(self.water_decay_h, 1)),
                "tau_e_max_h": self._bound_h(),
                "source": "measured: " + ("how fast the heating water cools after a switch-off "
                                          "(its excess over the room could be either)" if decay
                                          else "the heating water's excess over the room")}


def theta_of(result: dict) -> tuple[float, ...] | None:
    """The season model's θ in a fit JSON (``season.theta``,
    :data:`~.projection.columns.THETA` units), None when it has none or it is not a set of
    finite positive numbers."""
    block = (result.get("season") or {}).get("theta") if isinstance(result, dict) else None
    if not isinstance(block, dict):
        return None
    try:
        theta = tuple(float(block[k]) for k in THETA)
    except (KeyError, TypeError, ValueError):
        return None
    return theta if all(math.isfinite(t) and t > 0 for t in theta) else None


def _num(x: float) -> float | None:
    """A JSON number, or None for a value the model could not give."""
    return float(x) if math.isfinite(x) else None


def format_season(fit: SeasonFit) -> list[str]:
    """The season result as text lines (values, 95 % intervals, what they rest on)."""
    lines = [f"season model: {fit.owner_nights} owner nights and {fit.imp_nights} IMP nights, "
             f"{fit.used_h:.0f} h of rows"]
    for key, name, unit, scale in (("hlc_w_per_k", "HLC", "W/K", 1.0),
                                   ("tau_h", "tau", "h", 1.0),
                                   ("c_m_j_per_k", "C_m", "kWh/K", 1 / 3.6e6)):
        v = fit.values[key]
        if not math.isfinite(v):
            why = fit.missing.get(key, "not determined by the model")
            lines.append(f"  {name:<5}{'—':>9} {unit:<6} {why}")
            continue
        lines.append(f"  {name:<5}{v * scale:9.2f} {unit:<6} 95 % {fit.low[key] * scale:.2f} – "
                     f"{fit.high[key] * scale:.2f}")
    if fit.emitter is None:
        lines.append("  emitter: not known (assumed: its lag up to "
                     f"{fit._bound_h():g} h; no heating-water temperatures recorded "
                     "and none declared)")
    elif fit.emitter_declared:
        read = emitter_kind(fit.water_excess_k, fit.water_decay_h)
        lines.append(f"  emitter: {fit.emitter} (declared; its lag up to "
                     f"{fit._bound_h():g} h)"
                     + (f" — the heating water reads {read}: is the declaration right?"
                        if read not in (None, fit.emitter) else ""))
    else:
        fade = (f", its excess fading in {fit.water_decay_h:.1f} h after a switch-off"
                if decay_decides(fit.water_excess_k, fit.water_decay_h) else "")
        lines.append(f"  emitter: {fit.emitter} (measured: the water {fit.water_excess_k:.0f} K "
                     f"above the room at {REFERENCE_DT_K:.0f} K indoors–outdoors{fade}; its lag "
                     f"up to {fit._bound_h():g} h)")
    if math.isfinite(fit.signature_hlc_w_per_k):
        lines.append(f"  baseline: the energy signature of the same owner nights gives HLC "
                     f"{fit.signature_hlc_w_per_k:.1f} W/K")
    c = fit.change
    if c is not None and c.changed:
        lines.append(f"  changed since {c.since_date}: heat loss {c.delta_hlc_w_k:+.0f} W/K "
                     f"(95 % {c.low_w_k:+.0f} – {c.high_w_k:+.0f}), {c.nights_after} owner "
                     "nights after it; the estimate above still reads the nights before it")
    if fit.defrost_by() in ("estimated", "flow-return spread"):  # a signed meter: nothing
        lines.append(f"  defrosts: the heat they draw from the water is {fit.defrost_source()}")
    if fit.left_out_h:
        lines.append("  left out: " + ", ".join(f"{k} {h:.0f} h"
                                               for k, h in sorted(fit.left_out_h.items())))
    return lines
