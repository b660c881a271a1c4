"""The problems one :class:`~impctl.fit.NightFit` solves in a single optimiser call (torch).

A fit is many problems side by side: every start in the class box with and without the nuisance
terms, the same starts in the whole prior box, and each night alone (the paper's per-night mode).
Here is how they are laid out — which start in which box over which nights, in which group —
and the rows the optimiser evaluates for them, weighted by the residual σ of each group.

* :func:`nuisance_boxes` — the bounds of the nuisance terms, switched on and off;
* :func:`layout` — the problems, their groups and boxes; :func:`best_of` — the best of a group;
* :func:`stop_units` — which groups stop together (:func:`..optim.lm.levenberg_marquardt`);
* :func:`night_rows` — each night's row type, heat input and residual group;
* :func:`problem_rows` — the optimiser's rows; :func:`air_input` — Φ_HC of the AIR rows;
* :func:`initial_mass` — the mass temperature each row starts from (the start's parameters);
* :func:`residual_sigma` — the residual σ per group, from a fit (the rows' weights);
  :func:`night_sigma` — the same per night (``NightFit(noise="night")``).
"""

from __future__ import annotations

import numpy as np
import torch

from ..model.continuous import mass_from_air
from .ode.node import ROW_AIR, ROW_DEMAND
from .ode.parameters import (
    DTYPE,
    NUISANCE_BOUNDS,
    NUISANCE_NAMES,
    PARAM_NAMES,
    network,
    to_physical,
)
from .optim import lm
from .optim.problem import raw_residuals

_FIRST_NIGHT_GROUP = 3


def stop_units(groups: torch.Tensor) -> torch.Tensor:
    """Per group label, its stopping unit (:func:`..optim.lm.levenberg_marquardt`): the joint fit
    (groups 0–2) and the per-night fits (3 + i) stop on their own, so that the joint answer
    does not depend on whether — or how long — the per-night comparison runs."""
    return (torch.arange(int(groups.max()) + 1) >= _FIRST_NIGHT_GROUP).long()


def terms_of(result: lm.LMResult, sel: torch.Tensor) -> lm.RowTerms | None:
    """The optimiser's last evaluation on the rows ``sel`` (None when it kept none)."""
    return None if result.terms is None else result.terms.take(sel)


def starts(s: int, seed: int) -> torch.Tensor:
    """``s`` starts in the unbounded coordinates: the centre of the box, then random ones."""
    rng = np.random.default_rng(seed)
    # emitter_share (added last) draws after the others: the earlier starts stay the same
    frac = rng.uniform(0.15, 0.85, size=(s, len(PARAM_NAMES) + len(NUISANCE_NAMES) - 1))
    frac = np.concatenate([frac, rng.uniform(0.15, 0.85, size=(s, 1))], axis=1)
    u = torch.logit(torch.as_tensor(frac, dtype=DTYPE))
    u[0] = 0.0
    return u


def nuisance_boxes(night_gain: bool, emitter_state: bool, furniture_state: bool,
                   emitter_lag: bool, night_gain_w: float, estimate_gain: bool = False
                   ) -> tuple[dict, dict]:
    """Bounds of the nuisance terms (:data:`~.ode.parameters.NUISANCE_NAMES`) with the terms
    switched on as asked, and with all of them off (``plain``); (0, 0) is off. A night gain
    that is not fitted is pinned to ``night_gain_w`` [W] in both; ``estimate_gain``: the gain
    is free in both (under its Gaussian prior, :attr:`..optim.lm.Context.gain_prior`), so the
    likelihood-ratio test is about the other terms alone."""
    nuisance = {n: (NUISANCE_BOUNDS[n] if on else (0.0, 0.0)) for n, on in zip(
        NUISANCE_NAMES, (night_gain, emitter_state, emitter_state, furniture_state,
                         emitter_state and emitter_lag), strict=True)}
    # a gain not fitted is pinned to the assumed one (an occupied house never has 0 W)
    pinned = (float(night_gain_w),) * 2
    if not night_gain:
        nuisance["night_gain_w"] = pinned
    plain = {n: (0.0, 0.0) for n in NUISANCE_NAMES} | {"night_gain_w": pinned}
    if estimate_gain:
        nuisance["night_gain_w"] = plain["night_gain_w"] = NUISANCE_BOUNDS["night_gain_w"]
    return nuisance, plain


#: Starts in the whole prior box where the classes narrow it: that fit only has to say whether
#: the data contradict the classes (the likelihood-ratio test). Against as many starts as the
#: class box (then 4), paired on 300 held-out households: the same medians within their CIs, the
#: same coverage and rejections, 10 % less CPU in a classifier fleet (decision record 0012).
PRIOR_STARTS = 2


