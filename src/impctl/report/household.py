"""The report's opening, for the people who live in the house: what the nights taught about it
in W and kW at everyday outdoor temperatures, and what the experiment cost them in comfort —
how cold the rooms got and for how long — computed from the stored nights.

Pure numbers first (:func:`heat_loss_rows`, :func:`night_comfort`, :func:`household_summary`),
then the HTML (:func:`household_html`), so the figures can be tested without a page.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime

#: Indoor temperature of the plain-language heat figures [°C] (a usual living-room setpoint).
INDOOR_C = 21.0
#: Outdoor temperatures the figures are given at [°C]: a cold winter night, freezing, and the
#: mild 7 °C at which heat pumps are rated (EN 14511 "A7").
OUTDOOR_C = (-10.0, 0.0, 7.0)
#: The comfort threshold reported besides the experiment's own band [°C]: below 19 °C most
#: people find a living room cool (EN 16798-1 category II heating-season minimum 20 °C,
#: category III 18 °C).
COOL_C = 19.0
#: A gap between two samples longer than this many median steps is not counted as time spent
#: at the earlier reading (the value in between is not known).
_MAX_STEP_FACTOR = 3.0


@dataclass(frozen=True)
class NightComfort:
    """What one stored night did to the rooms (T_air from its samples).

    Attributes
    ----------
    night_id, kind, day : the night, ``constrained`` or ``normal``, local date of its window
    setpoint_c : T_set of the night [°C]; t_min_c : the lower edge of its band [°C] or None
    coldest_c : lowest T_air [°C] (None without readings)
    below_setpoint_h, below_band_h, below_cool_h : time with T_air below T_set, below T_min
        and below :data:`COOL_C` [h] (each sample holds until the next)
    """

    night_id: int
    kind: str
    day: str
    setpoint_c: float
    t_min_c: float | None
    coldest_c: float | None
    below_setpoint_h: float
    below_band_h: float
    below_cool_h: float


def heat_loss_rows(hlc: dict, indoor_c: float = INDOOR_C,
                   outdoor_c: Sequence[float] = OUTDOOR_C) -> list[dict]:
    """Heat the house loses at ``indoor_c`` inside and each outdoor temperature [W]:
    HLC × (T_in − T_out), with the 95 % interval of HLC when it has one.

    ``hlc`` is the fit JSON's ``lumped.hlc`` block (``value``, ``low``, ``high`` in W/K).
    """
    rows = []
    for t_out in outdoor_c:
        dt = indoor_c - t_out
        rows.append({"t_out_c": t_out, "t_in_c": indoor_c, "loss_w": hlc["value"] * dt,
                     "low_w": None if hlc.get("low") is None else hlc["low"] * dt,
                     "high_w": None if hlc.get("high") is None else hlc["high"] * dt})
    return rows


def _hours_below(ts: Sequence[datetime], t_air: Sequence[float | None],
                 threshold_c: float | None) -> float:
    if threshold_c is None or len(ts) < 2:
        return 0.0
    steps = [(b - a).total_seconds() for a, b in zip(ts[:-1], ts[1:], strict=True)]
    longest = _MAX_STEP_FACTOR * sorted(steps)[len(steps) // 2]
    seconds = sum(dt for dt, t in zip(steps, t_air[:-1], strict=True)
                  if t is not None and t < threshold_c and dt <= longest)
    return seconds / 3600.0


def night_comfort(night, samples, day: str = "") -> NightComfort:
    """:class:`NightComfort` of a stored night (:class:`impctl.store.Night`) from its
    samples (:class:`impctl.store.Sample`, in time order)."""
    ts = [s.ts for s in samples]
    t_air = [s.t_air_c if s.t_air_c is not None and math.isfinite(s.t_air_c) else None
             for s in samples]
    readings = [t for t in t_air if t is not None]
    return NightComfort(
        night_id=night.id, kind=night.kind, day=day, setpoint_c=night.setpoint_c,
        t_min_c=night.t_min_c, coldest_c=min(readings) if readings else None,
        below_setpoint_h=_hours_below(ts, t_air, night.setpoint_c),
        below_band_h=_hours_below(ts, t_air, night.t_min_c),
        below_cool_h=_hours_below(ts, t_air, COOL_C))


def household_summary(fit: dict, nights: Sequence[NightComfort]) -> dict:
    """The numbers of the opening: heat loss at :data:`OUTDOOR_C`, the coast, the comfort
    cost over the constrained (heating-off) nights and the normal nights' setpoints."""
    hlc = fit["lumped"]["hlc"]
    flex = fit.get("flexibility")
    if flex is None:  # a result written before the block was: computed as the report does
        from ..fit.result.report import flexibility_block

        flex = flexibility_block(fit)
    off = [n for n in nights if n.kind == "constrained" and n.coldest_c is not None]
    coldest = min(off, key=lambda n: n.coldest_c) if off else None
    held = [n for n in nights if n.kind == "normal" and n.coldest_c is not None]
    return {
        "hlc_w_per_k": hlc["value"], "hlc_low": hlc.get("low"), "hlc_high": hlc.get("high"),
        "hlc_determined": bool(hlc.get("determined", True)),
        "heat_loss": heat_loss_rows(hlc),
        "coast_h": flex.get("coast_h"), "coast_drop_k": flex.get("drop_k"),
        "coast_h_low": flex.get("coast_h_low"), "coast_h_high": flex.get("coast_h_high"),
        "coast_t_out_c": flex.get("t_out_c"),
        "constrained_nights": len(off),
        "coldest_c": None if coldest is None else coldest.coldest_c,
        "coldest_day": None if coldest is None else coldest.day,
        "below_setpoint_h": sum(n.below_setpoint_h for n in off),
        "below_band_h": sum(n.below_band_h for n in off),
        "below_cool_h": sum(n.below_cool_h for n in off),
        "band_low_c": sorted({n.t_min_c for n in off if n.t_min_c is not None}),
        "setpoints_c": sorted({n.setpoint_c for n in off}),
        "normal_nights": len(held),
        "normal_setpoints_c": sorted({n.setpoint_c for n in held}),
    }


