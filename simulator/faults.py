"""Fault injection for the simulator, switchable at start (``--faults``) and at run time.

Syntax: comma-separated items, e.g. ``"delay=2.5,greeting,fixed-tid,missing=2103:2160"``:

======================  ===========================================================
``drop``                close each connection when a request arrives (no answer)
``delay=S``             wait S wall-clock seconds before answering each request
``exception=N``         answer every request with Modbus exception code N
``greeting[=HEX]``      send unsolicited bytes on each new connection (default: a MAC)
``greeting-delay=S``    send the greeting S seconds after the connection opened
``fixed-tid[=N]``       put MBAP transaction id N (default 20) into every TCP response
``freeze``              stop updating the registers (stale values; the model runs on)
``missing=MA:MA``       these documented registers read −600 (sensor not connected)
``ignore-writes``       acknowledge FC 06 writes but keep the old value
``gateway-exceptions=R``  answer a share R of requests with gateway exception 10 or 11
``spikes=R@S``          delay a share R of answers by S wall-clock seconds (past a timeout)
``duplicates=R@S``      send a share R of answers twice, the copy up to S seconds later
``foreign=R[@S]``       RTU: before a share R of FC 03 answers, a second master's answer of
                        the same length (other registers) crosses the line; the real answer
                        follows S wall-clock seconds later (default 0)
``write-answer-lost=R``  a share R of FC 06 writes execute, but the gateway answers 11
``cop-3-decimals``      the controller encodes COP/SCOP (2371/2372) as ×0.001, not ×0.01
``tt3000-undocumented`` compact controller answers undocumented registers (2130 low, 2329
                        1234, COP 0) instead of exception 2, like some real TT3000/WPG units
``none``                no faults
======================  ===========================================================
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

from impctl.errors import InputError

#: A typical gateway "registration packet": its MAC address.
DEFAULT_GREETING = bytes.fromhex("9ca525a1b2c3")


@dataclass
class Faults:
    """Active faults; a plain mutable object the server consults on every request.

    Attributes
    ----------
    drop : bool
    delay_s : float
    exception_code : int
        0 = off.
    greeting : bytes
        Empty = off.
    greeting_delay_s : float
    fixed_tid : int or None
    freeze : bool
    missing_sensors : set of int
        Documented register numbers that read −600.
    ignore_writes : bool
    """

    drop: bool = False
    delay_s: float = 0.0
    exception_code: int = 0
    greeting: bytes = b""
    greeting_delay_s: float = 0.0
    fixed_tid: int | None = None
    freeze: bool = False
    missing_sensors: set[int] = field(default_factory=set)
    ignore_writes: bool = False
    # -- issue 15: a faulty gateway / shared bus --
    gateway_exception_rate: float = 0.0
    spike_rate: float = 0.0
    spike_s: float = 0.0
    duplicate_rate: float = 0.0
    duplicate_delay_s: float = 0.0
    foreign_rate: float = 0.0
    foreign_delay_s: float = 0.0
    tt3000_undocumented: bool = False
    cop_3_decimals: bool = False
    write_answer_lost_rate: float = 0.0

    def update(self, other: Faults) -> None:
        """Take over every field of ``other`` (switch faults at run time, in place)."""
        for f in fields(self):
            setattr(self, f.name, getattr(other, f.name))

    def describe(self) -> str:
        """The active faults in :func:`parse_faults` syntax (``"none"`` if there are none)."""
        items = []
        if self.drop:
            items.append("drop")
        if self.delay_s:
            items.append(f"delay={self.delay_s:g}")
        if self.exception_code:
            items.append(f"exception={self.exception_code}")
        if self.greeting:
            items.append(f"greeting={self.greeting.hex()}")
        if self.greeting_delay_s:
            items.append(f"greeting-delay={self.greeting_delay_s:g}")
        if self.fixed_tid is not None:
            items.append(f"fixed-tid={self.fixed_tid}")
        if self.freeze:
            items.append("freeze")
        if self.missing_sensors:
            items.append("missing=" + ":".join(str(m) for m in sorted(self.missing_sensors)))
        if self.ignore_writes:
            items.append("ignore-writes")
        if self.gateway_exception_rate:
            items.append(f"gateway-exceptions={self.gateway_exception_rate:g}")
        if self.spike_rate:
            items.append(f"spikes={self.spike_rate:g}@{self.spike_s:g}")
        if self.duplicate_rate:
            items.append(f"duplicates={self.duplicate_rate:g}@{self.duplicate_delay_s:g}")
        if self.foreign_rate:
            items.append(f"foreign={self.foreign_rate:g}" + (
                f"@{self.foreign_delay_s:g}" if self.foreign_delay_s else ""))
        if self.tt3000_undocumented:
            items.append("tt3000-undocumented")
        if self.cop_3_decimals:
            items.append("cop-3-decimals")
        if self.write_answer_lost_rate:
            items.append(f"write-answer-lost={self.write_answer_lost_rate:g}")
        return ",".join(items) or "none"


def parse_faults(text: str, source: str | None = None) -> Faults:
    """Parse the fault syntax of the module docstring.

    Raises
    ------
    InputError
        Unknown item or bad value.
    """
    faults = Faults()
    for item in (part.strip() for part in text.split(",")):
        if not item or item == "none":
            continue
        key, _, value = item.partition("=")
        try:
            if key == "drop":
                faults.drop = True
            elif key == "delay":
                faults.delay_s = float(value)
                if faults.delay_s < 0:
                    raise ValueError("delay must be >= 0")
            elif key == "exception":
                faults.exception_code = int(value)
                if not 1 <= faults.exception_code <= 0x0B:
                    raise ValueError("exception code must be 1–11")
            elif key == "greeting":
                faults.greeting = bytes.fromhex(value) if value else DEFAULT_GREETING
            elif key == "greeting-delay":
                faults.greeting_delay_s = float(value)
                if faults.greeting_delay_s < 0:
                    raise ValueError("delay must be >= 0")
            elif key == "fixed-tid":
                faults.fixed_tid = int(value) if value else 20
            elif key == "freeze":
                faults.freeze = True
            elif key == "missing":
                faults.missing_sensors = {int(m) for m in value.split(":") if m}
            elif key == "ignore-writes":
                faults.ignore_writes = True
            elif key == "gateway-exceptions":
                faults.gateway_exception_rate = _rate(value)
            elif key in ("spikes", "duplicates"):
                rate, _, seconds = value.partition("@")
                pair = (_rate(rate), float(seconds))
                if pair[1] < 0:
                    raise ValueError("seconds must be >= 0")
                if key == "spikes":
                    faults.spike_rate, faults.spike_s = pair
                else:
                    faults.duplicate_rate, faults.duplicate_delay_s = pair
            elif key == "foreign":
                rate, _, seconds = value.partition("@")
                faults.foreign_rate = _rate(rate)
                faults.foreign_delay_s = float(seconds) if seconds else 0.0
                if faults.foreign_delay_s < 0:
                    raise ValueError("seconds must be >= 0")
            elif key == "tt3000-undocumented":
                faults.tt3000_undocumented = True
            elif key == "write-answer-lost":
                faults.write_answer_lost_rate = _rate(value)
            elif key == "cop-3-decimals":
                faults.cop_3_decimals = True
            else:
                raise ValueError("unknown fault")
        except ValueError as exc:
            raise InputError(f"bad fault {item!r}: {exc}", source, "faults") from None
    return faults


def _rate(text: str) -> float:
    rate = float(text)
    if not 0.0 <= rate <= 1.0:
        raise ValueError("rate must be 0–1")
    return rate
