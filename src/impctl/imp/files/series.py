"""The optional NIGHTS.csv columns a night carries per sample for the season model and the heat
pump's curve: the heating water and the hot water, and an owner night's label.

* ``t_flow_c``, ``t_return_c`` — supply and return water [°C] (Kronoterm 2104, 2101);
* ``t_flow_target_c`` — the heat pump's calculated flow target [°C] (2128): the heating
  curve it runs;
* ``dhw`` — share of the row's time charging hot water (0–1; a single reading 0 or 1);
* ``emitter`` — the house's emitter as its installer declares it, ``radiators`` or
  ``underfloor`` (the season model's bound on the emitter's lag: known, before the water's
  reading), the same on every row that has one (empty: not declared);
* ``label`` — why an owner night is not the owner's ordinary night, empty when it is; the
  same on every row of the night. A constrained night carries one label only,
  :data:`~impctl.imp.protocol.SHORT_NIGHT` (it reached T_min too soon for the IMP fit: the
  season model reads it, the IMP fit does not); a normal night none.

Unlike the columns of :mod:`.extras` these are checked: a cell that is not a number or
lies outside its range refuses the file with one line naming the row (an empty cell is
missing). They describe the samples themselves, and a wrong one would be taken as measured.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ...errors import InputError
from ..protocol import EMITTER_KINDS, SHORT_NIGHT

#: Per-sample columns and their ranges: heating water between freezing and boiling.
SERIES_COLUMNS: dict[str, tuple[float, float, str]] = {
    "t_flow_c": (0.0, 100.0, "°C"),
    "t_return_c": (0.0, 100.0, "°C"),
    "t_flow_target_c": (0.0, 100.0, "°C"),
    "dhw": (0.0, 1.0, "(a share of the row's time)"),
}
LABEL = "label"
EMITTER = "emitter"


def out_of_range(table: pd.DataFrame, ranges: dict) -> tuple[str, int, float] | None:
    """The first (column, row index, value) of ``table`` outside its (lo, hi, unit) in
    ``ranges`` (columns the table lacks and missing values pass), else None."""
    for col, (lo, hi, _unit) in ranges.items():
        if col not in table:
            continue
        values = table[col].to_numpy(dtype=float)
        bad = np.isfinite(values) & ((values < lo) | (values > hi))
        if bad.any():
            i = int(np.argmax(bad))
            return col, i, float(values[i])
    return None


def range_text(col: str, value: float, ranges: dict) -> str:
    """The one line that says ``value`` of ``col`` is outside its range in ``ranges``."""
    lo, hi, unit = ranges[col]
    return f"column '{col}': {value:g} is outside {lo:g}…{hi:g} {unit}"


def check_series(table: pd.DataFrame, path, row) -> None:
    """Refuse (:class:`InputError`, one line) a value of :data:`SERIES_COLUMNS` outside its
    range; ``row(i)`` names the row of index ``i``."""
    found = out_of_range(table, SERIES_COLUMNS)
    if found is not None:
        col, i, value = found
        raise InputError(range_text(col, value, SERIES_COLUMNS), path, row(i))


def check_labels(table: pd.DataFrame, groups, kind_of, path, row) -> None:
    """Refuse a ``label`` on a night that is not an owner night (but a constrained night's
    :data:`~impctl.imp.protocol.SHORT_NIGHT`), or one that changes within a night.
    ``groups``: (night id, row indices); ``kind_of(night id, indices)``: its kind."""
    if LABEL not in table:
        return
    labels = table[LABEL].to_numpy(dtype=object)
    for night_id, idx in groups:
        if night_id == "":
            continue
        mine = labels[idx]
        changed = mine != mine[0]
        if changed.any():
            raise InputError(f"night {night_id!r} changes label from {mine[0]!r}", path,
                             row(int(idx[int(np.argmax(changed))])))
        kind = kind_of(night_id, idx) if mine[0] else None
        if mine[0] and kind != "owner" and not (kind == "constrained"
                                                 and mine[0] == SHORT_NIGHT):
            raise InputError(f"column 'label': only owner nights carry a label, and a "
                             f"constrained night {SHORT_NIGHT!r} (night {night_id!r} is "
                             f"{kind or 'of no kind'})", path, row(int(idx[0])))


def series_arrays(table: pd.DataFrame) -> dict:
    """The columns of :data:`SERIES_COLUMNS` the file has, as float arrays (NaN where empty),
    and the ``label`` column as text — once per file, for :func:`series_fields`."""
    out: dict = {col: table[col].to_numpy(dtype=float) for col in SERIES_COLUMNS if col in table}
    if LABEL in table:
        out[LABEL] = table[LABEL].to_numpy(dtype=object)
    return out


def series_fields(arrays: dict, idx: np.ndarray) -> dict:
    """The :class:`~impctl.imp.night.NightSamples` fields of the rows ``idx`` from
    :func:`series_arrays`: each series column's rows and the ``label``."""
    out = {col: a[idx] for col, a in arrays.items() if col != LABEL}
    if LABEL in arrays:
        out[LABEL] = str(arrays[LABEL][int(idx[0])])
    return out


def check_emitter(table: pd.DataFrame, path, row) -> str:
    """The emitter the file declares (``emitter`` column), "" where it declares none; refuse
    (:class:`InputError`, one line) a kind not in :data:`EMITTER_KINDS` or a second kind.
    ``row(i)`` names the row of index ``i``."""
    if EMITTER not in table:
        return ""
    cells = table[EMITTER].to_numpy(dtype=object)
    given = np.flatnonzero(cells != "")
    if not len(given):
        return ""
    first = cells[given[0]]
    if first not in EMITTER_KINDS:
        raise InputError(f"column '{EMITTER}': {first!r} is not one of "
                         f"{', '.join(EMITTER_KINDS)}", path, row(int(given[0])))
    other = given[cells[given] != first]
    if len(other):
        raise InputError(f"column '{EMITTER}': {cells[other[0]]!r} after {first!r} (one house, "
                         "one emitter)", path, row(int(other[0])))
    return str(first)
