"""What is published: the live state object and the fit results, as JSON-ready dicts.

Units are in the key names (``_c`` °C, ``_w`` W, ``_h`` h). A value that is missing is
``null`` (Home Assistant shows "unknown"), never a number.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from typing import Any


@dataclass
class LiveState:
    """Everything ``<base>/state`` carries; the daemon fills it, the bridge publishes it.

    Attributes
    ----------
    ts : when the values were read (aware), or None
    t_air_c, t_out_c : °C; q_hc_w : W (None = missing)
    night_state : "idle", "preparing", "active" or "restoring"
    night_kind : "constrained", "normal" or "none"
    night_id : id of the running night, or None
    campaign_valid, campaign_planned : nights
    link_ok : the last read of the heat pump succeeded
    writes : register → "used/limit" today
    skip_tonight : a skip request is pending
    restore_pending : journaled registers still to restore
    campaign_mode : "adaptive" or "fixed"
    nights_run, nights_valid : nights the campaign ran (valid or not) / that were valid
    hlc_rel_pct, tau_rel_pct : the last fit's 95 % half-widths relative to the estimates [%]
        (None = no fit yet, or not determined)
    campaign_status : short text (a Home Assistant state holds ≤ 255 characters);
        campaign_reason : the campaign's last decision in one sentence
    energy_el_kwh, energy_heat_kwh : the heat pump's lifetime counters (heating + hot water):
        electricity it used and heat it delivered [kWh]
    next_night_at : when the next night's preheat starts (aware), None = none planned
    suggested_flow_c : the flow temperature the recommended heating curve gives at the
        outdoor temperature now [°C] (None = no curve yet)
    """

    ts: datetime | None = None
    t_air_c: float | None = None
    t_out_c: float | None = None
    q_hc_w: float | None = None
    night_state: str = "idle"
    night_kind: str = "none"
    night_id: int | None = None
    campaign_valid: int = 0
    campaign_planned: int = 0
    link_ok: bool = False
    writes: dict[str, str] = field(default_factory=dict)
    skip_tonight: bool = False
    restore_pending: list[str] = field(default_factory=list)
    campaign_mode: str = "fixed"
    nights_run: int = 0
    nights_valid: int = 0
    hlc_rel_pct: float | None = None
    tau_rel_pct: float | None = None
    campaign_status: str = ""
    campaign_reason: str = ""
    energy_el_kwh: float | None = None
    energy_heat_kwh: float | None = None
    next_night_at: datetime | None = None
    suggested_flow_c: float | None = None

    def as_json(self) -> dict[str, Any]:
        """The JSON object of ``<base>/state``."""
        used = 0
        for text in self.writes.values():
            used += int(text.split("/")[0])
        return {
            "ts": None if self.ts is None else self.ts.isoformat(),
            "t_air_c": _round(self.t_air_c, 2), "t_out_c": _round(self.t_out_c, 2),
            "q_hc_w": _round(self.q_hc_w, 0),
            "night_state": self.night_state, "night_kind": self.night_kind,
            "night_id": self.night_id,
            "experiment_active": self.night_state in ("preparing", "active", "restoring"),
            "campaign": f"{self.campaign_valid}/{self.campaign_planned}",
            "campaign_valid": self.campaign_valid, "campaign_planned": self.campaign_planned,
            "link_ok": self.link_ok, "writes_today": used, "writes": dict(self.writes),
            "skip_tonight": self.skip_tonight, "restore_pending": list(self.restore_pending),
            "campaign_mode": self.campaign_mode, "nights_run": self.nights_run,
            "nights_valid": self.nights_valid, "hlc_rel_pct": _round(self.hlc_rel_pct, 1),
            "tau_rel_pct": _round(self.tau_rel_pct, 1),
            "campaign_status": self.campaign_status[:255],
            "campaign_reason": self.campaign_reason,
            "energy_el_kwh": _round(self.energy_el_kwh, 1),
            "energy_heat_kwh": _round(self.energy_heat_kwh, 1),
            "next_night_at": None if self.next_night_at is None else (
                self.next_night_at.isoformat(timespec="seconds")),
            "suggested_flow_c": _round(self.suggested_flow_c, 1),
        }


def _round(value: float | None, digits: int) -> float | None:
    return None if value is None else round(float(value), digits)


def fit_payloads(fit: tuple[datetime, list[int], dict] | None) -> dict[str, dict]:
    """The retained ``<base>/fit/<name>`` payloads from the store's last fit.

    HLC in W/K, C_m in MJ/K (the fit JSON holds J/K), τ and the coast time in h. The interval
    goes to attributes (``low``, ``high``); a quantity the nights do not determine
    (``determined: false``) has ``value: null`` and keeps its interval: it is never shown as
    measured. Where the fit carries the season model (owner nights recorded), its value and
    interval are shown instead, with ``source: season model`` and the count of owner nights
    behind them (``owner_nights``). The season HLC also says whether the house changed
    (``changed_since``: the date of the first night after a step in its heat loss, null when
    none was found; ``change_w_per_k`` with ``change_low``/``change_high``: the step [W/K]).
    ``coast_h`` comes from the fit's ``flexibility`` block, null when absent.
    """
    if fit is None:
        return {name: {"value": None} for name in ("hlc", "c_m", "tau", "coast_h")}
    created, nights, result = fit
    common = {"fit_created": created.isoformat(), "nights": list(nights)}
    lumped = result.get("lumped") or {}
    out: dict[str, dict] = {}
    for name, scale, unit in (("hlc", 1.0, "W/K"), ("c_m", 1e-6, "MJ/K"), ("tau", 1.0, "h")):
        q = lumped.get(name) or {}
        determined = bool(q.get("determined", False))

        def scaled(key: str, q: dict = q, scale: float = scale) -> float | None:
            v = q.get(key)
            return None if v is None else round(float(v) * scale, 3)

        out[name] = {"value": scaled("value") if determined else None,
                     "low": scaled("low"), "high": scaled("high"),
                     "determined": determined, "unit": unit, "source": "IMP nights", **common}
        sq = (result.get("season") or {}).get(_SEASON_KEYS[name])
        if sq and sq.get("value") is not None:
            # The season model reads every recorded night: its number, when there is one.
            out[name].update(value=scaled("value", sq), low=scaled("low", sq),
                             high=scaled("high", sq), determined=True,
                             source="season model",
                             owner_nights=result["season"].get("owner_nights"))
            determined = True
            if name == "hlc":
                out[name].update(_change_attributes(result["season"].get("change")))
        if name == "hlc" and determined and out[name]["value"] is not None:
            out[name]["heat_loss"] = heat_loss_words(out[name]["value"])
    flex = result.get("flexibility") or {}
    coast = flex.get("coast_h")
    out["coast_h"] = {"value": None if coast is None else round(float(coast), 2),
                      "low": flex.get("coast_h_low"), "high": flex.get("coast_h_high"),
                      "rebound_kwh": flex.get("rebound_kwh"), "unit": "h", **common}
    return out


def _change_attributes(change: dict | None) -> dict:
    """The season HLC's change attributes from the fit JSON's ``season.change`` (nulls when
    the test found no change, or did not run)."""
    c = change or {}
    found = bool(c.get("changed"))
    return {"changed_since": c.get("since_date") if found else None,
            "change_w_per_k": c.get("delta_hlc_w_k") if found else None,
            "change_low": c.get("lo") if found else None,
            "change_high": c.get("hi") if found else None}


#: The season block's key of each sensor's quantity.
_SEASON_KEYS = {"hlc": "hlc_w_per_k", "c_m": "c_m_j_per_k", "tau": "tau_h"}
#: The conditions of the plain-words heat loss: a cold winter night and a usual room [°C].
WORDS_T_OUT_C, WORDS_T_IN_C = -10.0, 21.0


def heat_loss_words(hlc_w_per_k: float) -> str:
    """The heat loss coefficient in plain words, e.g. "loses 106 W per °C of difference
    between inside and outside: 3.3 kW at −10 °C outside with 21 °C inside"."""
    at_w = hlc_w_per_k * (WORDS_T_IN_C - WORDS_T_OUT_C)
    return (f"loses {hlc_w_per_k:.0f} W per °C of difference between inside and outside: "
            f"{at_w / 1000:.1f} kW at {WORDS_T_OUT_C:g} °C outside with {WORDS_T_IN_C:g} °C "
            "inside").replace("-", "−")


