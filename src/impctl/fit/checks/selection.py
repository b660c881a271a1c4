"""Which of a fit's problems is reported, by likelihood-ratio tests (torch).

The problems of one fit (:mod:`..layout`) include the joint fit with and without the nuisance
terms, and in the class box and the whole prior box. First the data decide whether they need the
nuisance terms (:func:`nuisance_check`), then whether they contradict the class ranges
(:func:`class_check`); :func:`structure_share` widens the intervals by how far the nuisance terms
move the answer, and :func:`gain_statement` says whether the reported night gain was
estimated, or declared, measured or assumed (:func:`assumed_gain`: then with the interval of
that source).
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.special import chdtri

from ..gain import GainSource
from ..intervals.uncertainty import LUMPED_NAMES, Z95, laplace
from ..layout import best_of, terms_of
from ..nights.data import Estimate
from ..ode.parameters import NUISANCE_BOUNDS, PARAM_NAMES, lumped, to_physical
from ..optim import lm

#: Likelihood-ratio threshold for "the data contradict the class ranges", applied to the loss
#: drop from the class box to the prior box in units of the autocorrelation-inflated σ: χ² with
#: one degree of freedom at 95 %. With a right class the optimum is interior and the drop ≈ 0
#: (at most 0.7 over 28 right-class households of ``bench/fit.py``; 9 of 22 wrong ones exceed it).
CLASS_REJECT_CHI2 = 3.84
#: The nuisance terms (night gain, emitter amplitude and time constant, air/furniture
#: capacity) are kept when they lower the loss by more than χ² at 95 % with as many degrees of
#: freedom as terms switched on (3 by default: 7.81).


def nuisance_check(result: lm.LMResult, lay: dict, best_simple: int,
                   n_nuisance: int) -> tuple[int, dict]:
    """Forward selection (Bacher & Madsen 2011): keep the nuisance terms only when the
    likelihood-ratio test says the data need them: the loss drop (in units of the fitted
    residual σ) over the ``n_nuisance`` extra parameters against χ². Not deflated for residual
    autocorrelation: on a house the model fits (the ideal 5R1C) the drop stays ≈ 1, while
    emitter and furniture heat after switch-off give drops in the hundreds.

    Returns the problem to report and the ``nuisance_check_`` record."""
    best_nuis = best_of(result, lay, 0)
    drop = float(result.loss[best_simple] - result.loss[best_nuis])
    threshold = float(chdtri(n_nuisance, 0.05))
    selected = drop > threshold
    check = {"applied": True, "chi2": drop, "threshold": threshold, "selected": selected}
    return (best_nuis if selected else best_simple), check


def class_check(ctx: lm.Context, rows: lm.Rows, result: lm.LMResult, lay: dict,
                best_class: int, ranges: dict | None, group_n: torch.Tensor,
                n_nuisance: int) -> tuple[int, dict]:
    """Likelihood-ratio test of the class ranges against the whole prior ranges.

    Returns the problem to report and the ``class_check_`` record."""
    best_prior = best_of(result, lay, 1)
    sel = rows.problem == best_prior
    est = laplace(ctx, rows.subset(sel), result.u[best_prior], result.t_m0[sel],
                  group_n, has_power=True, summary_only=True,
                  terms=terms_of(result, sel))
    drop = float(result.loss[best_class] - result.loss[best_prior]) / est["inflation"]
    x = to_physical(result.u[best_prior], lay["box"][best_prior])
    outside = [n for n, (lo, hi) in (ranges or {}).items()
               if not lo <= float(x[PARAM_NAMES.index(n)]) <= hi]
    # The prior problems carry the nuisance terms; against a class fit without them the
    # test has those extra degrees of freedom too.
    threshold = (float(chdtri(1 + n_nuisance, 0.05)) if best_class in lay["simple"]
                 else CLASS_REJECT_CHI2)
    rejected = drop > threshold
    check = {"applied": True, "chi2": drop, "threshold": threshold,
             "rejected": rejected, "outside": outside if rejected else []}
    return (best_prior if rejected else best_class), check


def structure_share(result: lm.LMResult, lay: dict, lumped_: dict[str, Estimate],
                    ach_vent: float, ach_infl: float) -> tuple[dict, dict]:
    """Widen the intervals by the structural sensitivity: half the log-difference of each
    lumped quantity between the fits with and without the nuisance terms, added in
    quadrature. When the data need terms the 5R1C lacks, how far the answer moves with
    them is a measure of how much the remaining model error may move it (type B).

    Returns the widened ``lumped_`` and the share per quantity (log)."""
    q = {}
    for group in (0, 2):
        p = best_of(result, lay, group)
        x = to_physical(result.u[p], lay["box"][p])
        q[group] = lumped(x, ach_vent, ach_infl).tolist()
    out, shares = {}, {}
    for i, name in enumerate(LUMPED_NAMES):
        e = lumped_[name]
        share = 0.5 * abs(float(np.log(q[0][i] / q[2][i])))
        sd = np.hypot(np.log(e.high / e.low) / (2 * Z95), share)
        out[name] = type(e)(e.value, float(e.value * np.exp(-Z95 * sd)),
                            float(e.value * np.exp(Z95 * sd)), e.determined)
        shares[name] = share
    return out, shares


#: A gain estimated under its prior is reported as estimated when the nights shrink the
#: prior's SD at least to this share; above it the prior, not the nights, sets it: assumed.
GAIN_INFORMED_RATIO = 0.7


def gain_statement(u: torch.Tensor, box: torch.Tensor, gain: GainSource,
                   cov_u: torch.Tensor | None = None,
                   prior: tuple[float, float] | None = None) -> dict:
    """The night gain the reported fit (``u`` in ``box``) used [W] and where it came from.

    Pinned (the box (g, g)): ``gain``'s source — declared, measured or assumed — with its SD.
    Fitted: under the Gaussian ``prior`` (mean, SD [W]) it is *estimated* with its posterior
    SD (from ``cov_u``) when the nights shrink the prior's SD to at most
    :data:`GAIN_INFORMED_RATIO` of it or move it more than one prior SD from the prior's
    centre, else *assumed* (the prior sets it, said so); without a prior (the
    likelihood-ratio-selected term) estimated."""
    j = len(PARAM_NAMES)
    lo, hi = (float(v) for v in box[j])
    fitted = hi > lo   # the reported problem's box: pinned when (g, g)
    g = float(to_physical(u, box)[j])
    if not fitted:
        out = {"value_w": g, "sd_w": float(gain.sd_w), "source": gain.source,
               "assumed": gain.source == "assumed", "statement": gain.statement(g)}
        if gain.per_night_w:
            out["per_night_w"] = dict(gain.per_night_w)
        if gain.detail:
            out["detail"] = gain.detail
        return out
    sd = float("nan")
    if cov_u is not None:
        sig = torch.sigmoid(u[j])
        sd = float((hi - lo) * sig * (1 - sig) * cov_u[j, j].clamp_min(0).sqrt())
    if prior is None:
        return {"value_w": g, "sd_w": sd, "source": "estimated", "assumed": False,
                "statement": f"night gain estimated {g:.0f} W (fitted with the house)"}
    ratio = sd / prior[1]
    # the nights inform it when they shrink the prior's SD, or pull the value a prior SD
    # away from its centre (near the 0 W bound the curvature alone understates them)
    informed = ratio <= GAIN_INFORMED_RATIO or abs(g - prior[0]) > prior[1]
    text = (f"night gain estimated {g:.0f} ± {sd:.0f} W from the nights (prior "
            f"{prior[0]:.0f} ± {prior[1]:.0f} W; posterior/prior SD {ratio:.2f})" if informed
            else f"night gain assumed {g:.0f} ± {sd:.0f} W, not measured: the nights do not "
                 f"determine it (posterior/prior SD {ratio:.2f}); the prior is the "
                 f"population's {prior[0]:.0f} ± {prior[1]:.0f} W")
    return {"value_w": g, "sd_w": sd, "source": "estimated" if informed else "assumed",
            "assumed": not informed, "statement": text, "posterior_to_prior_sd": ratio,
            "prior_w": list(prior), "fitted": True}


def assumed_gain(statement: dict) -> dict:
    """The ``nuisance_`` entry of a night gain not fitted (:func:`gain_statement`): the pinned
    value [W] with the 95 % interval of its source (what the flex coast uses); ``assumed``
    true only for an assumption, ``source`` says which, ``pinned`` that it was not fitted."""
    g, sd = statement["value_w"], statement["sd_w"]
    return {"value": g, "low": max(0.0, g - Z95 * sd), "high": g + Z95 * sd,
            "bounds": list(NUISANCE_BOUNDS["night_gain_w"]),
            "assumed": statement["source"] == "assumed", "source": statement["source"],
            "pinned": True}
