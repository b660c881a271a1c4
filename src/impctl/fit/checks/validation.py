"""What a fit is checked and compared with, in sample (torch).

* :func:`in_sample_validation` — the paper's Tables II/V for the reported fit (heat demand on
  normal nights, T_air RMSE on constrained ones) and the measured vs fitted series per night
  (for plots);
* :func:`per_night_fits` — the paper's per-night-then-average mode, from the per-night problems
  of the same optimiser call (:mod:`..layout`): a comparison, not the result.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from ...imp.night import NightSamples
from ..intervals.uncertainty import LUMPED_NAMES
from ..nights.data import validation_table
from ..ode.node import ROW_AIR, ROW_DEMAND, build_rows
from ..ode.packing import PackedNights
from ..ode.parameters import PARAM_NAMES, lumped, to_physical
from ..optim import lm


def per_night_fits(result: lm.LMResult, lay: dict, packed: PackedNights, ach_vent: float,
                   ach_infl: float) -> tuple[list[dict], dict]:
    """Per night its best per-night problem — parameters (units as the house TOML), lumped
    hlc [W/K], c_m [J/K], tau [h] and what such a night determines — and their average;
    ``([], {})`` when the fit ran no per-night problems."""
    if not lay["night"]:
        return [], {}
    n = packed.n_nights
    members = torch.tensor(lay["night"]).view(-1, n)      # (starts, nights)
    best = members[result.loss[members].argmin(0), torch.arange(n)]
    params = to_physical(result.u[best], lay["box"][best])[:, :len(PARAM_NAMES)]
    q = lumped(params, ach_vent, ach_infl)
    entries = []
    for i, nid in enumerate(packed.night_ids):
        kind = packed.kinds[i]
        entries.append({
            "night_id": nid, "kind": kind,
            "parameters": dict(zip(PARAM_NAMES, params[i].tolist(), strict=True)),
            "lumped": dict(zip(LUMPED_NAMES, q[i].tolist(), strict=True)),
            # a night without heat power carries no absolute scale
            "determines": ["tau"] if kind == "constrained" else ["hlc", "c_m", "tau"],
        })
    mean_params = params.mean(0)
    mean = {"parameters": dict(zip(PARAM_NAMES, mean_params.tolist(), strict=True)),
            "lumped": dict(zip(LUMPED_NAMES, lumped(mean_params, ach_vent, ach_infl).tolist(),
                               strict=True))}
    return entries, mean


def in_sample_validation(packed: PackedNights, nights: Sequence[NightSamples], u: torch.Tensor,
                         box: torch.Tensor, t_m0: torch.Tensor, phi_n: torch.Tensor,
                         phi_in_n: torch.Tensor, *, ach_vent: float, ach_infl: float,
                         solver: str, normal_model: str) -> tuple[dict, list[dict]]:
    """In-sample Tables II/V: heat demand on normal nights, T_air RMSE on constrained ones.

    Returns the validation table (:func:`.data.validation_table`) and per night (``nights``,
    as packed) its measured and fitted series: T_air [°C] (None where T_air drives the model),
    T_out [°C], heat power [W] (fitted on normal nights)."""
    n = packed.n_nights
    params = to_physical(u, box).expand(n, -1)
    idx = torch.arange(n)
    with torch.no_grad():
        t_air = build_rows(packed, params, t_m0, idx, torch.full((n,), ROW_AIR), phi_n,
                           phi_in_n, ach_vent, ach_infl, solver).predict().numpy()
        q_model = build_rows(packed, params, t_m0, idx, torch.full((n,), ROW_DEMAND), phi_n,
                             phi_in_n, ach_vent, ach_infl, solver).predict().numpy()
    mask = packed.mask.numpy()
    validation = validation_table(packed.night_ids, packed.kinds, packed.grid_s.numpy(), mask,
                                  packed.t_air_c.numpy(), packed.q_w.numpy(), t_air, q_model)
    predictions = []
    for i, night in enumerate(nights):
        m = mask[i]
        # With the demand model a normal night's T_air is an input, not a prediction.
        as_input = night.kind == "normal" and normal_model == "demand"
        entry = {"night_id": night.night_id, "kind": night.kind,
                 "time_s": night.time_s, "t_air_measured_c": night.t_air_c,
                 "t_air_model_c": None if as_input else t_air[i][m],
                 "t_out_c": night.t_out_c, "q_measured_w": night.q_hc_w}
        if night.kind == "normal":
            entry["q_model_w"] = q_model[i][m]
        predictions.append(entry)
    return validation, predictions
