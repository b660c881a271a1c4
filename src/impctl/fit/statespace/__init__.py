"""A continuous–discrete stochastic state-space fit of the IMP nights (CTSM-R style).

Not wired into :class:`~impctl.fit.NightFit` or ``impctl fit``: measured against NightFit on the
same households it is not better (docs/decisions/0101-statespace-likelihood.md, the figures by
``bench/fit_statespace.py``); kept for that bench and for further work.

* :mod:`.model` — states (air + furniture, mass, emitter, latent heat input), parameters and the
  5R1C's HLC, C_m, τ of a parameter row;
* :mod:`.kalman` — exact discretisation (matrix exponential; process noise by the stationary
  covariance, checked against Van Loan) and the batched Kalman-filter likelihood;
* :mod:`.data` — nights on one step grid per household, padded into a batch;
* :mod:`.posterior` — likelihood + class and physical priors;
* :mod:`.optim` — batched BFGS and damped Newton on per-household objectives;
* :mod:`.estimator` — :class:`StateSpaceFit`, :func:`fit_households`: MAP, Laplace intervals;
* :mod:`.adequacy` — Ljung–Box and Bartlett tests of the standardised innovations.
"""

from .estimator import StateSpaceFit, fit_households

__all__ = ["StateSpaceFit", "fit_households"]
