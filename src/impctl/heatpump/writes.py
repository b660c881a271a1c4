"""Safe writes: whitelist, clamp, compare before writing, budget, write, read back.

The order matters and is the safety argument:

1. only whitelisted registers (2187, 2042; 2049/2052, 2014 and the curve points 2309/2314
   when configured), never 2017, 2018, 2113, 539 or 2197 — refused before any traffic;
2. the value is clamped to the configured limits (mode registers: an exact documented code);
3. the register is read; if it already holds the value, nothing is written (no EEPROM wear);
4. the write is counted against the register's daily budget *before* it is sent (an
   experiment's write that cannot be counted is refused; a restore that cannot be counted
   is logged and sent anyway: putting the owner's settings back never depends on recording);
5. FC 06, then read back (after a pause; the first answer may still be the old value) until
   it matches, else :class:`WriteVerifyError`.

Both reads take an answer only when it can be attributed to its request
(:func:`.attributed.attributed`: on an RTU line shared with another master, the other master's
answer of the right length may come first). A compare that cannot be attributed writes
nothing; a read-back that cannot be attributed is not a verification: the write is in doubt
and raises (as when the read-back is lost), so the caller never claims its value.

Every write whose answer is lost or is a Modbus exception is followed by the read-back, which
decides whether it executed (a gateway's exception 10/11 can hide an executed write). The
budget counts what the read-back shows: a write whose answer was lost or an exception and that
reads back unchanged did not execute and is given back (a restore is given back whenever it
reads back unchanged), so retrying a restore through a flaky link never uses up the budget
and its reserve and keeps the heating off for the rest of the day. Repeated failures of the
same register are logged once, at the first failure, until a write of it succeeds (one line
per incident, not per retry).
"""

from __future__ import annotations

import asyncio
import logging
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime

from ..clock import VirtualClock
from ..errors import InputError
from ..kronoterm.decode import decode, encode, raw_value
from ..kronoterm.registers import FORBIDDEN_WRITES, Kind, Register
from ..modbus import ModbusDeviceError, ModbusLink, ModbusLinkError
from .attributed import attributed, unattributable
from .budget import WriteBudget
from .config import CURVE_FLOW_BOUNDS_C, WritePolicy
from .errors import HeatPumpError, WriteRefused, WriteVerifyError

_LOG = logging.getLogger(__name__)
_MODES = frozenset({0, 1, 2})
#: The loop-1 heating-curve points: their owner's values are always restorable.
CURVE_POINTS = (2309, 2314)

Rule = tuple[float, float] | frozenset[int]


@dataclass(frozen=True)
class WriteResult:
    """What a safe write did.

    Attributes
    ----------
    name, ma : register name and documented number.
    requested : value asked for (physical unit).
    target : value after clamping (physical unit).
    clamped : the requested value lay outside the configured limits.
    written : ``False`` when the register already held the target (nothing sent).
    previous : value before the write (physical unit).
    read_back : value read back after the write (physical unit), or ``previous`` if unchanged.
    used_today : writes of this register counted today, including this one.
    """

    name: str
    ma: int
    requested: float
    target: float
    clamped: bool
    written: bool
    previous: float
    read_back: float
    used_today: int


def write_rules(policy: WritePolicy) -> Mapping[int, Rule]:
    """Writable register → clamp limits (physical unit) or the set of allowed codes."""
    rules: dict[int, Rule] = {2187: policy.loop1_setpoint_c, 2042: _MODES}
    if policy.loop2_setpoint_c is not None:
        rules.update({2049: policy.loop2_setpoint_c, 2052: _MODES})
    if policy.correction_k is not None:
        rules[2014] = (float(policy.correction_k[0]), float(policy.correction_k[1]))
    if policy.loop1_curve_c is not None:
        lo, hi = (float(v) for v in policy.loop1_curve_c)
        own = policy.loop1_curve_owner_c or (hi, hi)
        rules.update({ma: (lo, max(hi, float(o))) for ma, o in zip(CURVE_POINTS, own,
                                                                   strict=True)})
    if FORBIDDEN_WRITES & set(rules):  # guards against a future edit of this table
        raise RuntimeError("a forbidden register slipped into the write whitelist")
    return rules


