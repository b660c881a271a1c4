"""The IMP night state machine: prepare → act → sample → end → restore → assess."""

from .assess import assess_night
from .night import NightController, NightRefused
from .plan import NightPolicy, NightRequest
from .poll import sample_from_snapshot
from .restore import restore_all

__all__ = [
    "NightController",
    "NightPolicy",
    "NightRefused",
    "NightRequest",
    "assess_night",
    "restore_all",
    "sample_from_snapshot",
]
