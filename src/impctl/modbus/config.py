"""How to reach a Modbus device: TCP through an RS-485 gateway, or RTU on a serial line.

Bad values raise :class:`~impctl.errors.InputError` naming the key. Reading the TOML table is
the job of the package that owns the table (``[heatpump]``: :mod:`impctl.heatpump.config`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from ..errors import InputError

Transport = Literal["tcp", "rtu"]
#: Baud rates accepted for RTU; Kronoterm controllers use 19200 (TT3000, WPG) or 115200 (KSM).
BAUD_RATES = (9600, 19200, 38400, 57600, 115200)
Problem = tuple[str, str]  # (key, what is wrong)


@dataclass(frozen=True)
class LinkConfig:
    """How to reach a Modbus device (TCP through an RS-485 gateway, or RTU, 8N1).

    Attributes
    ----------
    transport : {"tcp", "rtu"}
    host, port : TCP gateway address.
    serial_port : RTU device path or pyserial URL (``socket://host:port`` is RTU over TCP).
    baudrate : RTU baud rate (8 data bits, no parity, 1 stop bit).
    device_id : Modbus unit id (default 20, the Kronoterm default).
    timeout_s : per-request response timeout and connect timeout [s].
    retries : accepted for old configurations and ignored: pymodbus' own resends are off,
        because a resend under the same transaction id lets a late answer complete a later
        request (issue 15); ``attempts`` does the retrying.
    attempts : tries of one read, with doubling back-off and a reconnect after a timeout
        (transient exceptions 5, 6, 10, 11 are retried; other exceptions are final).
    retry_delay_s : pause between tries [s].
    connect_backoff_s : first and maximum pause of the connect loop [s] (doubling).
    drain_s : wait after each connect before discarding unsolicited bytes (gateway greeting)
        [s]; 0 disables the drain.
    tolerate_fixed_tid : accept TCP responses whose transaction id does not match (gateways
        that answer with a fixed id); the connection is reset after any timeout then, so a late
        answer can never be taken for the next request's.
    request_gap_s : idle time between requests [s] (serial lines want ≥ 0.035).
    settle_s : RTU only: wait this long after each answer before accepting it, so that a
        real answer overtaken by a foreign or duplicated frame is seen [s] (issue 15).
    """

    transport: Transport = "tcp"
    host: str = "127.0.0.1"
    port: int = 502
    serial_port: str = ""
    baudrate: int = 19200
    device_id: int = 20
    timeout_s: float = 3.0
    retries: int = 1
    attempts: int = 3
    retry_delay_s: float = 1.0
    connect_backoff_s: tuple[float, float] = (0.5, 30.0)
    drain_s: float = 0.2
    tolerate_fixed_tid: bool = False
    request_gap_s: float = 0.0
    # -- issue 15: answer attribution (kept apart from the keys above) --
    settle_s: float = 0.05

    def __post_init__(self) -> None:
        raise_first(link_problems(self))

    def describe(self) -> str:
        """Human-readable endpoint, e.g. ``tcp 127.0.0.1:502 unit 20``."""
        where = (f"{self.host}:{self.port}" if self.transport == "tcp"
                 else f"{self.serial_port} {self.baudrate} 8N1")
        return f"{self.transport} {where} unit {self.device_id}"


def raise_first(problems: list[Problem]) -> None:
    """Raise the first of ``problems`` as an :class:`InputError` naming its key."""
    if problems:
        key, text = problems[0]
        raise InputError(text, place=f"key '{key}'")


def link_problems(c: Any) -> list[Problem]:
    """Every problem of a :class:`LinkConfig`'s values (or of anything with its attributes)."""
    out: list[Problem] = []
    if c.transport not in ("tcp", "rtu"):
        out.append(("transport", f"must be 'tcp' or 'rtu', got {c.transport!r}"))
    if c.transport == "tcp" and not str(c.host).strip():
        out.append(("host", "must not be empty (the gateway's IP address or name)"))
    if c.transport == "rtu" and not c.serial_port:
        out.append(("serial_port", "rtu needs serial_port"))
    if c.baudrate not in BAUD_RATES:  # checked on tcp too: a typo there is a typo
        out.append(("baudrate", f"must be one of {BAUD_RATES}"))
    if not 1 <= c.device_id <= 247:
        out.append(("device_id", "must be 1–247"))
    if not 0 < c.port < 65536:
        out.append(("port", "must be 1–65535"))
    if not 0 < c.timeout_s <= 60:
        out.append(("timeout_s", "must lie in (0, 60] s"))
    # A read that needs more than 10 tries (with doubling pauses: minutes) is a lost link,
    # which the night's link-lost limit handles.
    if not 0 <= c.retries <= 10:
        out.append(("retries", "must lie in 0–10"))
    if not 1 <= c.attempts <= 10:
        out.append(("attempts", "must lie in 1–10"))
    lo, hi = c.connect_backoff_s
    if not 0 < lo <= hi <= 3600:  # an hour: the longest a night may run without readings
        out.append(("connect_backoff_s",
                    "must be (first, max) with 0 < first <= max <= 3600 s"))
    # Upper bounds: the pause between tries (60 s) and the drain after a connect (10 s) are
    # generous for any gateway; a poll makes 10–20 requests, so 1 s between them already
    # takes up to 20 s of a sample interval.
    for key, top in (("drain_s", 10.0), ("request_gap_s", 1.0), ("retry_delay_s", 60.0)):
        if not 0 <= getattr(c, key) <= top:
            out.append((key, f"must lie in 0–{top:g} s"))
    if not 0 <= c.settle_s <= 10:
        out.append(("settle_s", "must be 0–10 s"))
    return out
