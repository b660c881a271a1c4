"""What the real house does at switch-off beyond the 5R1C, as the coast uses it.

The fit (:mod:`impctl.fit`) keeps nuisance terms when its likelihood-ratio test says the nights
need them (``impctl.fit.ode.parameters.NUISANCE_NAMES``, the fit JSON's ``"nuisance"``
block): a night gain [W], the emitter's release after switch-off (its time constant [h]) and
the air/furniture capacity at the air node [J/(m²K) of floor]. They are weakly determined: the
fit sees the constrained nights only from one emission lag (1 h) after switch-off, where the
emitter's and the furniture's releases look alike. :func:`switch_off_from_fit` turns them into
the coast's inputs, (value, low, high) each:

* a term whose 95 % interval reaches a bound of the fit's search box is not determined by the
  nights; the coast then takes the documented physical range (real-houses.md): air/furniture
  3 + 0–31 kJ/(m²K) (§1, value its middle), an emitter release slower than the fit's box
  (τ at 8 h) the underfloor screed's 3.5–7 h (§2) — the union with the fit's interval;
* the release in the unobserved first hour may be faster than the tail the fit saw: the low end
  of τ_em reaches down to the radiators' documented 25 min (§2).

Pure data handling: no torch, no pandas.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError

#: The terms the coast uses, in the fit JSON's ``"nuisance"`` names.
SWITCH_OFF_TERMS = ("night_gain_w", "emitter_tau_h", "furniture_j_per_m2k")
#: The fit's search bounds of those terms (``impctl.fit.ode.parameters.NUISANCE_BOUNDS``;
#: repeated so that this module needs no torch — a test keeps them equal). Used when a
#: summary lacks them.
FIT_BOUNDS = {"night_gain_w": (0.0, 500.0), "emitter_tau_h": (0.2, 8.0),
              "furniture_j_per_m2k": (0.0, 40000.0)}
#: Air (1200 J/(m³K) × 2.5 m) + furniture 0–31 kJ/(m²K) [J/(m²K)], real-houses.md §1.
FURNITURE_RANGE = (3000.0, 34000.0)
#: Underfloor screed release time constant [h], real-houses.md §2.
SCREED_TAU_H = (3.5, 7.0)
#: Shortest documented emitter release time constant (steel radiators, 25 min) [h], §2.
RADIATOR_TAU_H = 25.0 / 60.0


@dataclass(frozen=True)
class SwitchOff:
    """The coast's switch-off terms: each field (value, low, high), floats or arrays (n,);
    NaN = the term was not fitted.

    Attributes
    ----------
    night_gain_w : constant heat to the air node (sleepers, base load) [W]
    emitter_tau_h : time constant of the emitter's release after switch-off [h]
    furniture_j_per_m2k : air + furniture capacity at the air node, per m² of floor [J/(m²K)]
    documented : names of the terms replaced by their documented range (per house: a list of
        such tuples, :meth:`stack`)
    """

    night_gain_w: Any = (np.nan, np.nan, np.nan)
    emitter_tau_h: Any = (np.nan, np.nan, np.nan)
    furniture_j_per_m2k: Any = (np.nan, np.nan, np.nan)
    documented: Any = ()

    def values(self, n: int) -> dict[str, np.ndarray]:
        """(3, n) arrays (value, low, high) per term."""
        return {k: np.broadcast_to(np.asarray(getattr(self, k), float).reshape(3, -1),
                                   (3, n)).copy() for k in SWITCH_OFF_TERMS}

    @classmethod
    def stack(cls, items: list[SwitchOff]) -> SwitchOff:
        """Single houses' terms → one object with (3, n) arrays."""
        return cls(**{k: np.stack([np.asarray(getattr(s, k), float) for s in items], axis=-1)
                      for k in SWITCH_OFF_TERMS}, documented=[s.documented for s in items])


def _triple(entry: Any, name: str) -> tuple[float, float, float, tuple[float, float]]:
    if entry is None:
        return np.nan, np.nan, np.nan, FIT_BOUNDS[name]
    try:
        v = tuple(float(entry[k]) if entry.get(k) is not None else np.nan
                  for k in ("value", "low", "high"))
        bounds = tuple(float(b) for b in (entry.get("bounds") or FIT_BOUNDS[name]))
    except (TypeError, ValueError, AttributeError, KeyError):
        raise InputError(f"not an impctl fit result (nuisance {name}: {entry!r})") from None
    return (*v, bounds)


