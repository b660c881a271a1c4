"""SQLite storage of IMP nights, samples, the restore journal, trigger requests and fits.

One file in the state directory, WAL mode, every write committed at once (a sample taken is a
sample kept, even if the process is killed the next instant). The schema is versioned with
``PRAGMA user_version`` and migrated forward on open. Times are stored as UTC ISO 8601 strings;
temperatures in °C, powers in W.
"""

from .db import Store
from .records import (
    CampaignDecision,
    Command,
    FitRecord,
    JournalEntry,
    Night,
    Sample,
    TriggerRequest,
)
from .schema import SCHEMA_VERSION

__all__ = ["SCHEMA_VERSION", "CampaignDecision", "Command", "FitRecord", "JournalEntry",
           "Night", "Sample", "Store", "TriggerRequest"]
