"""Household commands from the broker: parse and check a payload, or say in one line why not.

Topics under ``<base>/cmd/``:

* ``abort`` — end the running night now and restore the owner's settings;
* ``skip_tonight`` — do not start the next scheduled night;
* ``trigger`` — queue a night: ``tonight`` / ``now`` / ``PRESS``, or a JSON object
  ``{"kind": "constrained" | "normal", "setpoint_c": 21.0, "when": "tonight" | "now"}``;
  missing fields come from the two settings below;
* ``night_kind`` — ``constrained`` or ``normal`` (the trigger button's kind);
* ``night_setpoint`` — °C (the trigger button's setpoint).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from ..numtext import non_ascii_problem, underscore_problem
from .homeassistant.discovery import Limits

#: The commands under ``<base>/cmd/``.
COMMANDS = ("abort", "skip_tonight", "trigger", "night_kind", "night_setpoint")
#: Payloads a button may send (Home Assistant's default is PRESS; ours name the command).
#: Never the empty payload: that is how a retained message is cleared (``mosquitto_pub -r -n``),
#: and a person tidying the broker must not switch the heating off.
_PRESS = {"press", "1", "on", "true"}
_MAX_PAYLOAD = 256


class BadCommand(ValueError):
    """A payload that is not a valid command; ``str()`` says why in one line."""


@dataclass(frozen=True)
class Command:
    """A parsed command: ``name`` is abort, skip_tonight, trigger, night_kind or
    night_setpoint; the other fields are set where they apply."""

    name: str
    kind: str | None = None
    setpoint_c: float | None = None
    when: str | None = None


def setpoint_problem(kind: str, setpoint_c: float, limits: Limits) -> str | None:
    """Why a night at ``setpoint_c`` may not run (the CLI trigger's rule), or None."""
    lo, hi = limits.setpoint_min_c, limits.setpoint_max_c
    top = setpoint_c + limits.comfort_band_k if kind == "constrained" else setpoint_c
    if not (lo <= setpoint_c <= hi and top <= hi):
        return (f"setpoint {setpoint_c:g} °C (top {top:g} °C) outside the safety limits "
                f"[{lo:g}, {hi:g}] °C")
    return None


def _number(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise BadCommand(f"expected a number, got {value!r}")
    if isinstance(value, str):
        # float() would take '٢٢', '２２' or '2_2' as 22: the ASCII digits alone
        if (problem := non_ascii_problem(value) or underscore_problem(value)) is not None:
            raise BadCommand(problem)
    try:
        out = float(value)
    except ValueError:
        raise BadCommand(f"expected a number, got {value!r}") from None
    if not math.isfinite(out):
        raise BadCommand(f"expected a finite number, got {value!r}")
    return out


def parse_command(name: str, payload: bytes, limits: Limits, kind: str,
                  setpoint_c: float) -> Command:
    """Parse the payload of ``<base>/cmd/<name>``.

    ``kind`` and ``setpoint_c`` are the current settings, used where a trigger leaves them out.

    Raises
    ------
    BadCommand
        Unknown command, undecodable or malformed payload, value outside the limits.
    """
    if len(payload) > _MAX_PAYLOAD:
        raise BadCommand(f"payload of {len(payload)} bytes is too long")
    try:
        text = payload.decode("utf-8").strip()
    except UnicodeDecodeError:
        raise BadCommand("payload is not UTF-8 text") from None
    if not text:
        raise BadCommand("empty payload: not a command (an empty message only clears a "
                         "retained one)")
    low = text.lower()
    if name in ("abort", "skip_tonight"):
        if low in _PRESS or low == name:
            return Command(name)
        raise BadCommand(f"expected {name!r} or PRESS, got {text!r}")
    if name == "night_kind":
        if low in ("constrained", "normal"):
            return Command(name, kind=low)
        raise BadCommand(f"expected 'constrained' or 'normal', got {text!r}")
    if name == "night_setpoint":
        sp = _number(text)
        if not limits.setpoint_min_c <= sp <= limits.setpoint_max_c:
            raise BadCommand(f"setpoint {sp:g} °C outside the safety limits "
                             f"[{limits.setpoint_min_c:g}, {limits.setpoint_max_c:g}] °C")
        return Command(name, setpoint_c=sp)
    if name == "trigger":
        when = "tonight"
        if low in ("tonight", "now"):
            when = low
        elif low not in _PRESS:
            try:
                data = json.loads(text)
            except ValueError:
                raise BadCommand(f"expected tonight, now or a JSON object, got {text!r}") \
                    from None
            if not isinstance(data, dict):
                raise BadCommand(f"expected a JSON object, got {text!r}")
            unknown = set(data) - {"kind", "setpoint_c", "when"}
            if unknown:
                raise BadCommand(f"unknown field(s) {', '.join(sorted(unknown))}")
            kind = data.get("kind", kind)
            if kind not in ("constrained", "normal"):
                raise BadCommand(f"kind must be 'constrained' or 'normal', got {kind!r}")
            if "setpoint_c" in data:
                setpoint_c = _number(data["setpoint_c"])
            when = data.get("when", when)
            if when not in ("tonight", "now"):
                raise BadCommand(f"when must be 'tonight' or 'now', got {when!r}")
        problem = setpoint_problem(kind, setpoint_c, limits)
        if problem:
            raise BadCommand(problem)
        return Command(name, kind=kind, setpoint_c=setpoint_c, when=when)
    raise BadCommand(f"unknown command {name!r}")