def _rule(reg: Register, policy: WritePolicy, restore: bool = False) -> Rule:
    if reg.ma in FORBIDDEN_WRITES:
        raise WriteRefused(f"register {reg.ma} ({reg.name}) is never written by impctl")
    rule = write_rules(policy).get(reg.ma)
    if rule is None and restore and reg.ma in CURVE_POINTS:
        # The owner's curve comes back whatever the configuration says now.
        rule = CURVE_FLOW_BOUNDS_C
    if rule is None:
        raise WriteRefused(f"register {reg.ma} ({reg.name}) is not in the write whitelist "
                           "for this configuration")
    return rule


def _finite(reg: Register, value: float) -> float:
    if not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise InputError(f"write value must be a finite number, got {value!r}",
                         place=f"register {reg.ma}")
    return float(value)


def _mode(reg: Register, value: float, codes: frozenset[int]) -> float:
    if value != int(value) or int(value) not in codes:
        raise WriteRefused(f"register {reg.ma} ({reg.name}) accepts only {sorted(codes)}, "
                           f"not {value!r}")
    return float(int(value))


def check_target(reg: Register, value: float, policy: WritePolicy) -> float:
    """Apply the whitelist and limits; return the value to write.

    Raises
    ------
    WriteRefused
        Forbidden or not whitelisted register, or a mode code that is not documented.
    InputError
        A value that is not a finite number.
    """
    rule = _rule(reg, policy)
    value = _finite(reg, value)
    if isinstance(rule, frozenset):
        return _mode(reg, value, rule)
    low, high = rule
    return min(max(value, low), high)


def check_restore(reg: Register, value: float, policy: WritePolicy) -> float:
    """Validate an owner's value being put back: whitelisted and plausible, *not* clamped.

    The owner's setpoint may lie outside impctl's experiment limits; it is still refused when
    it is no documented mode code, no plausible temperature (sentinel or outside −60…150 °C) or
    outside the documented −4…4 K of the correction.
    """
    rule = _rule(reg, policy, restore=True)
    value = _finite(reg, value)
    if isinstance(rule, frozenset):
        return _mode(reg, value, rule)
    if reg.kind is Kind.TEMP:
        reading = decode(reg, [encode(reg, value)], datetime.now(UTC))
        if reading.missing:
            raise WriteRefused(f"register {reg.ma}: will not restore {value!r} "
                               f"({reading.reason})")
    elif reg.ma == 2014 and not -4 <= value <= 4:
        raise WriteRefused(f"register 2014: will not restore {value!r} (outside -4…4 K)")
    return value


