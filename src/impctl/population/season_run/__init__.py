"""A heating season on virtual households: the IMP campaign with the owner's own nights
around it, on the realistic plant.

* :mod:`.season` — :func:`~.season.simulate_season`: a winter per household in one pass
* :mod:`.nights` — a simulated season's nights as a household's NIGHTS (IMP and owner)
"""
