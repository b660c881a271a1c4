"""The optional ``[plant.<section>]`` tables of a house TOML → :class:`PlantParams`.

Example (every key optional; sections and keys as :mod:`impctl.plant.params`)::

    [plant.emitter]
    kind = "underfloor"        # or "radiators"
    design_water_c = 33.0

    [plant.heat_pump]
    control = "thermostat"     # "curve", "thermostat" or "ideal"
    min_modulation = 1.0       # an on/off unit

A bad section, key, type or value is one :class:`~impctl.errors.InputError` naming the file and
``plant.<section>.<key>``.
"""

from __future__ import annotations

import math
from dataclasses import fields
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..model import HouseParameters, house_from_mapping, read_toml
from .params import (
    CONTROL_CURVE,
    CONTROL_IDEAL,
    CONTROL_THERMOSTAT,
    RADIATORS,
    SECTIONS,
    UNDERFLOOR,
    PlantParams,
)

#: Words accepted for the coded fields.
_WORDS = {
    ("emitter", "kind"): {"radiators": RADIATORS, "underfloor": UNDERFLOOR},
    ("heat_pump", "control"): {"curve": CONTROL_CURVE, "thermostat": CONTROL_THERMOSTAT,
                               "ideal": CONTROL_IDEAL},
}


def plant_params_from_mapping(data: dict[str, Any] | None,
                              source: str | Path | None = None) -> PlantParams:
    """Build :class:`PlantParams` from the ``plant`` table of a house file (None → defaults).

    Underfloor emitters get the underfloor defaults (n 1.1, 33 °C) unless the file sets them.

    Raises
    ------
    InputError
        Naming ``source`` and ``plant.<section>.<key>``.
    """
    if data is None:
        return PlantParams()
    if not isinstance(data, dict):
        raise InputError("must be a table of sections", source, "key 'plant'")
    sections: dict[str, Any] = {}
    for name, table in data.items():
        if name not in SECTIONS:
            raise InputError(f"unknown section (expected: {', '.join(SECTIONS)})", source,
                             f"key 'plant.{name}'")
        if not isinstance(table, dict):
            raise InputError("must be a table", source, f"key 'plant.{name}'")
        cls = SECTIONS[name]
        names = [f.name for f in fields(cls)]
        values: dict[str, float] = {}
        for key, value in table.items():
            place = f"key 'plant.{name}.{key}'"
            if key not in names:
                raise InputError(f"unknown key (expected: {', '.join(names)})", source, place)
            words = _WORDS.get((name, key))
            if words and isinstance(value, str):
                if value not in words:
                    raise InputError(f"must be one of {', '.join(words)}", source, place)
                value = words[value]
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(f"must be a number, got {type(value).__name__} {value!r}",
                                 source, place)
            if not math.isfinite(value):
                raise InputError("must be a finite number", source, place)
            values[key] = float(value)
        if name == "emitter" and values.get("kind") == UNDERFLOOR:
            values = {"exponent": 1.1, "design_water_c": 33.0, **values}
        try:
            sections[name] = cls(**values)
        except InputError as exc:
            raise exc.at(source) from None
    return PlantParams(**sections)


def load_plant(path: str | Path) -> tuple[HouseParameters, PlantParams]:
    """Read a house TOML: its 5R1C parameters and its ``[plant.*]`` realism options."""
    path = Path(path)
    data = read_toml(path)
    return house_from_mapping(data, path), plant_params_from_mapping(data.get("plant"), path)
