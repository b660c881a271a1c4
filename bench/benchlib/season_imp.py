"""The 0-owner-night point of bench/season.py: a season household's IMP nights alone, fitted on
``impctl fit``'s path (:mod:`impctl.fit.household`: the nights chosen, the night fit, a fit no
house gives refused) with the true class ranges, as bench/fit.py's figure of record
(``--ranges true``) — the IMP fit the season model adds owner nights to. A household whose
campaign left no valid constrained night is one the gateway does not identify (``impctl fit``
refuses it); as bench/fit.py, the bench still fits its normal nights — τ and C_m then rest on
the class ranges — and counts it, marked ``identified`` False.

torch is imported when a fit runs (the season model's runs never load it).
"""

from __future__ import annotations

import math

from benchlib.fit_protocol import true_ranges
from impctl.model import HouseParameters

#: The season bench's quantity names → the night fit's lumped names.
LUMPED_NAMES = {"hlc_w_per_k": "hlc", "tau_h": "tau", "c_m_j_per_k": "c_m"}


def fit_imp_nights(nights: list, house: HouseParameters) -> tuple[dict | None, str | None]:
    """The night fit of the IMP nights among ``nights`` (owner records left out) with ``house``'s
    true class ranges: ({quantity: value, quantity_low, quantity_high (units of the quantity
    names)}, None), or (None, why not)."""
    from impctl.errors import InputError
    from impctl.fit.estimator import NightFit
    from impctl.fit.household import FitOptions, choose_nights, fit_refusal

    imp = [n for n in nights if n.kind != "owner"]
    # the season's rows are interval means, as the gateway exports them
    options = FitOptions(timestamps="interval")
    chosen = choose_nights(imp, options.max_nights)
    refusal = chosen.too_little()
    if refusal is not None and "normal" in chosen.missing:
        return None, refusal.problem
    try:
        fit = NightFit(**options.estimator_params()).fit(chosen.nights, true_ranges(house))
    except InputError as exc:
        return None, exc.problem
    refused = fit_refusal(fit)
    if refused is not None:
        return None, f"{refused.reason}: {refused.problem}"
    out: dict = {"imp_nights": len(chosen.chosen), "identified": refusal is None}
    for name, short in LUMPED_NAMES.items():
        est = fit.lumped_[short]
        finite = all(math.isfinite(x) for x in (est.value, est.low, est.high))
        out[name] = float(est.value) if finite else None
        out[f"{name}_low"] = float(est.low) if finite else math.nan
        out[f"{name}_high"] = float(est.high) if finite else math.nan
    return out, None
