"""The value checks of a NIGHTS table: every cell in its plausible range (:data:`PLAUSIBLE`;
a file in °F is told as such), ``heating`` 1 or 0, ``kind`` one of :data:`KINDS`, the
per-row series (:mod:`.series`), no empty ``night`` cell and the timestamps increasing (within
each night when ``night`` is given). :func:`check_values` refuses the first problem in one line
naming the file and the row (:func:`_row`: counted as file lines); :mod:`.nights_csv` runs it
on every table before it cuts the nights.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import InputError
from ..plan import NIGHT_KINDS
from ..plausibility import fahrenheit_problem, to_celsius
from .series import check_series, out_of_range, range_text

#: Plausible value ranges; outside them the file is refused (wrong units or a sensor fault).
PLAUSIBLE = {
    "t_air": (-40.0, 60.0, "°C"),
    "t_out": (-60.0, 60.0, "°C"),
    # A signed heat reading goes negative while a defrost draws heat from the water (up to the
    # unit's output; real-houses.md §3); the fit compares it with its recovery.
    "q_hc": (-25_000.0, 100_000.0, "W"),
    "setpoint": (5.0, 35.0, "°C"),
}
#: The kinds a ``kind`` cell may name: the IMP nights' and the owner's recorded nights.
KINDS = (*NIGHT_KINDS, "owner")


def _row(index: int) -> str:
    return f"row {index + 2}"


def check_values(table: pd.DataFrame, path: Path, stamp_text, stamp_ns: np.ndarray) -> None:
    # A file in °F: its rooms are warmer than any room in °C, yet mostly inside t_air's range.
    fahrenheit = fahrenheit_problem(table["t_air"].to_numpy(dtype=float))
    if fahrenheit is not None:
        raise InputError(fahrenheit, path, "column 't_air'")
    found = out_of_range(table, PLAUSIBLE)
    if found is not None:
        col, i, value = found
        lo, hi, unit = PLAUSIBLE[col]
        text = range_text(col, value, PLAUSIBLE)
        if unit == "°C" and value > hi and lo <= to_celsius(value) <= hi:
            text += (f" — looks like °F ({to_celsius(value):.1f} °C): convert with "
                     "(°F − 32) / 1.8")
        raise InputError(text, path, _row(i))
    if "heating" in table:
        heating = table["heating"].to_numpy(dtype=float)
        bad = (heating != 0) & (heating != 1)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(f"column 'heating': {heating[i]:g} is not 1 or 0", path, _row(i))
    if "kind" in table:
        kinds = table["kind"]
        bad = ~kinds.isin(KINDS).to_numpy()
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(f"column 'kind': {kinds.iloc[i]!r} is not 'constrained', 'normal' "
                             "or 'owner'", path, _row(i))
    check_series(table, path, _row)
    if "night" in table:
        empty = (table["night"] == "").to_numpy()
        if empty.any():
            raise InputError("column 'night': empty cell", path, _row(int(np.argmax(empty))))
    back = np.r_[False, stamp_ns[1:] <= stamp_ns[:-1]]
    if "night" in table:  # labelled nights may overlap (e.g. simulated); each must increase
        ids = table["night"].to_numpy(dtype=object)
        back[1:] &= ids[1:] == ids[:-1]
    if back.any():
        from .hints import order_problem  # only on the failure path

        text, i = order_problem(table["timestamp"], back, stamp_text)
        raise InputError(text, path, _row(i))