def curve_payload(curve: dict | None) -> dict:
    """The retained ``<base>/curve`` payload from the kept heating-curve result
    (``impctl-curve/1``): the expected saving over a winter [kWh] as the value (null when
    the curve it runs is unknown, or when none is kept), its interval and the advice in plain
    words as attributes, and the recommended curve's flows at −15, 0 and +15 °C outside."""
    if curve is None:
        return {"value": None}
    savings = curve.get("savings") or {}
    saving = (savings.get("saving_kwh") or {})
    rec = curve.get("recommended") or {}
    run = curve.get("running") or {}
    flows = rec.get("flow_c") or [None, None]
    if not saving:
        value = None  # the curve it runs is unknown, so is the saving
    elif curve.get("lowers"):
        value = saving.get("value")
    else:
        value = 0.0  # the curve is kept: nothing to save
    return {
        "value": value,
        "low": saving.get("low"), "high": saving.get("high"), "unit": "kWh",
        "advice": str(curve.get("advice", "")),
        "curve_at_minus_15_c": flows[0], "curve_at_0_c": rec.get("flow_at_0_c"),
        "curve_at_plus_15_c": flows[1], "running_at_0_c": run.get("flow_at_0_c"),
        "hotter_at_0_k": curve.get("hotter_at_0_k"),
        "winter": (savings.get("climate") or {}).get("description"),
        "efficiency_assumed": bool((curve.get("cop") or {}).get("assumed", True)),
    }
