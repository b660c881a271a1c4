"""Is this answer the answer to *this* request? Byte accounting, answer signatures, quirks.

pymodbus matches an answer to the pending request by the MBAP transaction id (TID) on Modbus
TCP; nothing else. Where there is no usable TID — RTU (none exists) or a TCP gateway that
answers with a fixed TID (``tolerate_fixed_tid``) — any well-formed frame that arrives while a
request is pending is taken as its answer: a late answer, a gateway's duplicate, a second
master's traffic. This module gives the link the checks that make such a mix-up visible:

* **Byte accounting** (every transport): the link sees every byte received. While a request is
  pending, exactly one answer frame of the expected length may arrive; anything more, or any
  byte received while nothing is pending, is *foreign traffic*. On RTU it makes the current
  answers unattributable (an impostor frame taken for our answer is followed by our real
  answer, which then shows up as extra bytes — within ``settle_s`` or in a later window, which
  is why a whole snapshot is read again when the counter moved); on TCP it is only evidence of
  a quirk (pymodbus skips frames with the wrong TID, and without TIDs the signature rule below
  leaves no impostor that could pass the checks).
* **Answer signatures** (TCP without TIDs): on one connection no two *different* requests may
  expect answers that look alike (same function code and length; an FC 06 echo carries its
  address and value), and no request is sent twice. Before a request that would break the rule
  the link opens a new connection. So on any connection an answer that passes the length and
  function-code checks can only be the answer to the one request that could produce it; late
  answers and duplicates from earlier requests die with the connection they were sent on.
* **Quirks** recognised from the traffic and named once, with the configuration that fixes
  them: a gateway answering with a fixed TID, greeting bytes after connect, a second master.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass, field

# Quirks are link incidents: logged under the link's logger, next to its other lines.
_LOG = logging.getLogger("impctl.modbus.link")

#: Quirk name → what it is and the configuration change that fixes it.
QUIRK_FIXES: dict[str, str] = {
    "fixed_tid": ("the gateway answers every request with the same Modbus TCP transaction id "
                  "{detail}: set tolerate_fixed_tid = true in [heatpump] (impctl then checks "
                  "answers by length and connection instead of the id)"),
    "greeting": ("the gateway sends unsolicited bytes after each connect ({detail}): they are "
                 "discarded; if answers still fail after connect raise drain_s in [heatpump]"),
    "second_master": ("foreign Modbus traffic on the line ({detail}): another master (outdoor "
                      "unit, cloud module, second integration) shares the RS-485 bus; give "
                      "impctl its own bus/gateway port or stop the other master — until then "
                      "affected samples are stored as missing"),
    "late_answers": ("answers arrive late or twice ({detail}): the gateway's RS-485 timeout is "
                     "longer than impctl's; raise timeout_s in [heatpump] (≥ 3 s for TCP "
                     "gateways)"),
}


def pdu_length(function_code: int, count_or_value: int, is_error: bool) -> int:
    """Length [bytes] of the answer PDU (function code + data) to an FC 03 or FC 06 request."""
    if is_error:
        return 2
    return 2 + 2 * count_or_value if function_code == 3 else 5


@dataclass
class _Window:
    key: tuple[int, int, int]
    sent_tid: int
    received: int = 0
    tids: list[int] = field(default_factory=list)


class Attribution:
    """Per-link bookkeeping of requests, received bytes and quirks.

    Parameters
    ----------
    transport : "tcp" or "rtu"
    tids_usable : bool
        The TCP gateway's transaction ids are trustworthy (``tolerate_fixed_tid`` is off).
    """

    def __init__(self, transport: str, tids_usable: bool) -> None:
        self.transport = transport
        self.tids_usable = transport == "tcp" and tids_usable
        #: Bumped whenever an answer may have been misattributed; readers compare it before
        #: and after a group of reads and discard the group when it moved.
        self.anomalies = 0
        self.quirks: dict[str, str] = {}
        self.foreign_bytes = 0
        self._window: _Window | None = None
        self._connected = False
        #: True while the link drains a fresh connection: bytes then are a greeting.
        self.draining = False
        self._keys: set[tuple[int, int, int]] = set()
        self._signatures: dict[tuple[int, int, int], tuple[int, int, int]] = {}
        self._mismatched_tids: Counter[int] = Counter()

    @property
    def framing(self) -> int:
        """Bytes around a PDU: MBAP header (TCP) or unit id + CRC (RTU)."""
        return 7 if self.transport == "tcp" else 3

    # -- connection lifecycle ------------------------------------------------------------------
    def connected(self) -> None:
        """A fresh connection: nothing sent on it yet."""
        self._connected = True
        self._keys.clear()
        self._signatures.clear()
        self._window = None

    def needs_new_connection(self, function_code: int, address: int, arg: int) -> bool:
        """Whether the request would break the signature rule on the current connection."""
        if self.tids_usable or self.transport != "tcp":
            return False
        key = (function_code, address, arg)
        if key in self._keys:
            return True
        owner = self._signatures.get(self._signature(key))
        return owner is not None and owner != key

    @staticmethod
    def _signature(key: tuple[int, int, int]) -> tuple[int, int, int]:
        fc, address, arg = key
        return (3, 0, arg) if fc == 3 else (6, address, arg)

    # -- one request ---------------------------------------------------------------------------
    def begin(self, function_code: int, address: int, arg: int, tid: int) -> None:
        """A request is about to be sent."""
        key = (function_code, address, arg)
        self._keys.add(key)
        self._signatures.setdefault(self._signature(key), key)
        self._window = _Window(key, tid)

    def received(self, data: bytes) -> None:
        """Every chunk of bytes the transport delivers (before pymodbus parses it)."""
        window = self._window
        if window is None and self.draining:
            self.note("greeting", f"{len(data)} byte(s): {data[:16].hex()}")
            return
        if window is None:
            self.foreign_bytes += len(data)
            self._foreign(f"{len(data)} byte(s) while no request was pending: {data[:16].hex()}")
            return
        window.received += len(data)
        if self.transport == "tcp":
            window.tids.extend(_mbap_tids(data))

    def end(self, function_code: int, arg: int, is_error: bool | None) -> str | None:
        """The request finished (``is_error`` None = no answer). Returns why the answer cannot
        be attributed, or None when the bytes received are exactly one answer."""
        window, self._window = self._window, None
        if window is None:
            return None
        if window.tids and self.transport == "tcp":
            self._check_tids(window)
        if is_error is None:
            return None
        expected = self.framing + pdu_length(function_code, arg, is_error)
        if window.received == expected:
            return None
        extra = window.received - expected
        self.foreign_bytes += max(extra, 0)
        if self.transport == "tcp":
            # With TIDs pymodbus skipped the surplus (a duplicate or late answer); without,
            # the signature rule leaves no other request on this connection whose answer
            # could pass the length and function-code checks.
            self.note("late_answers", f"{extra} surplus byte(s) around one answer")
            return None
        self._foreign(f"{window.received} byte(s) received for a {expected}-byte answer")
        return f"{window.received} bytes arrived for a {expected}-byte answer"

    def abandon(self) -> None:
        """The connection is being closed: whatever is pending is void."""
        self._window = None
        self._connected = False

    # -- quirks ------------------------------------------------------------------------------
    def _check_tids(self, window: _Window) -> None:
        # A fixed-TID gateway: request after request, answers carry one and the same foreign
        # id and never ours. Late duplicates carry varying old ids, or ours shows up too.
        if not window.sent_tid or window.sent_tid in window.tids or len(set(window.tids)) != 1:
            self._mismatched_tids.clear()
            return
        self._mismatched_tids[window.tids[0]] += 1
        tid, n = self._mismatched_tids.most_common(1)[0]
        if len(self._mismatched_tids) > 1:
            self._mismatched_tids = Counter({window.tids[0]: 1})
        elif n >= 2 and self.tids_usable:
            self.note("fixed_tid", f"{tid} in {n} answers in a row")

    def _foreign(self, detail: str) -> None:
        if self.transport == "rtu":
            # No TIDs, no connection to throw away: whatever was read around this may have
            # been overtaken by it.
            self.anomalies += 1
            self.note("second_master", detail)
        else:
            self.note("late_answers", detail)

    def note(self, quirk: str, detail: str) -> None:
        """Record a quirk; the first time it is seen, say so in one log line with its fix."""
        text = QUIRK_FIXES[quirk].format(detail=detail)
        if quirk not in self.quirks:
            _LOG.warning("Modbus quirk recognised: %s", text)
        self.quirks[quirk] = text


def _mbap_tids(data: bytes) -> list[int]:
    """Transaction ids of the MBAP frames in ``data`` (a chunk may hold several frames)."""
    tids = []
    while len(data) >= 7:
        tids.append(int.from_bytes(data[:2], "big"))
        data = data[6 + int.from_bytes(data[4:6], "big"):]
    return tids