def _kw(w: float | None) -> str:
    return "—" if w is None else f"{w / 1e3:.1f}"


def _c(t: float) -> str:
    """A temperature for people: a real minus sign, no trailing zeros."""
    return f"{t:g}".replace("-", "−")


def _temps(values: Sequence[float]) -> str:
    return "/".join(_c(v) for v in values) + " °C"


def household_html(s: dict) -> str:
    """The opening section of the report (HTML) from :func:`household_summary`."""
    e = html.escape
    hlc, lo, hi = s["hlc_w_per_k"], s["hlc_low"], s["hlc_high"]
    iv = (f" (95 % interval {lo:.0f}–{hi:.0f} W per degree)" if lo is not None and hi is not None
          else "")
    cold = s["heat_loss"][0]
    parts = ["<h2>In short: what the nights found out about your house</h2>",
             f"<p class='lead'>Your house loses an estimated <b>{hlc:.0f} W per degree</b> of "
             f"difference between inside and outside{e(iv)}: at {_c(cold['t_out_c'])} °C "
             f"outside and {_c(cold['t_in_c'])} °C inside that is "
             f"<b>{_kw(cold['loss_w'])} kW</b>.</p>"]
    if not s["hlc_determined"]:
        parts.append("<p>These nights did not pin the heat loss down; take the figures as "
                     "a rough guide.</p>")
    rows = "".join(
        f"<tr><td>{_c(r['t_out_c'])} °C</td><td><b>{_kw(r['loss_w'])} kW</b></td>"
        f"<td>{_kw(r['low_w'])}–{_kw(r['high_w'])} kW</td></tr>" for r in s["heat_loss"])
    parts.append(f"<table><thead><tr><th>outside</th><th>heat the house loses at "
                 f"{_c(cold['t_in_c'])} °C inside</th><th>95 % interval</th></tr></thead>"
                 f"<tbody>{rows}</tbody></table>"
                 "<p>The heat pump supplies this minus what people, appliances and the sun "
                 "give off.</p>")
    if s["coast_h"] is not None:
        low, high = s["coast_h_low"], s["coast_h_high"]
        span = (f" (95 % interval {low:.1f}–{high:.1f} h)" if low is not None
                and high is not None else "")
        parts.append(f"<p>With the heating off at {_c(s['coast_t_out_c'])} °C outside, the "
                     f"rooms cool by {s['coast_drop_k']:g} K in about "
                     f"<b>{s['coast_h']:.1f} h</b>{span}.</p>")
    parts.append("<h3>What the experiment cost you in comfort</h3>")
    if s["constrained_nights"]:
        band = _temps(s["band_low_c"]) if s["band_low_c"] else "—"
        parts.append(
            f"<p>On {s['constrained_nights']} night{'s' if s['constrained_nights'] > 1 else ''}"
            f" the heating was switched off. The rooms were at their coldest "
            f"<b>{s['coldest_c']:.1f} °C</b> (the night of {e(s['coldest_day'])}). In all "
            f"they spent <b>{s['below_setpoint_h']:.1f} h</b> below the night's setpoint "
            f"({_temps(s['setpoints_c'])}), <b>{s['below_band_h']:.1f} h</b> below the agreed "
            f"lower limit ({band}, where a night ends and the heating comes back) and "
            f"<b>{s['below_cool_h']:.1f} h</b> below {COOL_C:g} °C.</p>")
    else:
        parts.append("<p>No night with the heating off has readings yet.</p>")
    if s["normal_nights"]:
        parts.append(f"<p>On {s['normal_nights']} night{'s' if s['normal_nights'] > 1 else ''}"
                     f" the rooms were held at {_temps(s['normal_setpoints_c'])} to measure the "
                     "heat the house needs.</p>")
    return "\n".join(parts)
