"""Plausible bounds of every house-file parameter, and the check that lists every problem.

The bounds are wide limits for a dwelling (a flat … a large villa, passive house … solid
stone), well outside anything the population, the fit's search box or the demo use; a value
outside them is a typo or a wrong unit (mm for m, W/K for W/(m²K), % for 0–1), not a house.
Units as in :data:`PARAMETER_UNITS`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..errors import InputError

#: key → (lowest, highest) accepted value; the lower bound of keys in :data:`OPEN_LOW` is
#: excluded (a length or a U-value of exactly 0 is no house).
HOUSE_LIMITS: dict[str, tuple[float, float]] = {
    "floor_area": (10.0, 5000.0),          # m²
    "wall_height": (1.8, 10.0),            # m, storey height
    "walls_area": (1.0, 20000.0),          # m², opaque external walls
    "windows_area": (0.0, 5000.0),         # m²
    "c_f": (0.5, 5.0),                     # 1e5 J/(m²K), ISO 13790 Table 12 and beyond
    "u_walls": (0.05, 5.0),                # W/(m²K)
    "u_windows": (0.3, 7.0),               # W/(m²K), triple glazing … single pane
    "ach_vent": (0.0, 20.0),               # 1/h
    "ach_infl": (0.0, 20.0),               # 1/h
    "heat_recovery": (0.0, 1.0),           # -
    "max_heating_power": (100.0, 1.0e6),   # W (or inf: no cap)
}
OPEN_LOW = frozenset({"windows_area"})


class HouseFileError(InputError):
    """Several house-file problems at once; ``str()`` gives one line per problem."""

    def __init__(self, problems: list[InputError]):
        self.problems = problems
        super().__init__("\n".join(str(p) for p in problems))

    def _line(self) -> str:
        return "\n".join(str(p) for p in self.problems)

    def at(self, source: str | Path | None = None, place: str | None = None) -> InputError:
        return HouseFileError([p.at(source, place) for p in self.problems])


#: Units of every house parameter (as in the house TOML).
PARAMETER_UNITS = {
    "floor_area": "m²", "wall_height": "m", "walls_area": "m²", "windows_area": "m²",
    "c_f": "1e5 J/(m²K)", "u_walls": "W/(m²K)", "u_windows": "W/(m²K)", "ach_vent": "1/h",
    "ach_infl": "1/h", "heat_recovery": "-", "max_heating_power": "W",
}


def limit_problem(key: str, value: float) -> str | None:
    """What is wrong with ``value`` for ``key`` (``None`` if it is inside the limits)."""
    lo, hi = HOUSE_LIMITS[key]
    if key == "max_heating_power" and value == math.inf:
        return None
    low_ok = value > lo if key in OPEN_LOW else value >= lo
    if math.isfinite(value) and low_ok and value <= hi:
        return None
    unit = PARAMETER_UNITS.get(key, "")
    unit = "" if unit in ("", "-") else f" {unit}"
    if not math.isfinite(value):
        return f"must be a finite number, got {value!r}"
    sign = "(" if key in OPEN_LOW else "["
    return f"{value:g} is outside the plausible range {sign}{lo:g}, {hi:g}]{unit}"


def check_house_values(data: Mapping[str, Any], known: tuple[str, ...],
                       optional: Mapping[str, float], source: str | Path | None
                       ) -> dict[str, float]:
    """Every key of a house mapping checked at once: unknown, missing, not a number, outside
    :data:`HOUSE_LIMITS`. Returns the values (optional keys filled in with their defaults).

    Raises
    ------
    HouseFileError
        One line per problem, naming ``source`` and the key.
    """
    problems: list[InputError] = []
    for key in data:
        if key not in known:
            problems.append(InputError(f"unknown key (expected: {', '.join(known)})", source,
                                       f"key '{key}'"))
    values: dict[str, float] = {}
    for key in known:
        if key not in data:
            if key in optional:
                values[key] = optional[key]
            else:
                problems.append(InputError("missing key", source, f"key '{key}'"))
            continue
        value = data[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            problems.append(InputError(f"must be a number, got {type(value).__name__} "
                                       f"{value!r}", source, f"key '{key}'"))
            continue
        why = limit_problem(key, float(value))
        if why is not None:
            problems.append(InputError(why, source, f"key '{key}'"))
            continue
        values[key] = float(value)
    if problems:
        raise HouseFileError(problems)
    return values
