"""Two clients with one MQTT client id: each CONNECT makes the broker close the other's session
(MQTT 3.1.1 §3.1.4: "the Server MUST disconnect the existing Client"; MQTT 5 sends reason
code 0x8E, "Session taken over"). Over MQTT 3.1.1 the client only sees its connection lost,
like an outage, so the pattern is what names it: sessions ended by the broker within seconds
of their start, several times in a row, while every reconnect succeeds.
"""

from __future__ import annotations

import math
import time

#: A session the broker ends sooner than this after it began counts as short [wall s].
SHORT_S = 10.0
#: Short sessions in a row that name a client-id clash.
IN_A_ROW = 3
#: MQTT 5 reason code of DISCONNECT: "Session taken over".
SESSION_TAKEN_OVER = 0x8E


def _reason_code(exc: BaseException) -> int | None:
    rc = getattr(exc, "rc", None)
    value = getattr(rc, "value", rc)
    return value if isinstance(value, int) else None


class TakeoverWatch:
    """Counts short sessions; says when they amount to a client-id clash and when it is over.

    Parameters
    ----------
    client_id : the id both clients use (for the message)
    short_s, in_a_row : what counts as short, and how many in a row make a clash
    """

    def __init__(self, client_id: str, short_s: float = SHORT_S, in_a_row: int = IN_A_ROW):
        self.client_id, self.short_s, self.in_a_row = client_id, short_s, in_a_row
        self.clash = False
        self._short = 0
        self._started: float | None = None
        self._lost: float | None = None

    @property
    def reason(self) -> str:
        """The clash in one line (the link's error for ``impctl status``)."""
        return (f"client id '{self.client_id}' is in use by another client: the broker hands "
                "the session to whichever connected last (session taken over); give each "
                "gateway its own mqtt.client_id")

    def started(self) -> None:
        """A session began (CONNACK received)."""
        self._started, self._lost = time.monotonic(), None

    def lost(self) -> None:
        """The connection dropped now. An operation awaiting the broker's reply notices it
        only at its own timeout, seconds later; the session's length ends here."""
        if self._started is not None and self._lost is None:
            self._lost = time.monotonic()

    def lived_s(self) -> float:
        """Wall seconds the current (or last) session has lasted (up to the moment its
        connection dropped, when known); inf when none began."""
        if self._started is None:
            return math.inf
        end = time.monotonic() if self._lost is None else self._lost
        return end - self._started

    def ended(self, exc: BaseException) -> str | None:
        """The broker ended the session with ``exc``. Returns "new" when this makes a clash,
        "ongoing" while one lasts, "short" for a short session not (yet) a clash, None for an
        ordinary end (the caller's outage handling applies)."""
        lived, self._started, self._lost = self.lived_s(), None, None
        taken = _reason_code(exc) == SESSION_TAKEN_OVER
        if not taken and lived >= self.short_s:
            self._short, self.clash = 0, False
            return None
        self._short += 1
        if self.clash:
            return "ongoing"
        if taken or self._short >= self.in_a_row:
            self.clash = True
            return "new"
        return "short"

    def held(self) -> bool:
        """Called ``short_s`` after a session began: True (and the clash forgotten) when that
        session still runs, i.e. the other client has gone."""
        if self._started is None or self.lived_s() < self.short_s or not self.clash:
            return False
        self._short, self.clash = 0, False
        return True
