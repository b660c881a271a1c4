"""The IMP run on virtual households: how it is set up, and its simulated nights.

* :mod:`.setup` — :class:`~.setup.ImpSimConfig` (the protocol) and the weather's usable nights
* :mod:`.ideal` — every household's nights on the ideal 5R1C, vectorised
* :mod:`.realistic` — the same nights on the realistic plant (:mod:`impctl.plant`)
* :mod:`.gateway` — constrained nights ended where the gateway's controller ends them
* :mod:`.synth` — fine-step simulated nights for the fit's tests and benches
"""