async def safe_write(link: ModbusLink, reg: Register, value: float, policy: WritePolicy,
                     budget: WriteBudget | None, clock: VirtualClock, *,
                     restore: bool = False) -> WriteResult:
    """Write ``value`` to ``reg`` following the module's five steps.

    Parameters
    ----------
    restore : bool
        Put back an owner's journaled value: validated by :func:`check_restore` instead of
        clamped, and allowed to use ``policy.restore_reserve`` writes beyond the daily budget
        (so a used-up budget can never keep the heating off).

    Raises
    ------
    WriteRefused, WriteBudgetExceeded
        Nothing was sent.
    ModbusDeviceError
        The device rejected the write (exception response).
    ModbusLinkError
        The link failed before the write, the register's value before it could not be
        attributed (nothing was sent), or both the write and every read-back failed.
    WriteVerifyError
        The value read back differs from the value written, or no read-back answer could be
        attributed to its request.
    """
    limited = (check_restore if restore else check_target)(reg, value, policy)
    if budget is None:
        raise WriteRefused("no write budget configured; writes are disabled")
    clamped = limited != float(value)
    if clamped:
        _LOG.warning("register %d (%s): %s %s clamped to %s %s", reg.ma, reg.name, value,
                     reg.unit, limited, reg.unit)
    word = encode(reg, limited)
    target = raw_value(reg, word)
    before = await attributed(link, lambda: link.read(reg.address, 1))
    if before is None:
        # Another master's answer may hold anything, the target too: "already there" taken
        # from it would skip the write and claim a value the register never held.
        raise ModbusLinkError(f"register {reg.ma} ({reg.name}): " + unattributable(
            link, "its value before the write is unknown; nothing written"))
    current = before[0]
    previous = raw_value(reg, current)
    if current == word:
        _LOG.info("register %d (%s) already %s %s; not written", reg.ma, reg.name, target,
                  reg.unit)
        return WriteResult(reg.name, reg.ma, float(value), target, clamped, False,
                           previous, previous, budget.used_or_zero(reg.ma, clock.now().date()))
    reserve = policy.restore_reserve if restore else 0
    day = clock.now().date()
    # A register whose last write failed: log its repeated failures at DEBUG only.
    loud = logging.DEBUG if reg.ma in link.failed_writes else logging.WARNING
    delay = link.config.retry_delay_s
    for attempt in range(link.config.attempts):
        used = budget.consume(reg.ma, day, reserve=reserve, best_effort=restore)
        write_error = await _send(link, reg, word, loud)
        read_back, crossed = await _read_back(link, reg, word, policy, loud)
        if read_back == word:
            break
        if read_back == current and (restore or write_error is not None):
            # Unchanged after a lost or exception answer: the write never executed. (An
            # acknowledged write that reads back unchanged still counts: it may have reached
            # the EEPROM before the controller overrode it; only a restore is given back.)
            budget.refund(reg.ma, day)
            if (isinstance(write_error, ModbusDeviceError) and write_error.transient
                    and attempt + 1 < link.config.attempts):
                await asyncio.sleep(delay)  # busy / gateway 10, 11: not now, later
                delay *= 2
                continue
        link.failed_writes.add(reg.ma)
        if isinstance(write_error, ModbusDeviceError) and read_back in (current, None):
            raise write_error  # the caller reports the device's answer
        shown = ("nothing" if read_back is None else f"{raw_value(reg, read_back)} {reg.unit}")
        shown += " attributable" if crossed else ""
        msg = (f"register {reg.ma} ({reg.name}): wrote {target} {reg.unit}, read back {shown} "
               f"after {policy.verify_attempts} attempt(s)")
        _LOG.log(logging.ERROR if loud == logging.WARNING else loud, msg)
        if read_back is None and write_error is not None:
            raise ModbusLinkError(msg) from write_error
        raise WriteVerifyError(msg, reg.ma, word, read_back)
    link.failed_writes.discard(reg.ma)
    _LOG.warning("register %d (%s): %s → %s %s and verified (%d/%d today)", reg.ma,
                 reg.name, _shown(reg, previous), _shown(reg, target),
                 "restored" if restore else "written", used, budget.limit(reg.ma))
    return WriteResult(reg.name, reg.ma, float(value), target, clamped, True, previous,
                       target, used)


def _shown(reg: Register, value: float | None) -> str:
    """A register value as people write it: "22.5 °C" for a setpoint, "1" for a mode code."""
    if value is None:
        return "unknown"
    return f"{value:.1f} {reg.unit}" if reg.unit else f"{value:.0f}"


async def _send(link: ModbusLink, reg: Register, word: int, loud: int) -> HeatPumpError | None:
    """FC 06 once; the error if its answer was lost or an exception (the read-back decides)."""
    try:
        await link.write(reg.address, word)
    except ModbusDeviceError as exc:
        # An exception answer may come from a gateway whose RS-485 side lost the device's
        # answer (10, 11) after the write executed: only the read-back can tell.
        _LOG.info("register %d: write answered with Modbus exception %d; checking by "
                  "read-back", reg.ma, exc.exception_code)
        return exc
    except ModbusLinkError as exc:
        # The write may have landed even though its answer was lost: let the read-back decide.
        _LOG.log(loud, "register %d: write not confirmed (%s); checking by read-back", reg.ma,
                 exc)
        return exc
    return None


async def _read_back(link: ModbusLink, reg: Register, word: int, policy: WritePolicy,
                     level: int = logging.WARNING) -> tuple[int | None, bool]:
    """The register's word after the write — ``word`` once an attributable answer shows it,
    else the last attributable word read, or None when none was — and whether an attempt's
    answers could not be attributed."""
    seen: int | None = None
    crossed = False
    for _ in range(policy.verify_attempts):
        await asyncio.sleep(policy.verify_delay_s)
        try:
            words = await attributed(link, lambda: link.read(reg.address, 1))
        except HeatPumpError as exc:
            _LOG.log(level, "register %d read-back failed: %s", reg.ma, exc)
            continue
        if words is None:
            # Another master's answer of the right length may carry the written word: an
            # attempt that proves nothing, like a lost answer.
            crossed = True
            _LOG.log(level, "register %d read-back failed: %s", reg.ma,
                     unattributable(link, "not taken as the register's value"))
            continue
        seen = words[0]
        if seen == word:
            return seen, crossed
    return seen, crossed
