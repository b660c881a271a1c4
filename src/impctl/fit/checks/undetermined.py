"""What a fit must not report as determined: nuisance terms at a bound, Table IV parameters
the data leave to their range.

* :func:`nuisance_at_bound` — a fitted nuisance term that ends at the edge of its box has not
  been estimated: the bound, not the nights, set it, and the quantities it trades against are
  not determined either (an emitter release at its 4 kW bound stands in for heat the model
  puts nowhere else: C_m and τ are then what that bound makes them);
* :func:`table_iv` — a Table IV parameter the data do not determine is reported as its prior
  (the centre of its search range, the prior-midpoint baseline), never as a fitted value
  the data do not support, which on average is further from the truth.
"""

from __future__ import annotations

from ..nights.data import Estimate

#: A term within this share of its box's width from a bound sits at the bound.
AT_BOUND_SHARE = 0.01
#: Per nuisance term: (which bound matters, what it is called, the lumped quantities it
#: leaves undetermined). The lower bounds of the release, its time constant and the
#: air/furniture capacity are 0 / "not needed", which determines nothing away.
_AFFECTS = {
    "emitter_w": ("high", "emitter release", ("c_m", "tau")),
    "emitter_tau_h": ("high", "emitter release time constant", ("c_m", "tau")),
    "furniture_j_per_m2k": ("high", "air/furniture capacity", ("c_m", "tau")),
    "emitter_share": ("high", "emitter share of C_m", ("c_m", "tau")),
    # 0 W is a real gain (an empty house); 500 W is the box, not a household
    "night_gain_w": ("high", "night gain", ("hlc", "c_m")),
}
_UNITS = {"emitter_w": (1e-3, "kW"), "emitter_tau_h": (1.0, "h"),
          "furniture_j_per_m2k": (1e-3, "kJ/(m²K)"), "emitter_share": (1.0, ""),
          "night_gain_w": (1.0, "W")}
_NAMES = {"hlc": "HLC", "c_m": "C_m", "tau": "τ"}


def nuisance_at_bound(nuisance: dict) -> list[dict]:
    """The fitted nuisance terms (``nuisance_`` entries, not pinned ones) at a bound of their
    box: per term its name, value, the bound, the lumped quantities it leaves undetermined
    and the plain statement."""
    out = []
    for name, entry in (nuisance or {}).items():
        if not entry or name not in _AFFECTS or entry.get("pinned"):
            continue
        lo, hi = entry["bounds"]
        side, label, affects = _AFFECTS[name]
        width = hi - lo
        if width <= 0:
            continue
        v = entry["value"]
        at = ("high" if v >= hi - AT_BOUND_SHARE * width else
              "low" if v <= lo + AT_BOUND_SHARE * width else None)
        if at is None or (side != "both" and at != side):
            continue
        bound = hi if at == "high" else lo
        k, unit = _UNITS[name]
        what = ", ".join(_NAMES[a] for a in affects)
        out.append({"term": name, "value": v, "bound": bound, "affects": list(affects),
                    "statement": f"{label} at its {k * bound:g}{' ' if unit else ''}{unit} "
                                 f"bound: {what} not determined"})
    return out


def mark_undetermined(lumped: dict[str, Estimate], at_bound: list[dict]
                      ) -> dict[str, Estimate]:
    """``lumped`` with every quantity a term at its bound affects marked not determined."""
    hit = {a for t in at_bound for a in t["affects"]}
    return {k: (Estimate(e.value, e.low, e.high, False) if k in hit else e)
            for k, e in lumped.items()}


def table_iv(parameters: dict[str, float], determined: dict[str, bool],
             bounds: dict[str, tuple[float, float]]) -> dict[str, dict]:
    """Per Table IV parameter the value to report: the fitted one where the data determine
    it, else its prior — the centre of the search range it was fitted in — with both kept."""
    out = {}
    for name, x in parameters.items():
        lo, hi = bounds[name]
        prior = 0.5 * (lo + hi)
        data = bool(determined.get(name))
        out[name] = {"value": float(x) if data else prior, "source": "data" if data else "prior",
                     "fitted": float(x), "prior": prior}
    return out