def layout(n: int, with_prior: bool, nuisance_box, class_box, prior_box, *, n_starts: int,
           seed: int, per_night: bool) -> dict:
    """Problems: joint starts in the class box with the nuisance terms ("class"), the same
    without them ("simple"), [joint starts in the prior box, with], per night (without).

    Groups (for "keep the best" and early stopping): 0 class, 1 prior, 2 simple, 3 + i
    night i. Without nuisance terms to test, "class" is the plain class box and there is
    no "simple" group.
    """
    s = max(1, n_starts)
    u_starts = starts(s, seed)
    with_nuisance = bool((nuisance_box[len(PARAM_NAMES):, 1]
                          > nuisance_box[len(PARAM_NAMES):, 0]).any())
    kinds = [("class", j, -1) for j in range(s)]
    if with_nuisance:
        kinds += [("simple", j, -1) for j in range(s)]
    if with_prior:
        kinds += [("prior", j, -1) for j in range(min(s, PRIOR_STARTS))]
    if per_night:
        # the paper's per-night mode is a comparison, not the result: at most two starts
        kinds += [("night", j, i) for j in range(min(s, 2)) for i in range(n)]
    boxes = {"class": nuisance_box, "simple": class_box, "prior": prior_box,
             "night": class_box}
    row_problem, row_night, group, box, u0 = [], [], [], [], []
    for p, (kind, j, i) in enumerate(kinds):
        nights = range(n) if i < 0 else [i]
        row_problem += [p] * len(nights)
        row_night += list(nights)
        group.append({"class": 0, "prior": 1, "simple": 2}.get(kind, 3 + i))
        box.append(boxes[kind])
        u0.append(u_starts[j])
    def idx(k):
        return [p for p, x in enumerate(kinds) if x[0] == k]
    return {"kinds": kinds, "class": idx("class"), "prior": idx("prior"),
            "simple": idx("simple"), "night": idx("night"),
            "row_problem": torch.tensor(row_problem),
            "row_night": torch.tensor(row_night), "group": torch.tensor(group),
            "box": torch.stack(box), "u0": torch.stack(u0), "n_problems": len(kinds)}


def best_of(result: lm.LMResult, lay: dict, group: int) -> int:
    """The problem of ``group`` with the lowest loss."""
    members = [p for p in range(lay["n_problems"]) if int(lay["group"][p]) == group]
    return members[int(torch.argmin(result.loss[members]))]


def problem_rows(lay: dict, sigma: dict[str, float], row_type_n: torch.Tensor, phi_n: torch.Tensor,
         phi_in_n: torch.Tensor, group_n: torch.Tensor, only: list[int] | None = None,
         sigma_n: torch.Tensor | None = None) -> lm.Rows:
    """The optimiser's rows of the problems in ``lay`` (or only of the problems ``only``,
    renumbered), each weighted by 1/σ of its night's residual group (``sigma``: K, K, W), or
    by 1/σ of its own night when ``sigma_n`` (per packed night, K or W) is given."""
    sig = torch.tensor([sigma["constrained_t_air_k"], sigma["normal_t_air_k"],
                        sigma["normal_power_w"]], dtype=DTYPE)
    problem, night = lay["row_problem"], lay["row_night"]
    box, n_prob = lay["box"], lay["n_problems"]
    if only is not None:  # the problems `only`, renumbered 0…len(only)−1
        keep = torch.isin(problem, torch.tensor(only))
        remap = torch.full((n_prob,), -1, dtype=torch.long)
        remap[torch.tensor(only)] = torch.arange(len(only))
        problem, night = remap[problem[keep]], night[keep]
        box, n_prob = box[torch.tensor(only)], len(only)
    row_sigma = sig[group_n[night]] if sigma_n is None else sigma_n[night]
    return lm.Rows(problem, night, row_type_n[night], phi_n[night],
                   phi_in_n[night], 1.0 / row_sigma, box, n_prob)


def night_rows(packed, normal_model: str) -> tuple[torch.Tensor, ...]:
    """Per night: its row type (AIR, or DEMAND for normal nights with the "demand" model), Φ_HC
    [W] of AIR rows at the nodes and on the intervals (:func:`air_input`) and its residual
    group (0 constrained T_air, 1 normal T_air, 2 normal power)."""
    cons = packed.constrained
    demand = ~cons & torch.tensor(normal_model == "demand")
    row_type_n = torch.where(demand, ROW_DEMAND, ROW_AIR)
    phi_n, phi_in_n = air_input(packed, normal_model)
    group_n = torch.where(cons, 0, torch.where(demand, 2, 1))
    return row_type_n, phi_n, phi_in_n, group_n


