"""The problems of one :class:`~impctl.fit.NightFit`, prepared once before the optimiser runs.

The given nights are cut at gaps, checked, coarsened and packed side by side; the class and the
prior search boxes, the optimiser's context and the layout of every start follow
(:mod:`..layout`). Nothing here changes while the fit runs — except the prior the context carries,
which the noise weights temper for their refits (:mod:`.weights`) — so the weights and the
statement (:mod:`.statement`) take a :class:`Problems` and never rebuild any of it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from ...errors import InputError
from ...imp.gaps import Gap, cut_at_gaps
from ...imp.night import NightSamples
from ..gain import GainSource, resolve
from ..layout import initial_mass, layout, night_rows, nuisance_boxes, problem_rows
from ..nights.data import compared_power, prepare_nights, search_bounds
from ..nights.resample import coarsen
from ..ode.packing import PackedNights, pack_nights
from ..ode.parameters import bounds_tensor
from ..optim import lm
from ..prior import PopulationPrior
from .params import FitParams


@dataclass(frozen=True)
class Problems:
    """What every optimiser call of one fit shares (read-only once prepared)."""

    nights: list[NightSamples]        # the given nights, each cut to one gap-free piece
    gaps: list[Gap]                   # the gaps they were cut at
    skipped: list[tuple[str, str]]    # (night_id, reason) of the nights left out
    kept: list[NightSamples]          # the nights fitted (coarsened to the fit's step)
    ranges: dict[str, tuple[float, float]] | None   # the class ranges given
    class_box: dict[str, tuple[float, float]]
    prior_box: dict[str, tuple[float, float]]
    packed: PackedNights
    prior: PopulationPrior | None     # as given: untempered
    ctx: lm.Context
    row_type_n: torch.Tensor          # per packed night: row type, Φ_HC of AIR rows [W]
    phi_n: torch.Tensor
    phi_in_n: torch.Tensor
    group_n: torch.Tensor             # and residual group (:func:`..layout.night_rows`)
    n_nuisance: int                   # nuisance terms switched on (the LR test's dof)
    lay: dict                         # :func:`..layout.layout`
    gain: GainSource | None = None    # the gain pinned when no gain term is fitted

    @property
    def with_prior(self) -> bool:
        """Whether the class box is narrower than the prior box (then the classes are tested)."""
        return self.class_box != self.prior_box

    def rows(self, sigma: dict[str, float], sigma_n: torch.Tensor | None = None,
             only: list[int] | None = None) -> lm.Rows:
        """The optimiser's rows weighted by σ per group (K, K, W) or per night (``sigma_n``)."""
        return problem_rows(self.lay, sigma, self.row_type_n, self.phi_n, self.phi_in_n,
                            self.group_n, only, sigma_n)

    def initial_mass(self, ach_vent: float, ach_infl: float) -> torch.Tensor:
        """θ_m,0 [°C] per row at each problem's start (:func:`..layout.initial_mass`)."""
        lay = self.lay
        return initial_mass(self.packed, lay["u0"][lay["row_problem"]], lay["row_night"],
                            lay["box"][lay["row_problem"]], self.row_type_n, self.phi_n,
                            ach_vent, ach_infl)


def prepare(options: FitParams, nights: Sequence[NightSamples],
            ranges: dict[str, tuple[float, float]] | None) -> Problems:
    """The problems ``options`` (a NightFit's constructor parameters) solve on ``nights``.

    Raises
    ------
    InputError
        When no night is usable (each skipped night is named).
    """
    o = options
    nights, gaps = cut_at_gaps(nights, o.emission_lag_h)
    kept, offsets, skipped = prepare_nights(nights, o.emission_lag_h, o.min_night_h,
                                            o.resume_threshold_w)
    if not kept:
        why = "; ".join(f"{i}: {r}" for i, r in skipped) or "no nights given"
        raise InputError(f"no usable night to fit ({why})")
    if o.timestamps == "instant":
        kept = [coarsen(n, o.fit_step_s) for n in kept]
    class_box = search_bounds(ranges, o.physical_bounds)
    prior_box = search_bounds(None, o.physical_bounds)
    power_ok = compared_power(kept, o.resume_threshold_w, o.settle_h, o.settle_until_held)
    packed = pack_nights(kept, offsets, timestamps=o.timestamps,
                         smooth_air_s=3600.0 * o.smooth_air_h,
                         smooth_out_s=3600.0 * o.smooth_out_h, power_ok=power_ok)
    packed.emitter_lag = bool(o.emitter_lag and o.emitter_state)
    gain = resolve(o.night_gain_w, o.night_gain_sd_w, kept)
    if gain.per_night_w:
        # each measured night its own gain: the pinned campaign value plus its deviation
        packed.gain_w = torch.tensor([gain.per_night_w.get(i, gain.value_w) - gain.value_w
                                      for i in packed.night_ids], dtype=packed.q_mean_w.dtype)
    prior = PopulationPrior() if o.prior == "population" else o.prior
    # not declared, not measured: the gain is estimated under the assumption as its prior —
    # unless that assumption is stated exact (SD 0): then there is nothing to estimate, and a
    # zero-width prior would make the curvature singular
    estimate = o.night_gain == "prior" and gain.source == "assumed" and gain.sd_w > 0
    ctx = lm.Context(packed, o.ach_vent, o.ach_infl, o.ridge, o.solver, prior,
                     gain_prior=(gain.value_w, gain.sd_w) if estimate else None)
    row_type_n, phi_n, phi_in_n, group_n = night_rows(packed, o.normal_model)
    nuisance, plain = nuisance_boxes(o.night_gain is True, o.emitter_state, o.furniture_state,
                                     o.emitter_lag, gain.value_w, estimate)
    lay = layout(packed.n_nights, class_box != prior_box, bounds_tensor(class_box, nuisance),
                 bounds_tensor(class_box, plain), bounds_tensor(prior_box, nuisance),
                 n_starts=o.n_starts, seed=o.seed, per_night=o.per_night)
    return Problems(nights, gaps, skipped, kept, ranges, class_box, prior_box, packed, prior, ctx,
                    row_type_n, phi_n, phi_in_n, group_n,
                    sum(hi > lo for n, (lo, hi) in nuisance.items()
                        if not (estimate and n == "night_gain_w")), lay, gain)
