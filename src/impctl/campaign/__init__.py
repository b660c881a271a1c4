"""The adaptive IMP campaign: stop as soon as HLC and τ are known to the precision the
aggregator needs, and choose each next night by the information it is expected to bring.

:mod:`.records` holds what the policy reads and writes (target, nights, fit summaries,
predictions, decision); :mod:`.policy` decides run / skip / stop (both standard library only,
imported by the daemon);
:mod:`.design` (numpy + :mod:`impctl.model`, run by ``impctl campaign next`` in a subprocess)
predicts, for each possible next night, the interval half-widths after it.
"""

from .policy import decide, plan_order
from .records import (
    CONSTRAINED,
    NORMAL,
    Candidate,
    Decision,
    FitSummary,
    NightRecord,
    Outlook,
    Target,
    parse_candidates,
    parse_outlook,
)

__all__ = ["CONSTRAINED", "NORMAL", "Candidate", "Decision", "FitSummary", "NightRecord",
           "Outlook", "Target", "decide", "parse_candidates", "parse_outlook",
           "plan_order"]
