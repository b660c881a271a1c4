"""The rows of a NIGHTS file the heating curve is worked out from.

Besides the series every NIGHTS file has (``timestamp``, ``t_air``, ``t_out``, ``q_hc``), the
curve reads the optional columns a gateway records on held and owner nights:

* ``t_flow_c``, ``t_return_c`` — the heating water leaving and coming back [°C] (Kronoterm
  2104 and 2101);
* ``t_flow_target_c`` — the flow temperature the heat pump's own curve asks for [°C]
  (Kronoterm 2128, the loop-1 calculated target);
* ``dhw`` — the share of the row's interval spent heating hot water (0–1);
* ``defrost`` — 1 while the heat pump defrosts; ``p_el_w`` — its electrical power [W];
* ``setpoint`` [°C], ``heating`` (1/0), ``kind`` (``constrained``, ``normal``, ``owner``),
  ``night``, ``label``.

The four series are checked as the fit checks them (a bad cell, an implausible value or °F
refuse the file with one line naming the row); in the optional columns a cell that is empty,
not a number or implausible is missing, never a number.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import InputError
from ...imp.files.limits import refuse_large_file
from ...imp.files.nights_csv import PLAUSIBLE, REQUIRED_COLUMNS
from ...imp.plausibility import fahrenheit_problem, to_celsius
from ...imp.tables import read_table

#: The optional numeric columns and their plausible ranges (outside: missing).
CURVE_COLUMNS: dict[str, tuple[float, float]] = {
    "t_flow_c": (-20.0, 100.0),
    "t_return_c": (-20.0, 100.0),
    "t_flow_target_c": (5.0, 90.0),
    "dhw": (0.0, 1.0),
    "defrost": (0.0, 1.0),
    "p_el_w": (0.0, 30_000.0),
    "setpoint": (5.0, 35.0),
    "heating": (0.0, 1.0),
}
#: Text columns kept as they are.
TEXT_COLUMNS = ("kind", "night", "label", "phase")
#: Night kinds whose rows have the heating on at the owner's or a held setpoint.
HEATED_KINDS = frozenset({"normal", "owner", "held"})


def read_rows(path: str | Path, tz: str) -> pd.DataFrame:
    """The rows of NIGHTS file ``path``: ``timestamp`` (tz-aware, in ``tz``), ``t_air``,
    ``t_out``, ``q_hc`` and every optional column of :data:`CURVE_COLUMNS` (float, NaN where
    missing or absent) and :data:`TEXT_COLUMNS` (str, "" where absent).

    Raises
    ------
    InputError
        One line naming the file, the row and the problem.
    """
    path = Path(path)
    refuse_large_file(path)
    try:
        table = read_table(path, required=REQUIRED_COLUMNS, numeric=("t_air", "t_out", "q_hc"),
                           optional=(*CURVE_COLUMNS, *TEXT_COLUMNS), tz=tz)
    except InputError:
        from ...imp.files.hints import layout_problem

        cause = layout_problem(path, REQUIRED_COLUMNS)  # ';' separators, decimal commas
        if cause is None:
            raise
        raise InputError(cause[0], path, cause[1]) from None
    return rows_from_table(table, path)


def rows_from_table(table: pd.DataFrame, source: str | Path) -> pd.DataFrame:
    """:func:`read_rows` on a table already read (checks and optional columns)."""
    fahrenheit = fahrenheit_problem(table["t_air"].to_numpy(dtype=float))
    if fahrenheit is not None:
        raise InputError(fahrenheit, source, "column 't_air'")
    for col in ("t_air", "t_out", "q_hc"):
        lo, hi, unit = PLAUSIBLE[col]
        values = table[col].to_numpy(dtype=float)
        bad = (values < lo) | (values > hi)
        if bad.any():
            i = int(np.argmax(bad))
            text = f"column '{col}': {values[i]:g} is outside {lo:g}…{hi:g} {unit}"
            if unit == "°C" and values[i] > hi and lo <= to_celsius(values[i]) <= hi:
                text += f" — looks like °F ({to_celsius(values[i]):.1f} °C)"
            raise InputError(text, source, f"row {i + 2}")
    stamps = table["timestamp"]
    back = (stamps.diff().dt.total_seconds() <= 0).to_numpy()
    if "night" in table:  # labelled nights may overlap (simulated ones): each must increase
        back = back & (table["night"] == table["night"].shift()).to_numpy()
    if back.any():
        raise InputError("timestamps must increase: sort the rows by timestamp", source,
                         f"row {int(np.argmax(back)) + 2}")
    out = table[["timestamp", "t_air", "t_out", "q_hc"]].copy()
    # The timestamp texts kept for messages would be deep-copied by every pandas step after.
    out.attrs = {}
    for col, (lo, hi) in CURVE_COLUMNS.items():
        if col in table:
            values = np.array(pd.to_numeric(table[col], errors="coerce"), dtype=float)
            values[~np.isfinite(values) | (values < lo) | (values > hi)] = np.nan
        else:
            values = np.full(len(table), np.nan)
        out[col] = values
    for col in TEXT_COLUMNS:
        out[col] = table[col].astype(str).str.strip() if col in table else ""
    # An IMP night's pre-heat runs the heat pump at impctl's raised setpoint, not the owner's:
    # neither the curve it runs nor the house's need at the owner's setpoint.
    return out[(out["phase"] != "preheat").to_numpy()].reset_index(drop=True)
