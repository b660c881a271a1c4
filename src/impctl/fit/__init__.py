"""The night fit: the 5R1C parameters from IMP nights, by a Neural ODE bounded by the class ranges.

Pipeline position: classifiers → **fit** → fleet. torch is imported only when a name that needs
it is first used (the names below are resolved lazily), so ``import impctl.fit`` stays light and
reading a result (:mod:`.result`) needs no torch.

* :class:`NightFit` (:mod:`.estimator`): the estimator (torch)
* :func:`prepare_nights` (:mod:`.nights.data`): measured nights → the fit's input
* :func:`fit_to_dict` (:mod:`.result.report`), :func:`format_table` (:mod:`.result.table`),
  :func:`plot_fit` (:mod:`.result.plot`): the JSON summary, its printed form, the figure (no
  torch)

Inside, by concern:

* :mod:`.ode` — the night dynamics: :mod:`.ode.node` (the 5R1C night ODE with its nuisance
  terms, batched over rows), :mod:`.ode.parameters` (the fitted parameters: bounds, transforms,
  HLC/C_m/τ), :mod:`.ode.packing` (the nights side by side) and :mod:`.ode.solver` (exact
  discretisation, or torchdiffeq);
* :mod:`.optim` — the optimiser: :mod:`.optim.problem` (the problems' rows and residuals),
  :mod:`.optim.lm` (Levenberg–Marquardt over merged starts and nights), :mod:`.optim.batch`
  (many households in one call: the fleet);
* :mod:`.intervals` — :mod:`.intervals.uncertainty` (Laplace, sandwich, type-B shares) and
  :mod:`.intervals.model_error` (the share calibrated on realistic virtual houses);
* :mod:`.nights` — the fit's input (no torch): :mod:`.nights.data` (measured nights → rows),
  :mod:`.nights.resample` (fine rows into blocks), :mod:`.nights.quality` (night quality, model
  adequacy);
* :mod:`.result` — the result (no torch): :mod:`.result.report` (the JSON),
  :mod:`.result.table` (its printed form), :mod:`.result.plot` (the figure);
* :mod:`.steps` — the estimator's steps: :mod:`.steps.problems` (the nights prepared, the
  problems laid out), :mod:`.steps.weights` (the noise weights and their refits),
  :mod:`.steps.statement` (the problem reported and every fitted attribute);
* :mod:`.checks` — :mod:`.checks.selection` (which problem is reported: the likelihood-ratio
  tests), :mod:`.checks.validation` (in-sample checks, per-night fits) and the rest a fit
  checks of itself;
* here: :mod:`.estimator` (the estimator and its procedure), :mod:`.layout` (the problems
  one fit solves in one optimiser call: starts, boxes, groups, rows), :mod:`.household` (one
  household's nights as the commands take them), :mod:`.prior`, :mod:`.gain`,
  :mod:`.baselines` (the methods the fit is compared with).
"""

from __future__ import annotations

import lazy_loader

# Resolved on first use (lazy_loader), so that importing the package stays light.
__getattr__, __dir__, _LAZY_NAMES = lazy_loader.attach(__name__, submod_attrs={
    "estimator": ["NightFit"],
    "nights.data": ["prepare_nights"],
    "result.report": ["fit_to_dict"],
    "result.table": ["format_table"],
    "result.plot": ["plot_fit"],
})
__all__ = [*_LAZY_NAMES]
