"""The virtual population: households, their simulated IMP nights, and the training dataset.

Pipeline position: model → plant → imp → **population** → classifiers → fit. Nothing here imports
torch or scikit-learn; the names below are resolved lazily, so ``import impctl.population`` loads
only numpy (pandas comes with the first household, night or dataset asked for).

* :func:`sample_households`, :func:`sample_population`, :class:`PopulationConfig`
  (:mod:`.households`)
* :class:`ImpSimConfig` (:mod:`.imp_run.setup`): how the IMP is run on virtual households, and
  :func:`~.imp_run.setup.usable_nights`, the weather's nights it runs on
* :func:`simulate_imp`, :class:`ImpResult` (:mod:`.imp_run.ideal`)
* :func:`simulate_imp_plant` (:mod:`.imp_run.realistic`): the same nights on the realistic plant
  (:mod:`impctl.plant`); :func:`sample_params` (:mod:`.realism`): every household's realism
  options drawn over their documented ranges
* :func:`generate_dataset`, :class:`Dataset` (:mod:`.dataset`)
* :func:`synth_nights` (:mod:`.imp_run.synth`): fine-step simulated nights for the fit's tests
  and benches
* :mod:`.season_run`: a heating season on the realistic plant, the IMP campaign with the
  owner's own nights around it (the season model's tests and benches)
* :data:`DEFAULT_RANGES` (:mod:`.ranges`): the parameter ranges (the paper's Table III) the
  population is drawn over and the classifiers put a house into
"""

from __future__ import annotations

import lazy_loader

from .ranges import DEFAULT_RANGES

# Resolved on first use (lazy_loader), so that importing the package stays light.
__getattr__, __dir__, _LAZY_NAMES = lazy_loader.attach(__name__, submod_attrs={
    "households": ["PopulationConfig", "sample_households", "sample_population"],
    "imp_run.setup": ["ImpSimConfig"],
    "imp_run.ideal": ["ImpResult", "simulate_imp"],
    "imp_run.realistic": ["simulate_imp_plant"],
    "realism": ["sample_params"],
    "dataset": ["Dataset", "generate_dataset"],
    "imp_run.synth": ["synth_nights"],
})
__all__ = ["DEFAULT_RANGES", *_LAZY_NAMES]
