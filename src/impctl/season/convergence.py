"""How the season estimate settles as owner nights accrue: the fit on the first N of them.

:func:`convergence` refits the season model on the record cut after the 7th, 14th, 28th and
56th usable owner night (those fewer than the record holds), each search warm-started at the
full fit's time constants, and gives each cut's HLC, τ and C_m with their 95 % intervals —
the curve an owner or an aggregator reads to see whether more nights would still move the
number. Units in every name.
"""

from __future__ import annotations

import math

import numpy as np

from .emitter import tau_e_max_s
from .fit import fit_season
from .projection.uncertainty import LUMPED
from .result import SeasonFit

#: The owner-night counts the curve is given at [-].
STEPS = (7, 14, 28, 56)
#: Evaluations a cut's search may take from the full fit's θ [-]: on 6 simulated households
#: (8 IMP + 56 owner nights) 30 changed no value or bound by more than 0.05 % and took one
#: curve 1.31 → 0.92 CPU-s; 20 moved them by up to 2 %.
CUT_MAX_NFEV = 30

_NAMES = {"hlc_w_per_k": ("HLC", "W/K", 1.0), "tau_h": ("tau", "h", 1.0),
          "c_m_j_per_k": ("C_m", "kWh/K", 1 / 3.6e6)}


def _usable_owner(nights) -> list:
    """The owner records the model reads (no label), in time order."""
    return sorted((n for n in nights if n.kind == "owner" and not getattr(n, "label", "")),
                  key=lambda n: n.start)


def convergence(nights, full: SeasonFit | None = None) -> list[dict]:
    """Per count in :data:`STEPS` below the record's usable owner nights: ``owner_nights`` and
    each quantity's ``value``, ``low``, ``high`` (JSON units: W/K, h, J/K; None where not
    determined), the full fit last when given."""
    from .nights import record_from_nights

    owner = _usable_owner(nights)
    out = []
    for n in STEPS:
        if n >= len(owner):
            break
        end = owner[n - 1].start + _span(owner[n - 1])
        cut = [x for x in nights if x.start < end]
        try:
            start = full.theta if full is not None and full.theta else None
            fit = fit_season(record_from_nights(cut), start=start, max_nfev=CUT_MAX_NFEV,
                             emitter=full.emitter if full is not None and full.emitter_declared
                             else None,
                             start_bound_s=tau_e_max_s(full.emitter) if start else None)
        except (ValueError, np.linalg.LinAlgError):
            continue
        out.append(_row(n, fit))
    if full is not None:
        out.append(_row(full.owner_nights, full))
    return out


def _span(night):
    import pandas as pd

    return pd.Timedelta(seconds=float(np.asarray(night.time_s, float)[-1]))


def _row(n: int, fit: SeasonFit) -> dict:
    def num(x: float) -> float | None:
        return float(x) if math.isfinite(x) else None

    return {"owner_nights": n, **{k: {"value": num(fit.values[k]), "low": num(fit.low[k]),
                                      "high": num(fit.high[k])} for k in LUMPED}}


def format_convergence(rows: list[dict]) -> list[str]:
    """The curve as text lines: one per owner-night count."""
    if len(rows) < 2:
        return []
    lines = ["  against owner nights (95 % intervals):"]
    for r in rows:
        parts = []
        for k, (name, unit, scale) in _NAMES.items():
            q = r[k]
            if q["value"] is None:
                parts.append(f"{name} —")
                continue
            parts.append(f"{name} {q['value'] * scale:.3g} ({q['low'] * scale:.3g}–"
                         f"{q['high'] * scale:.3g}) {unit}")
        lines.append(f"    {r['owner_nights']:>3} nights: " + ", ".join(parts))
    return lines
