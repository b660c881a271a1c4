"""The steps of one :class:`~impctl.fit.NightFit`, each by concern (torch; internal):

* :mod:`.problems` — the nights prepared once, the problems laid out (:mod:`..layout`: the
  starts, boxes, groups and rows of one optimiser call);
* :mod:`.weights` — the noise weights and the refits they ask for;
* :mod:`.statement` — the problem reported and every fitted attribute;
* :mod:`.params` — what the steps read of the estimator's constructor parameters.
"""