def switch_off_from_fit(summary: dict) -> SwitchOff:
    """The coast's switch-off terms from an ``impctl fit`` summary's ``"nuisance"`` block (the
    module docstring's rules). A term the fit did not keep (null there) is NaN here. A night
    gain the fit assumed (``"assumed": true``, :mod:`impctl.imp.gain`) is used as the fit
    used it, with the assumption's interval, and named in ``documented``."""
    nuis = summary.get("nuisance") or {}
    if not isinstance(nuis, dict):
        raise InputError("not an impctl fit result (nuisance is not a mapping)")
    out, documented = {}, []
    for name in SWITCH_OFF_TERMS:
        value, low, high, (lo_b, hi_b) = _triple(nuis.get(name), name)
        if np.isfinite(value) and (nuis.get(name) or {}).get("assumed"):
            documented.append(name)   # the fit's assumed gain (impctl.imp.gain), not fitted
        if np.isfinite(value):
            low = value if not np.isfinite(low) else low
            high = value if not np.isfinite(high) else high
            span = 1e-3 * (hi_b - lo_b)
            if name == "furniture_j_per_m2k" and low <= lo_b + span:
                value, low, high = (0.5 * sum(FURNITURE_RANGE), min(low, FURNITURE_RANGE[0]),
                                    max(high, FURNITURE_RANGE[1]))
                documented.append(name)
            elif name == "emitter_tau_h" and high >= hi_b - span:
                value, low, high = (0.5 * sum(SCREED_TAU_H), min(low, SCREED_TAU_H[0]),
                                    max(high, SCREED_TAU_H[1]))
                documented.append(name)
            elif name == "emitter_tau_h":
                low = min(low, RADIATOR_TAU_H)
        out[name] = (value, low, high)
    return SwitchOff(**out, documented=tuple(documented))


#: FLEET.parquet columns of the fit's switch-off terms (value, _low, _high), as the fit found
#: them (before the rules above): a fleet row re-simulates like the fit JSON.
COLUMNS = tuple(f"{k}{s}" for k in SWITCH_OFF_TERMS for s in ("", "_low", "_high"))
#: FLEET.parquet column: True when ``night_gain_w`` is the gain the fit assumed
#: (:mod:`impctl.imp.gain`), not one it fitted; empty when no gain was used.
ASSUMED_COLUMN = "night_gain_assumed"


def to_columns(nuisance: dict | None) -> dict[str, float | None]:
    """A fit's ``nuisance`` block → the :data:`COLUMNS` values (None: not fitted) and
    :data:`ASSUMED_COLUMN`."""
    out: dict[str, float | bool | None] = dict.fromkeys((*COLUMNS, ASSUMED_COLUMN))
    for name in SWITCH_OFF_TERMS:
        entry = (nuisance or {}).get(name)
        if entry:
            for key, suffix in (("value", ""), ("low", "_low"), ("high", "_high")):
                out[f"{name}{suffix}"] = entry.get(key)
            if name == "night_gain_w":
                out[ASSUMED_COLUMN] = bool(entry.get("assumed", False))
    return out


def from_columns(row: Any) -> dict:
    """:data:`COLUMNS` (and :data:`ASSUMED_COLUMN`) of a row (a mapping; missing or NaN: not
    fitted) → a ``nuisance`` block for :func:`switch_off_from_fit` (bounds: the fit's,
    :data:`FIT_BOUNDS`)."""
    out: dict[str, dict | None] = {}
    for name in SWITCH_OFF_TERMS:
        v = row.get(name) if hasattr(row, "get") else None
        if v is None or not np.isfinite(float(v)):
            out[name] = None
            continue
        lo, hi = (row.get(f"{name}{s}") for s in ("_low", "_high"))
        out[name] = {"value": float(v), "low": None if lo is None else float(lo),
                     "high": None if hi is None else float(hi), "bounds": FIT_BOUNDS[name]}
        if name == "night_gain_w" and _true(row.get(ASSUMED_COLUMN)):
            out[name]["assumed"] = True
    return out


def _true(flag: Any) -> bool:
    # a Parquet bool read back through pandas may be None, NaN, numpy.bool_ or a float
    try:
        return flag is not None and bool(np.isfinite(float(flag))) and bool(flag)
    except (TypeError, ValueError):
        return False
