"""The fit's JSON summary (no torch needed to read a result); printed by :mod:`.table`, plotted
by :mod:`.plot`.

JSON schema (``impctl-fit/1``), units as in the house TOML; hlc W/K, c_m J/K, tau h::

    {"schema": "impctl-fit/1",
     "classes": {"floor_area": {"range": [lo, hi], "probability": p | null, "source": s,
                                "calibrated": bool | null (p calibrated on held-out households,
                                or the forest's vote share),
                                "search_range": [lo, hi]  (classifier: classes up to 95 %)}, ...},
     "bounds": {name: [lo, hi]},                     # the search box of all seven
     "parameters": {name: value},                    # joint fit, the seven of Table IV
     "units": {name: unit},
     "determined": {name: bool},                     # does the data pin it down?
     "basis": {name: "data" | "class range" | "physical bounds"},
     "fixed": {"ach_vent": ..., "ach_infl": ...},
     "lumped": {"hlc": {"value", "low", "high", "determined", "unit"}, "c_m": {...}, "tau": {...}},
     "interval_method": str,
     "per_night": [{"night_id", "kind", "samples", "hours", "t_m0_c", "parameters", "lumped",
                    "determines"}],
     "per_night_average": {"parameters": {...}, "lumped": {...}},
     "validation": {"normal": [{"night_id", "q_measured_kwh", "q_model_kwh", "dq_total_kwh",
                                "dq_power_kw", "eps_pct"}],
                    "constrained": [{"night_id", "rmse_k"}], "mean": {...}, "note": str},
     "class_check": {"applied", "chi2", "threshold", "rejected", "outside"},
     "predictions": [{"night_id", "kind", "time_s", "t_air_measured_c", "t_air_model_c" | null,
                      "t_out_c", "q_measured_w", "q_model_w" (normal nights)}],
     "fit": {"mode": "joint", "normal_model", "optimizer", "solver", "timestamps",
             "emission_lag_h", "settle_h", "starts", "iterations", "loss", "sigma", "time_s",
             "interval_basis": str,                  # sandwich over G nights, or "too few nights"
             "nuisance_at_bound": [{"term", "value", "bound", "affects", "statement"}],
             "night_gain": {"value_w", "sd_w", "source", "assumed", "statement"[, "per_night_w",
                            "detail"]},  # W; source declared | measured | estimated | assumed
             "model_error": {"group", "share": {"hlc", "c_m", "tau"}, "n_group",
                             "n_calibration", "n_fits", "seed", "version", "method"} | null},
     "skipped": [{"night_id", "reason"}], "notes": [str],
     "table_iv": {name: {"value", "source": "data" | "prior", "fitted", "prior"}},
                    # the value to report: the fitted one only where the data determine it,
                    # else the prior (search-range centre); "parameters" stays the fitted set
                    # (it re-simulates the house)
     "cross_checks": {"t_air_minus_rooms_k": {"mean", "nights", "fitted_on"},
                      "t_out_minus_ref_k": {"mean", "nights", "flagged"[, "statement"]},
                      "defrost": {"defrost_h", "unread_h", "nights", "share", "flagged"
                                  [, "statement"]}},
     "gaps": [{"night_id", "kind", "start_s", "end_s", "kept_from_s", "kept_to_s", "hours"}],
     "night_quality": [{"night_id", "kind", "rows", "hours", "t_air_resolution_k",
                        "cycles_per_h", "interruptions": [{"kind", "start_h", "minutes"}],
                        "emitter_discharge_h", "night_gain_w", "used", "usable_h", "reason"}],
     "nuisance": {"night_gain_w" | "emitter_w" | "emitter_tau_h" | "furniture_j_per_m2k":
                  {"value", "low", "high", "bounds"[, "assumed": true]} | null},
                  # also read by impctl.flex; night_gain_w "assumed": pinned, not fitted
     "adequacy": {"adequate": bool, "statement": str,
                  "groups": {"constrained" | "normal_power": {"rmse", "unit", "noise_from_data",
                             "rmse_over_noise", "lag1_autocorrelation"}}},
     "flexibility": {"coast_h", "coast_h_low", "coast_h_high", "rebound_kwh", "coast_method",
                     "coast_gain_w", ...}}  # impctl.flex, with the "nuisance" terms
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...model.house import TABLE_IV
from ...model.house_limits import PARAMETER_UNITS

# From the model, not from .node, so that reading a result needs no torch.
PARAM_NAMES = TABLE_IV
PARAM_UNITS = {name: PARAMETER_UNITS[name] for name in TABLE_IV}
CLASSIFIED = ("floor_area", "c_f", "u_walls")
#: The fit JSON's "solver" text per ``NightFit.solver``.
SOLVERS = {
    "exact": "exact discretisation: closed-form solution of the linear night ODE on every "
             "sample interval (inputs linear within it), chained by the exact linear "
             "recurrence; float64",
    "rk4": "torchdiffeq.odeint rk4, every sample interval batched in its normalised time, "
           "chained by the exact linear recurrence; float64",
}
INTERVAL_METHOD = (
    "the wider of (a) Laplace: Gauss-Newton curvature of the joint loss at the optimum, "
    "per-night initial mass temperatures marginalised, residual sigma per group from the fit "
    "inflated for lag-1 autocorrelation, and (b) a night-clustered sandwich covariance (robust "
    "to model error: widens when the nights disagree); delta method in log space; plus, in "
    "quadrature, the shares of uncalibrated sensor offsets, of unmetered night gains and, on "
    "HLC and C_m, of the heat meter's gain error (fit.offset_allowance)")
def _f(x: Any) -> Any:
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, dict):
        return {k: _f(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_f(v) for v in x]
    return x


def probability_kind(entry: dict) -> str:
    """What a class's ``probability`` in a fit result is: "calibrated" (mapped from the
    forest's votes on households it never saw), "forest vote share" (not calibrated), or
    "calibration not recorded" (a result written before the flag was)."""
    flag = entry.get("calibrated")
    if flag is None:
        return "calibration not recorded"
    return "calibrated" if flag else "forest vote share"


def fit_to_dict(fit, classes: dict | None = None, notes: list[str] | None = None) -> dict:
    """JSON-ready summary of a fitted :class:`~impctl.fit.NightFit` (module docstring).

    Parameters
    ----------
    classes : {name: {"range": (lo, hi), "probability": p, "source": str}}, optional
        How the classified ranges were obtained; default: what the fit was given. A
        ``"search_range"`` (the classes up to 95 % probability the fit searched) is kept.
    notes : extra lines for the reader (e.g. "classifiers not trained: prior ranges used")
    """
    if classes is None:
        classes = {n: {"range": list(fit.bounds_[n]), "probability": None,
                       "source": "given" if n in fit.classified_ else "prior"}
                   for n in CLASSIFIED}
    notes = list(notes or [])
    check = fit.class_check_
    if check.get("rejected"):
        notes.append(
            f"the nights contradict the classified ranges (likelihood-ratio Δχ² = "
            f"{check['chi2']:.1f} > {check['threshold']:g}); all values come from the fit over "
            f"the whole prior ranges" + (f" — outside its class: {', '.join(check['outside'])}"
                                         if check["outside"] else ""))
        classes = {n: {**c, "source": c.get("source"), "contradicted": True}
                   for n, c in classes.items()}
    basis = {}
    for name in PARAM_NAMES:
        if fit.determined_[name]:
            basis[name] = "data"
        elif (name in CLASSIFIED and not check.get("rejected")
              and classes.get(name, {}).get("source") in ("classifier", "given")):
            basis[name] = "class range"
        else:
            basis[name] = "physical bounds"
    per_night = []
    by_id = {p["night_id"]: p for p in fit.per_night_}
    for night in fit.nights_:
        entry = {"night_id": night.night_id, "kind": night.kind, "samples": len(night.time_s),
                 "hours": float(night.time_s[-1] - night.time_s[0]) / 3600.0,
                 "t_m0_c": fit.t_m0_c_[night.night_id]}
        if night.night_id in by_id:
            p = by_id[night.night_id]
            entry.update(parameters=p["parameters"], lumped=p["lumped"],
                         determines=p["determines"])
        per_night.append(entry)
    out = {
        "schema": "impctl-fit/1",
        "classes": {n: {"range": list(c["range"]), "probability": c.get("probability"),
                        "source": c.get("source"), "contradicted": bool(c.get("contradicted")),
                        "calibrated": c.get("calibrated"),
                        **({"search_range": list(c["search_range"])}
                           if c.get("search_range") is not None else {})}
                    for n, c in classes.items()},
        "bounds": {n: list(v) for n, v in fit.bounds_.items()},
        "parameters": dict(fit.parameters_),
        "units": PARAM_UNITS,
        "determined": dict(fit.determined_),
        "basis": basis,
        "fixed": {"ach_vent": fit.ach_vent, "ach_infl": fit.ach_infl},
        "lumped": {k: {**v.as_dict(), "unit": u} for (k, v), u in
                   zip(fit.lumped_.items(), ("W/K", "J/K", "h"), strict=True)},
        "interval_method": interval_method(fit),
        "per_night": per_night,
        "per_night_average": fit.per_night_mean_,
        "validation": fit.validation_,
        "class_check": fit.class_check_,
        "predictions": [{k: (np.asarray(v, float).round(4).tolist()
                             if isinstance(v, np.ndarray) else v) for k, v in p.items()}
                        for p in fit.predictions_],
        "fit": {"mode": "joint", "normal_model": fit.normal_model, "optimizer": fit.optimizer,
                "solver": SOLVERS.get(getattr(fit, "solver", "rk4")),
                "timestamps": fit.timestamps, "emission_lag_h": fit.emission_lag_h,
                "settle_h": getattr(fit, "settle_h", 0.0), "starts": fit.n_starts,
                "iterations": fit.n_iter_, "loss": fit.loss_, "sigma": fit.sigma_,
                # the noise model and each night's σ, the weights: a unit per key, so K on
                # constrained nights and W on held nights are never read as one column
                "noise": getattr(fit, "noise", "kind"),
                **_sigma_per_night(fit),
                "time_s": fit.fit_time_s_},
        "skipped": [{"night_id": i, "reason": r} for i, r in fit.skipped_],
        "gaps": [g.as_dict() for g in getattr(fit, "gaps_", [])],
        "notes": notes,
    }
    # added keys (schema stays impctl-fit/1: readers of the old keys are unaffected)
    if getattr(fit, "offset_allowance_", None) is not None:
        out["fit"]["offset_allowance"] = fit.offset_allowance_
    if getattr(fit, "interval_source_", None) is not None:
        out["fit"]["interval_source"] = fit.interval_source_
    if getattr(fit, "interval_basis_", None) is not None:
        out["fit"]["interval_basis"] = fit.interval_basis_
    out["fit"]["model_error"] = getattr(fit, "model_error_", None)
    # the population prior: what came from it and what from the data
    out["prior"] = getattr(fit, "prior_", None)
    for name, p in (out["prior"] or {}).get("parameters", {}).items():
        if p["prior_dominated"]:
            notes.append(f"{name} is prior-dominated (posterior/prior SD "
                         f"{p['posterior_to_prior_sd']:.2f}): the population prior inside the "
                         "class ranges, not the nights, sets it — not a measured value")
    if getattr(fit, "nuisance_check_", None) is not None:
        out["fit"]["nuisance_check"] = fit.nuisance_check_
    if getattr(fit, "night_gain_", None) is not None:
        out["fit"]["night_gain"] = fit.night_gain_
    if getattr(fit, "table_iv_", None):
        out["table_iv"] = fit.table_iv_
    for term in getattr(fit, "nuisance_at_bound_", None) or []:
        notes.append(term["statement"] + " (the bound, not the nights, set it)")
    if getattr(fit, "nuisance_at_bound_", None) is not None:
        out["fit"]["nuisance_at_bound"] = fit.nuisance_at_bound_
    if getattr(fit, "cross_checks_", None):
        out["cross_checks"] = fit.cross_checks_
        for key in ("t_out_minus_ref_k", "defrost"):
            flagged = (fit.cross_checks_.get(key) or {}).get("statement")
            if flagged:
                notes.append(flagged)
    if getattr(fit, "nuisance_", None) is not None:
        out["nuisance"] = fit.nuisance_
        out["fit"]["nuisance_terms"] = (
            "night_gain_w: constant internal gain over the campaign (ISO 13790 split over "
            "air, surface and mass; \"assumed\": pinned, not fitted); emitter_w, "
            "emitter_tau_h: heat still released after the fit start on constrained nights, "
            "emitter_w·exp(−t/emitter_tau_h); furniture_j_per_m2k: air/furniture capacity; "
            "emitter_share: share of C_m in the emitter between the heat meter and the room "
            "(with emitter_lag); bounded, fitted with the seven, not measured "
            "quantities of the product")
    if getattr(fit, "night_quality_", None) is not None:
        out["night_quality"] = fit.night_quality_
    if getattr(fit, "adequacy_", None) is not None:
        out["adequacy"] = fit.adequacy_
        if not fit.adequacy_["adequate"]:
            notes.append(fit.adequacy_["statement"])
    out["flexibility"] = flexibility_block(out)
    return _f(out)


def interval_method(fit) -> str:
    """The ``interval_method`` text of a fit: :data:`INTERVAL_METHOD`, then how few nights
    changed it and the calibrated model-error share (size and group) when one was added."""
    text = INTERVAL_METHOD
    basis = getattr(fit, "interval_basis_", None)
    if basis and basis.startswith("too few nights"):
        text += f"; {basis}"
    me = getattr(fit, "model_error_", None)
    if me:
        sizes = ", ".join(f"{k} {100 * v:.1f} %" for k, v in me["share"].items())
        text += (f"; plus, in quadrature, a model-error share calibrated on "
                 f"{me['n_calibration']} realistic virtual households ({me.get('n_fits')} fits), "
                 f"group '{me['group']}'"
                 + (f", band '{me['band']}' of night counts" if me.get("band") else "")
                 + f" (log-space SD {sizes}; impctl.fit.intervals.model_error)")
    else:
        text += "; no model-error share (measurement-only intervals)"
    return text


def flexibility_block(summary: dict) -> dict:
    """The ``"flexibility"`` block of a summary at the default conditions (:mod:`impctl.flex`);
    all values None when the fitted house cannot be simulated."""
    from ...errors import InputError
    from ...flex import BLOCK_KEYS, flexibility_of_fit

    try:
        return flexibility_of_fit(summary).block()
    except InputError:
        return dict.fromkeys(BLOCK_KEYS)


def _sigma_per_night(fit) -> dict:
    """``sigma_per_night_k`` (constrained nights, T_air residuals [K]) and
    ``sigma_per_night_w`` (held nights, heat-power residuals [W])."""
    sigma = getattr(fit, "sigma_night_", None) or {}
    kinds = {n.night_id: n.kind for n in fit.nights_}
    return {"sigma_per_night_k": {i: v for i, v in sigma.items() if kinds.get(i) == "constrained"},
            "sigma_per_night_w": {i: v for i, v in sigma.items() if kinds.get(i) != "constrained"}}
