"""The season model: HLC, τ and C_m from every night and day the gateway recorded.

The owner's own days and nights (read-only recordings, kind ``owner``) carry the heat loss over
a winter's spread of outdoor temperatures; the constrained IMP nights carry the time constant.
One model — ISO 13790's 5R1C read in demand form (:mod:`.projection.columns`) — and one
least-squares likelihood over all of them (:mod:`.projection.solve`), with intervals
(:mod:`.fit`). No torch.

>>> from impctl.season import fit_season, record_from_nights
>>> fit = fit_season(record_from_nights(nights))          # doctest: +SKIP
"""

from .fit import MIN_OWNER_NIGHTS, fit_season, signature
from .nights import record_from_nights
from .record import SeasonRecord
from .result import SeasonFit

__all__ = ["MIN_OWNER_NIGHTS", "SeasonFit", "SeasonRecord", "fit_season", "record_from_nights",
           "signature"]
