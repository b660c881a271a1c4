"""Incidents of one night: the heat-pump link lost, or the readings a night needs missing.

Each incident is logged once and recorded as a store event when it starts and when it ends —
one line per incident, not one per poll — and noted in the night's reasons with its start and
length.
"""

from __future__ import annotations

import logging
from datetime import datetime

from ..store import Store


def _span(what: str, since: datetime, until: datetime) -> str:
    """An incident note: what, from when, how long (UTC)."""
    minutes = (until - since).total_seconds() / 60
    return f"incident: {what} from {since:%H:%M}Z for {minutes:.0f} min"


class Incidents:
    """The open incidents of one night and the notes of the closed ones.

    Parameters
    ----------
    store : Store
        Receives one event when an incident starts and one when it ends.
    """

    def __init__(self, store: Store) -> None:
        self.store = store
        #: Notes of the closed incidents, for the night's reasons.
        self.notes: list[str] = []
        self._lost_since: datetime | None = None
        self._problem: tuple[str, datetime] | None = None  # missing readings: why, since when

    def link_lost(self, exc: Exception, since: datetime, log: logging.Logger) -> None:
        """The first failed poll after a good one (or before any)."""
        log.warning("heat-pump link lost: %s", exc)
        self.store.add_event("warning", f"link lost: {exc}")
        self._lost_since = since

    def link_back(self, now: datetime, log: logging.Logger) -> None:
        """The first good poll after a failed one."""
        log.info("heat-pump link back")
        self.store.add_event("info", "link back")
        if self._lost_since is not None:
            self.notes.append(_span("link lost", self._lost_since, now))
            self._lost_since = None

    def readings(self, problem: str | None, now: datetime, log: logging.Logger) -> None:
        """A good poll's missing-readings problem (None: all there): a change of problem
        closes the open incident and opens the new one."""
        if problem == (self._problem and self._problem[0]):
            return
        if self._problem is not None:
            self.notes.append(_span(self._problem[0], self._problem[1], now))
            if problem is None:
                log.info("readings back: %s is over", self._problem[0])
                self.store.add_event("info", f"readings back ({self._problem[0]})")
        if problem is not None:
            log.warning("readings missing: %s", problem)
            self.store.add_event("warning", f"readings missing: {problem}")
        self._problem = None if problem is None else (problem, now)

    def close(self, now: datetime) -> None:
        """The night ends: note the incidents still going on."""
        if self._lost_since is not None:
            self.notes.append(_span("link lost", self._lost_since, now))
        if self._problem is not None:
            self.notes.append(_span(self._problem[0], self._problem[1], now))
        self._lost_since = self._problem = None
