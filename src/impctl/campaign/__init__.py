"""The adaptive IMP campaign: stop as soon as HLC and τ are known to the precision the
aggregator needs, and choose each next night by the information it is expected to bring.

:mod:`.policy` (standard library only, imported by the daemon) decides run / skip / stop;
:mod:`.design` (numpy + :mod:`impctl.model`, run by ``impctl campaign next`` in a subprocess)
predicts, for each possible next night, the interval half-widths after it.
"""

from .policy import (
    CONSTRAINED,
    NORMAL,
    Candidate,
    Decision,
    FitSummary,
    NightRecord,
    Outlook,
    Target,
    decide,
    parse_candidates,
    parse_outlook,
    plan_order,
)

__all__ = ["CONSTRAINED", "NORMAL", "Candidate", "Decision", "FitSummary", "NightRecord",
           "Outlook", "Target", "decide", "parse_candidates", "parse_outlook",
           "plan_order"]