def air_input(packed, model: str) -> tuple[torch.Tensor, torch.Tensor]:
    """Φ_HC [W] of AIR rows at the nodes and on the intervals: 0 on constrained nights (eq. 6)."""
    cons = packed.constrained[:, None]
    if model == "mean":
        mean = packed.q_mean_w[:, None].expand_as(packed.q_w)
        node, interval = mean, mean
    else:
        node, interval = packed.q_w, packed.q_in_w
    return torch.where(cons, 0.0, node), torch.where(cons, 0.0, interval)


def initial_mass(packed, u_rows, night, box_rows, row_type_n, phi_n, ach_vent: float,
                 ach_infl: float) -> torch.Tensor:
    """Initial mass temperature θ_m,0 [°C] per row: the one the first sample's T_air implies
    under the row's start parameters (:func:`~impctl.model.continuous.mass_from_air`; demand
    rows at the night's mean power)."""
    net = network(to_physical(u_rows, box_rows), ach_vent, ach_infl)
    demand = row_type_n[night] == ROW_DEMAND
    phi0 = torch.where(demand, packed.q_mean_w[night], phi_n[night, 0])
    return mass_from_air(packed.t_air_c[night, 0], packed.t_out_c[night, 0], phi0, net)


def _best_raw(ctx: lm.Context, rows: lm.Rows, result: lm.LMResult, best: int):
    """(rows of the problem ``best``, their raw residuals (model − measured), data units)."""
    sel = rows.problem == best
    sub = rows.subset(sel)
    if result.terms is not None:  # the optimiser's own last evaluation at this point
        return sub, result.terms.take(sel).raw()
    with torch.no_grad():
        return sub, raw_residuals(ctx, sub, result.u[best][None], result.t_m0[sel])


def night_sigma(ctx: lm.Context, rows: lm.Rows, result: lm.LMResult, best: int,
                group_n: torch.Tensor) -> torch.Tensor:
    """Per packed night the RMS residual (K or W) of the problem ``best`` — the maximum-
    likelihood σ of that night given the fit — over the samples it compares, with its θ_m,0
    and its share of the 7 parameters counted as degrees of freedom, floored as
    :func:`residual_sigma` floors."""
    sub, raw = _best_raw(ctx, rows, result, best)
    packed = ctx.packed
    m = torch.where((sub.row_type == ROW_DEMAND)[:, None], packed.demand_mask()[sub.night],
                    packed.mask[sub.night])
    n = m.sum(1).to(DTYPE)
    dof = (n - 1.0 - 7.0 * n / n.sum().clamp_min(1.0)).clamp_min(1.0)
    rms = ((raw * m).pow(2).sum(1) / dof).sqrt()
    floors = torch.tensor(_SIGMA_FLOORS, dtype=DTYPE)[group_n[sub.night]]
    out = torch.ones(len(group_n), dtype=DTYPE)
    out[sub.night] = torch.maximum(rms, floors)
    return out


#: Floors of the residual σ per group (constrained T_air K, normal T_air K, power W).
_SIGMA_FLOORS = (0.005, 0.005, 1.0)


def residual_sigma(ctx: lm.Context, rows: lm.Rows, result: lm.LMResult, best: int,
                   mask: torch.Tensor, group_n: torch.Tensor,
                   sigma: dict[str, float]) -> dict[str, float]:
    """``sigma`` with each residual group's σ (K, K, W) replaced by the RMS residual of the
    problem ``best`` (degrees of freedom counted; floored), where that group has rows."""
    sigma = dict(sigma)
    sub, raw = _best_raw(ctx, rows, result, best)
    mask = mask[sub.night]
    groups = group_n[sub.night]
    floors = _SIGMA_FLOORS
    n_all = int(mask.sum())
    for g, key in enumerate(("constrained_t_air_k", "normal_t_air_k", "normal_power_w")):
        m = mask & (groups == g)[:, None]
        n_g = int(m.sum())
        if n_g:
            # Degrees of freedom: each night's θ_m,0 and the group's share of the 7
            # parameters are fitted to these residuals (matters for hourly data).
            dof = max(1.0, n_g - int((groups == g).sum()) - 7.0 * n_g / n_all)
            rms = float(raw[m].pow(2).sum() / dof) ** 0.5
            sigma[key] = max(floors[g], rms)
    return sigma
