"""What one :class:`~impctl.fit.NightFit` reports: the problem chosen and every fitted attribute.

:func:`choose` picks the problem by the likelihood-ratio tests (:mod:`..checks.selection`): first
whether the data need the nuisance terms, then whether they contradict the class box.
:func:`statement` builds from it every attribute a fitted NightFit reports — the Laplace
intervals with their type-B, structural, prior and model-error shares, the nuisance terms,
the per-night fits, the in-sample validation, the adequacy of the model and each night's
quality — as a name → value mapping, so that the estimator holds no half-built state.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import torch

from ..checks.cross_checks import cross_checks
from ..checks.instruments import instruments
from ..checks.selection import (
    assumed_gain,
    class_check,
    gain_statement,
    nuisance_check,
    structure_share,
)
from ..checks.undetermined import mark_undetermined, nuisance_at_bound, table_iv
from ..checks.validation import in_sample_validation, per_night_fits
from ..intervals import model_error
from ..intervals.uncertainty import laplace, nuisance_intervals, offset_allowance
from ..layout import best_of, terms_of
from ..nights.quality import adequacy, t_air_resolution_k, used_nights_quality
from ..ode.parameters import PARAM_NAMES, to_physical
from ..optim import lm
from ..prior import prior_statement
from .params import FitParams
from .problems import Problems
from .weights import Weights


@dataclass(frozen=True)
class Choice:
    """The reported problem, its rows and optimum, and the tests that chose it."""

    best: int
    sel: torch.Tensor        # its rows among all problems' rows (bool)
    sub: lm.Rows             # those rows
    u: torch.Tensor          # its optimum (unbounded coordinates)
    t_m0: torch.Tensor       # its θ_m,0 per night [°C]
    nuisance_check: dict
    class_check: dict
    bounds: dict[str, tuple[float, float]]


def choose(problems: Problems, rows: lm.Rows, result: lm.LMResult) -> Choice:
    """The problem to report among ``result``'s (``rows``: all problems' rows, as weighted)."""
    lay = problems.lay
    # First whether the data need the nuisance terms (inside the class box), then whether
    # they contradict the class box: testing the classes with a model that lacks terms the
    # data need rejects right classes (the prior box then absorbs the misfit).
    best = best_of(result, lay, 2 if lay["simple"] else 0)
    nuisance = {"applied": bool(lay["simple"]), "selected": False}
    if lay["simple"]:
        best, nuisance = nuisance_check(result, lay, best, problems.n_nuisance)
    classes = {"applied": problems.with_prior, "rejected": False}
    if problems.with_prior:
        best, classes = class_check(problems.ctx, rows, result, lay, best, problems.ranges,
                                    problems.group_n, problems.n_nuisance)
    sel = rows.problem == best
    return Choice(best, sel, rows.subset(sel), result.u[best], result.t_m0[sel], nuisance,
                  classes, problems.class_box if best not in lay["prior"] else problems.prior_box)


def statement(options: FitParams, problems: Problems, weights: Weights, result: lm.LMResult,
              choice: Choice, cal: dict | None) -> dict[str, object]:
    """Every attribute a fitted NightFit reports (name → value), for the problem ``choice``;
    ``cal``: the model-error calibration (:func:`..intervals.model_error.load_calibration`)."""
    o, p, c = options, problems, choice
    packed, box = p.packed, c.sub.box[0]
    out: dict[str, object] = {
        "gaps_": p.gaps, "skipped_": p.skipped, "classified_": sorted(p.ranges or {}),
        "nights_": p.kept, "n_iter_": result.n_iter + weights.n_iter, "noise_": weights.guess,
        "sigma_": weights.sigma, "sigma_night_": weights.per_night(p),
        "nuisance_check_": c.nuisance_check, "class_check_": c.class_check,
        "bounds_": c.bounds, "loss_": float(result.loss[c.best]),
        "t_m0_c_": dict(zip(packed.night_ids, c.t_m0.tolist(), strict=True)),
        "parameters_": dict(zip(PARAM_NAMES, to_physical(c.u, box)[:len(PARAM_NAMES)].tolist(),
                                strict=True)),
    }
    est = laplace(p.ctx, c.sub, c.u, c.t_m0, p.group_n,
                  has_power=bool((~packed.constrained).any()), terms=terms_of(result, c.sel))
    offsets, meter, sources = instruments(o.sensor_offsets_k, o.meter_error)
    lumped, allowance = offset_allowance(
        est["lumped"], p.kept, offsets, meter,
        # a fitted gain's uncertainty is in the covariance already
        0.0 if (c.nuisance_check.get("selected") and o.night_gain is True)
        or p.ctx.gain_prior is not None else p.gain.sd_w)
    allowance["sources"] = sources
    share = None
    if o.structure_share and p.lay["simple"]:
        lumped, share = structure_share(result, p.lay, lumped, o.ach_vent, o.ach_infl)
        allowance["structure_relative_sd"] = share
    out |= {"offset_allowance_": allowance, "structure_share_": share,
            "interval_source_": est["interval_source"], "determined_": est["determined"],
            "range_fraction_sd_": est["range_fraction_sd"],
            "residual_autocorrelation_": est["autocorrelation"], "cov_u_": est["cov_u"],
            "prior_": None}
    if p.prior is not None:
        lumped, out["prior_"] = prior_statement(p.prior, lumped, c.u, box, est["cov_u"],
                                                o.ach_vent, o.ach_infl)
        out["prior_"]["tempering"] = weights.tempering
    nuisance = out["nuisance_"] = nuisance_intervals(c.u, box, est["cov_u"])
    gain = out["night_gain_"] = gain_statement(c.u, box, p.gain, est["cov_u"],
                                               p.ctx.gain_prior)
    if not gain.get("fitted") and gain["source"] != "estimated":
        nuisance["night_gain_w"] = assumed_gain(gain)
    elif gain.get("fitted") and nuisance.get("night_gain_w"):
        nuisance["night_gain_w"]["source"] = gain["source"]   # fitted under its prior
    out["cross_checks_"] = cross_checks(p.nights)
    # a term the bound set, not the nights, leaves what it trades against undetermined
    out["nuisance_at_bound_"] = nuisance_at_bound(nuisance)
    out["per_night_"], out["per_night_mean_"] = per_night_fits(result, p.lay, packed,
                                                               o.ach_vent, o.ach_infl)
    out["validation_"], out["predictions_"] = in_sample_validation(
        packed, p.kept, c.u, box, c.t_m0, p.phi_n, p.phi_in_n, ach_vent=o.ach_vent,
        ach_infl=o.ach_infl, solver=o.solver, normal_model=o.normal_model)
    res = [t_air_resolution_k(n.t_air_c) for n in p.kept if n.kind == "constrained"]
    res = [r for r in res if r]
    held = [np.asarray(n.q_hc_w, float) for n in p.kept if n.kind == "normal"]
    out["adequacy_"] = adequacy(weights.sigma, weights.guess, est["autocorrelation"],
                                est.get("residual_blocks"), min(res) if res else None,
                                float(np.mean(np.concatenate(held))) if held else None)
    out["night_quality_"] = used_nights_quality(p.nights, p.kept, p.skipped,
                                                o.resume_threshold_w, nuisance)
    out["interval_basis_"] = est["interval_basis"]
    out["model_error_"] = None
    if cal is not None:
        # the diagnostics read the statement as they would read the fitted estimator
        lumped, out["model_error_"] = model_error.widen(
            lumped, model_error.diagnostics(SimpleNamespace(**out)), cal)
    out["lumped_"] = mark_undetermined(lumped, out["nuisance_at_bound_"])
    out["table_iv_"] = table_iv(out["parameters_"], est["determined"], c.bounds)
    return out
