"""Checks of command-line options: physical bounds, time zones — one line and exit status 2.

Each check raises :class:`impctl.errors.InputError` naming the option (``place``); the CLI's
:func:`impctl.cli.run_group` prints it as one line. Kept free of numpy, pandas and torch.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import click

from ..errors import InputError

# the size guard of every command that reads nights (and of each household of a fleet)
from ..imp.files.limits import MAX_FILE_MB, file_mb, refuse_large_file  # noqa: F401
from ..numtext import non_ascii_problem

#: Setpoints a room can be heated to [°C]: a room thermostat's span, as the NIGHTS.csv and
#: DRIVERS.csv ``setpoint`` column (impctl.imp.files.values.PLAUSIBLE).
SETPOINT_C = (5.0, 35.0)
#: Outdoor temperatures an analysis accepts [°C] (any winter night anywhere people heat).
T_OUT_C = (-50.0, 40.0)
#: The coast's T_air drop of ``impctl flex`` [K]: more than 10 K below the setpoint is no
#: longer a home.
FLEX_DROP_K = (0.0, 10.0)
#: Initial mass temperature of a simulation [°C]: anything a building's structure can hold.
T_M_INIT_C = (-40.0, 60.0)
#: Length of the built-in weather of ``impctl simulate`` [days] (10 years at most).
SIM_DAYS = (0.1, 3660.0)
#: Time step of ``impctl simulate`` [s]: 1 s … 1 day.
SIM_STEP_S = (1.0, 86400.0)


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e12 else f"{x:g}"


def in_range(value: float | None, bounds: tuple[float, float], place: str, unit: str = "",
             *, low_open: bool = False) -> float | None:
    """``value`` if it is ``None`` or a finite number inside ``bounds``; else InputError.

    ``low_open`` excludes the lower bound itself (e.g. a positive length).
    """
    if value is None:
        return None
    lo, hi = bounds
    unit = f" {unit}" if unit else ""
    if not math.isfinite(value):
        raise InputError(f"must be a finite number, got {value!r}", place=place)
    low_ok = value > lo if low_open else value >= lo
    if not (low_ok and value <= hi):
        sign = "(" if low_open else "["
        raise InputError(f"{_num(value)}{unit} is outside the plausible range "
                         f"{sign}{_num(lo)}, {_num(hi)}]{unit}", place=place)
    return value


def option_name(param: click.Parameter | None) -> str | None:
    """The name an error line gives a parameter: its longest option string (``--max-nights``)."""
    if param is None:
        return None
    return max(param.opts, key=len) if param.opts else param.name


_ASCII_TYPES: dict[type, type] = {}


def _ascii_type(kind: type) -> type:
    """``kind`` (a click number type: FLOAT, INT, their ranges) refusing text outside ASCII
    first: click's number types call ``float()`` / ``int()``, which take '٢٢' and '２２' as 22.
    A subclass, so that help texts still show ranges as click shows them."""
    if kind not in _ASCII_TYPES:
        def convert(self: Any, value: Any, param: click.Parameter | None,
                    ctx: click.Context | None) -> Any:
            if isinstance(value, str) and (problem := non_ascii_problem(value)) is not None:
                raise InputError(problem, place=option_name(param))
            return super(_ASCII_TYPES[kind], self).convert(value, param, ctx)

        _ASCII_TYPES[kind] = type(f"Ascii{kind.__name__}", (kind,), {"convert": convert})
    return _ASCII_TYPES[kind]


def ascii_numbers(command: click.Command) -> None:
    """Make every number option and argument of ``command`` and its subcommands take ASCII
    text only (one line naming the option and the character, exit status 2)."""
    import copy

    for param in command.params:
        kind = type(param.type)
        if isinstance(param.type, (click.types.FloatParamType, click.types.IntParamType)) and (
                kind not in _ASCII_TYPES.values()):
            typed = copy.copy(param.type)
            typed.__class__ = _ascii_type(kind)
            param.type = typed
    for sub in getattr(command, "commands", {}).values():
        ascii_numbers(sub)


def bounded(bounds: tuple[float, float], unit: str = "", *, low_open: bool = False
            ) -> Callable[[click.Context, click.Parameter, Any], Any]:
    """A click ``callback`` that checks a float option with :func:`in_range`."""
    def callback(ctx: click.Context, param: click.Parameter, value: Any) -> Any:
        return in_range(value, bounds, option_name(param), unit, low_open=low_open)
    return callback


def house_limit(key: str) -> Callable[[click.Context, click.Parameter, Any], Any]:
    """A click ``callback``: the option must lie in the house file's limits for ``key``
    (:data:`impctl.model.house_limits.HOUSE_LIMITS`, imported only when the option is parsed,
    so the CLI starts without numpy)."""
    def callback(ctx: click.Context, param: click.Parameter, value: Any) -> Any:
        from ..model.house_limits import limit_problem

        why = None if value is None else limit_problem(key, float(value))
        if why is not None:
            raise InputError(why, place=max(param.opts, key=len))
        return value
    return callback


def time_zone(ctx: click.Context | None, param: click.Parameter | None, value: str) -> str:
    """A click ``callback`` (or a plain check): ``value`` must be an IANA time-zone name."""
    from zoneinfo import ZoneInfo

    try:
        ZoneInfo(value)
    except (KeyError, ValueError, OSError, TypeError):  # ZoneInfoNotFoundError is a KeyError
        raise InputError(f"unknown time zone {value!r} (an IANA name such as "
                         "Europe/Ljubljana or UTC)", place="--tz") from None
    return value


def instrument_options(command: Callable) -> Callable:
    """``--t-air-offset-sd-k``, ``--t-out-offset-sd-k`` and ``--meter-error`` of ``impctl fit``
    and ``impctl fleet fit``: what the installer knows of the instruments
    (:mod:`impctl.fit.checks.instruments`; not given: assumed, and said so)."""
    from ..fit.checks.instruments import (
        ASSUMED_METER_ERROR,
        ASSUMED_SENSOR_OFFSETS_K,
        METER_ERROR_LIMITS,
        SENSOR_OFFSET_LIMITS_K,
    )

    lo, hi = SENSOR_OFFSET_LIMITS_K
    for name, which, assumed in (("--t-out-offset-sd-k", "outdoor", ASSUMED_SENSOR_OFFSETS_K[1]),
                                 ("--t-air-offset-sd-k", "indoor", ASSUMED_SENSOR_OFFSETS_K[0])):
        command = click.option(
            name, default=None, type=float, callback=bounded(SENSOR_OFFSET_LIMITS_K, "K"),
            help=f"SD of the {which} temperature sensor's offset [K], declared (a calibrated "
                 f"sensor: its calibration uncertainty). Not given: assumed {assumed:g} K. It "
                 f"enters the intervals as offset/ΔT; {lo:g}–{hi:g}.")(command)
    m_lo, m_hi = METER_ERROR_LIMITS
    return click.option(
        "--meter-error", default=None, type=float, callback=bounded(METER_ERROR_LIMITS),
        help="The heat meter's maximum systematic error, a fraction (0.02: class 2; 0.05: "
             "class 3; about 0.01 for the electric power of resistive heaters), declared. Not "
             f"given: assumed {ASSUMED_METER_ERROR:g}. It scales HLC and C_m one to one; "
             f"{m_lo:g}–{m_hi:g}.")(command)


def emitter_option(command: Callable) -> Callable:
    """``--emitter`` of ``impctl fit`` and ``impctl season``: the emitter as the installer
    declares it (known), the season model's bound on its lag."""
    from ..imp.protocol import EMITTER_KINDS

    return click.option(
        "--emitter", type=click.Choice(EMITTER_KINDS), default=None,
        help="The heating's emitter, declared: radiators (the season model's emitter lag up to "
             "1.5 h) or underfloor (up to 5 h; a house with both: underfloor). Not given: the "
             "file's emitter column, else read from the heating water (t_flow_c, t_return_c), "
             "else assumed (up to 3 h), said so.")(command)


def agreed_emitter(option: str | None, nights: list, path) -> str | None:
    """The declared emitter: ``--emitter``, else the file's ``emitter`` column; InputError
    (one line) when both are given and differ — two declarations, and which is right is not
    known."""
    from ..imp.night import declared_emitter

    in_file = declared_emitter(nights)
    if option is not None and in_file is not None and option != in_file:
        raise InputError(f"--emitter {option}, but the file's emitter column says {in_file}: "
                         "give one", path)
    return option if option is not None else in_file
