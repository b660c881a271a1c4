"""Why a NIGHTS.csv could not be read, in the words of its likely cause.

A spreadsheet set to a European locale writes ``;`` between fields and ``,`` as the decimal
mark; pandas then sees one column (``missing column 'timestamp'``) or shifted columns
(``cannot parse timestamp '3'``). A logger that wrote a night twice, or files pasted together,
give repeated or unsorted timestamps. Home Assistant's history export is the long format (one
row per entity and change: ``entity_id,state,last_changed``), not a NIGHTS table. These
functions look at the raw text (or the parsed
timestamps) once a read has failed and name the cause and the fix; they never change what is
accepted.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pandas as pd

#: Bytes of the file looked at: the header and the first few hundred rows.
_SAMPLE_BYTES = 65536
_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+$")
_DECIMAL_COMMA_IN_TEXT = re.compile(r"[+-]?\d+,\d+")
_SEPARATORS = {",": "','", ";": "';'", "\t": "tab"}


def _cells(line: str, sep: str) -> list[str]:
    return [c.strip() for c in next(csv.reader([line], delimiter=sep), [])]


#: Columns of Home Assistant's history export (the UI's "download data", the recorder's
#: ``states`` table): one row per entity and state change.
HA_HISTORY_COLUMNS = ("entity_id", "state")
HA_HISTORY_TIMES = ("last_changed", "last_updated")
#: Entities named in the message at most.
_HA_ENTITIES_SHOWN = 6


def _ha_history(header: str, rows: list[tuple[int, str]],
                required: tuple[str, ...]) -> tuple[str, str] | None:
    cells = _cells(header, ",")
    if not (set(HA_HISTORY_COLUMNS) <= set(cells) and set(HA_HISTORY_TIMES) & set(cells)):
        return None
    column = cells.index("entity_id")
    entities: list[str] = []
    for _, line in rows:
        row = _cells(line, ",")
        if len(row) > column and row[column] and row[column] not in entities:
            entities.append(row[column])
    shown = ", ".join(entities[:_HA_ENTITIES_SHOWN]) + (
        ", …" if len(entities) > _HA_ENTITIES_SHOWN else "")
    return (f"a Home Assistant history export (one row per entity and change: "
            f"{','.join(cells)}; entities {shown or 'none'}): NIGHTS needs one row per time "
            f"with the columns {','.join(required)} — pivot it first, naming which entity is "
            "which column (docs: NIGHTS files, 'From Home Assistant's history')", "row 1")


def layout_problem(path: str | Path, required: tuple[str, ...]) -> tuple[str, str] | None:
    """(problem, place) when the file's layout explains a failed read: Home Assistant's long
    history format, another separator than ``,``, or decimal commas; None when the layout
    looks right (the reader's own message stands then)."""
    try:
        with Path(path).open("rb") as fh:
            raw = fh.read(_SAMPLE_BYTES)
    except OSError:
        return None
    lines = raw.decode("utf-8-sig", errors="replace").splitlines()
    if len(raw) == _SAMPLE_BYTES:
        lines = lines[:-1]  # possibly cut in the middle
    numbered = [(i + 1, x) for i, x in enumerate(lines) if x.strip()]
    if not numbered:
        return None
    header = numbered[0][1]
    rows = numbered[1:]
    history = _ha_history(header, rows, required)
    if history is not None:
        return history

    def hits(sep: str) -> int:
        return sum(c in required for c in _cells(header, sep))

    sep = max(_SEPARATORS, key=hits)
    if hits(sep) == 0:
        return None
    comma_cell = None
    if sep != ",":
        for number, line in rows:
            cell = next((c for c in _cells(line, sep) if _DECIMAL_COMMA.match(c)), None)
            if cell is not None:
                comma_cell = (number, cell)
                break
        name = _SEPARATORS[sep]
        if comma_cell is not None:
            return (f"separator {name} and decimal commas detected (header {header[:60]!r}; "
                    f"e.g. {comma_cell[1]!r} in row {comma_cell[0]}): NIGHTS.csv needs ',' "
                    "between fields and '.' as the decimal mark (export the sheet as CSV "
                    "with those settings)", "row 1")
        return (f"separator {name} detected (header {header[:60]!r}): NIGHTS.csv needs ',' "
                "between fields (export the sheet as CSV with ',' as the field separator)",
                "row 1")
    n_header = len(_cells(header, ","))
    for number, line in rows:
        cells = _cells(line, ",")
        quoted = next((c for c in cells if _DECIMAL_COMMA.match(c)), None)
        if quoted is not None:
            return (f"decimal comma detected ({quoted!r}): write numbers with '.' as the "
                    "decimal mark", f"row {number}")
        example = _DECIMAL_COMMA_IN_TEXT.search(line.split(",", 1)[-1])
        if len(cells) > n_header and example:
            return (f"{len(cells)} cells where the header has {n_header}: decimal commas "
                    f"detected, e.g. {example.group(0)!r}; write numbers with '.' as the "
                    "decimal mark", f"row {number}")
    return None


def order_problem(stamps: pd.Series, back: np.ndarray, text=None) -> tuple[str, int]:
    """What is wrong with timestamps that do not strictly increase (``back`` marks each row
    that does not come after the one before it): duplicates, or rows out of time order; and
    the index of the row the text speaks of. ``text``: the timestamp cells as the file writes
    them, indexed by row (an array, or :class:`~.tables.CellText`), which the line quotes (else
    the parsed instants)."""
    def quoted(i: int) -> str:
        return str(text[i]) if text is not None else stamps.iloc[i].isoformat()

    step = stamps.diff().dt.total_seconds().to_numpy()
    same = back & (step == 0)
    earlier = back & (step < 0)
    if not earlier.any():
        first = int(np.argmax(same))
        return (f"timestamps must strictly increase: {int(same.sum())} duplicated "
                f"timestamp{'s' if same.sum() > 1 else ''} (the first, "
                f"{quoted(first)}, repeats the row before): remove the "
                "repeated rows", first)
    first = int(np.argmax(earlier))
    dup = f", and {int(same.sum())} duplicated" if same.any() else ""
    return (f"timestamps must strictly increase: the rows are not in time order "
            f"({int(earlier.sum())} step{'s' if earlier.sum() > 1 else ''} back in time{dup}; "
            f"the first, {quoted(first)}, comes after {quoted(first - 1)}): sort the rows by "
            "timestamp"
            + (" and remove the repeated rows" if same.any() else ""), first)
