"""Strict CSV tables: timestamps and numbers checked row by row, one clear error line.

Row numbers in errors are file line numbers (the header is row 1).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputError
from ..numtext import non_ascii_problem

#: A UTC offset at the end of a timestamp with a time of day: Z, ±hh:mm, ±hhmm or ±hh (ISO 8601
#: allows the hours alone); a date alone ends in "-dd", which is no offset.
_OFFSET = re.compile(r"[T ]\d.*(?:Z|[+-]\d\d(?::?\d\d)?)$")
#: Key of ``DataFrame.attrs`` holding the timestamp cells as the source wrote them (strings,
#: indexed by row: an array, or :class:`CellText` for a frame read from Parquet).
TIMESTAMP_TEXT = "timestamp_text"


class CellText:
    """A column's cells as text, each formatted when a message quotes it: formatting a season's
    datetimes for the one or two a message quotes took 40 ms per household of a Parquet input."""

    def __init__(self, values: pd.Series):
        self._values = values

    def __getitem__(self, i: int) -> str:
        return str(self._values.iloc[int(i)]).strip()

    def __len__(self) -> int:
        return len(self._values)


def _first_bad(mask: np.ndarray) -> int:
    return int(np.argmax(mask)) + 2


def parse_timestamps(raw: pd.Series, path: str | Path, tz: str, column: str = "timestamp"):
    """Parse ISO 8601 strings into a tz-aware DatetimeIndex in ``tz``.

    Strings with a UTC offset keep their instant; naive strings are local time in ``tz``.
    """
    text = raw.astype(str).str.strip()
    empty = (raw.isna() | (text == "")).to_numpy()
    if empty.any():
        raise InputError(f"empty {column}", path, f"row {_first_bad(empty)}")
    parsed = pd.to_datetime(text, format="ISO8601", utc=True, errors="coerce")
    bad = parsed.isna().to_numpy()
    if bad.any():
        row = _first_bad(bad)
        cell = text.iloc[row - 2]
        raise InputError(f"cannot parse {column} {cell!r} as ISO 8601"
                         + (f": {why}" if (why := non_ascii_problem(cell)) else ""),
                         path, f"row {row}")
    has_offset = text.str.contains(_OFFSET).to_numpy()
    if has_offset.all():
        return pd.DatetimeIndex(parsed).tz_convert(tz)
    if has_offset.any():
        row = _first_bad(~has_offset)
        raise InputError(f"{column} mixes UTC offsets and local times", path, f"row {row}")
    try:
        naive = pd.DatetimeIndex(pd.to_datetime(text, format="ISO8601"))
        local = naive.tz_localize(tz, ambiguous="NaT", nonexistent="NaT")
    except (TypeError, ValueError) as exc:  # an offset the pattern above does not know
        raise InputError(f"cannot read {column} as local times ({exc}): write each with its "
                         "UTC offset as +hh:mm, or none of them", path) from None
    bad = local.isna()
    if bad.any():
        row = _first_bad(bad)
        stamp = naive[row - 2]
        one = naive[row - 2:row - 1]
        first = one.tz_localize(tz, ambiguous=np.array([True]), nonexistent="NaT")[0]
        if pd.isna(first):
            what = "does not exist (clocks skip it at the spring DST change)"
            how = "write timestamps with their UTC offset"
        else:
            second = one.tz_localize(tz, ambiguous=np.array([False]))[0]
            what = "occurs twice (clocks go back at the autumn DST change)"
            how = (f"write timestamps with their UTC offset ({first.isoformat()} the first "
                   f"time, {second.isoformat()} the second)")
        raise InputError(
            f"local {column} {stamp:%Y-%m-%d %H:%M} {what} in {tz}, so the time is not known: "
            f"{how}, or give --tz UTC if the logger's clock runs on UTC", path, f"row {row}")
    return local


def read_table(
    path: str | Path,
    *,
    required: Iterable[str],
    numeric: Iterable[str] = (),
    optional: Iterable[str] = (),
    may_be_empty: Iterable[str] = (),
    tz: str = "UTC",
) -> pd.DataFrame:
    """Read a CSV with a ``timestamp`` column and numeric columns, rejecting bad cells.

    Parameters
    ----------
    path : the CSV file
    required : columns that must be in the header
    numeric : columns (required or optional) that hold numbers
    optional : further columns that may appear; anything else is ignored
    may_be_empty : numeric columns whose empty cells mean "none" (kept as NaN)
    tz : time zone for naive timestamps

    Returns
    -------
    DataFrame with a tz-aware ``timestamp`` column and float numeric columns.

    Raises
    ------
    InputError
        Missing file, empty file, missing column, bad timestamp, text/NaN in a number column.
    """
    path = Path(path)
    required = tuple(required)
    numeric = tuple(numeric)
    may_be_empty = set(may_be_empty)
    try:
        df = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except pd.errors.EmptyDataError:
        raise InputError("file is empty", path) from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise InputError(f"not a readable CSV: {str(exc).splitlines()[0]}", path) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path) from None
    _refuse_ragged_rows(path, len(df.columns))
    df.columns = [str(c).strip() for c in df.columns]
    for col in required:
        if col not in df.columns:
            raise InputError(f"missing column '{col}' (header: {','.join(df.columns)})", path,
                             "row 1")
    if df.empty:
        raise InputError("no data rows", path)
    out = pd.DataFrame(index=range(len(df)))
    out["timestamp"] = parse_timestamps(df["timestamp"], path, tz)
    # as the file writes them, for messages that quote a row (TIMESTAMP_TEXT)
    out.attrs[TIMESTAMP_TEXT] = df["timestamp"].str.strip().to_numpy()
    for col in numeric:
        if col not in df.columns:
            continue
        text = df[col].str.strip()
        empty = (text == "").to_numpy()
        values = text_floats(text)
        bad = (np.isnan(values) & ~empty) | np.isinf(values)
        if col not in may_be_empty:
            bad |= empty
        if bad.any():
            row = _first_bad(bad)
            cell = text.iloc[row - 2]
            what = "empty cell" if cell == "" else (
                non_ascii_problem(cell) or f"{cell!r} is not a finite number")
            raise InputError(f"column '{col}': {what}", path, f"row {row}")
        out[col] = values
    for col in optional:
        if col in df.columns and col not in out.columns:
            out[col] = df[col].str.strip()
    return out


def text_floats(text: pd.Series) -> np.ndarray:
    """Cells of stripped text as float64, NaN where empty or not a number (what
    ``pd.to_numeric(..., errors="coerce")`` gives). pyarrow's cast reads a subset of what
    ``to_numeric`` reads (decimal numbers, not ``1_000``, ``0x10`` or text with spaces) ten
    times faster — a season's file of 12,000 rows spent a third of its read in ``to_numeric``;
    where it refuses a cell, ``to_numeric`` reads the column as before."""
    import pyarrow as pa
    import pyarrow.compute as pc

    cells = pa.array(text)   # pandas' own arrow strings: no copy
    try:
        cast = pc.cast(pc.if_else(pc.equal(cells, ""), pa.scalar(None, cells.type), cells),
                       pa.float64())
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
        return pd.to_numeric(text.where(text != "", None), errors="coerce").to_numpy(
            dtype=float, na_value=np.nan)
    return cast.to_numpy(zero_copy_only=False)


def frame_table(
    frame: pd.DataFrame,
    source: str | Path,
    *,
    required: Iterable[str],
    numeric: Iterable[str] = (),
    optional: Iterable[str] = (),
    may_be_empty: Iterable[str] = (),
    lenient: Iterable[str] = (),
    tz: str = "UTC",
) -> pd.DataFrame:
    """:func:`read_table`'s checks for a DataFrame already read (Parquet): the same output.

    ``timestamp`` may hold datetimes (naive ones are local time in ``tz``) or ISO 8601 strings.
    Row numbers in errors count as in the CSV form (first data row = row 2). ``lenient``:
    optional columns whose cells become numbers or missing later, never a refusal — stored as
    numbers they stay numbers (float, a null NaN), else text like the other optional columns.
    """
    cols = [str(c) for c in frame.columns]
    for col in required:
        if col not in cols:
            raise InputError(f"missing column '{col}' (columns: {','.join(cols)})", source)
    if frame.empty:
        raise InputError("no data rows", source)
    # the columns gathered first and made a frame once (one column at a time: a copy each)
    out: dict = {}
    stamps = frame["timestamp"].reset_index(drop=True)
    if pd.api.types.is_datetime64_any_dtype(stamps):
        idx = pd.DatetimeIndex(stamps)
        if idx.isna().any():
            raise InputError("empty timestamp", source, f"row {_first_bad(idx.isna())}")
        out["timestamp"] = (idx.tz_convert(tz) if idx.tz is not None else
                            parse_timestamps(pd.Series(idx.strftime("%Y-%m-%dT%H:%M:%S.%f")),
                                             source, tz))
    else:
        out["timestamp"] = parse_timestamps(stamps.astype(object), source, tz)
    may_be_empty = set(may_be_empty)
    for col in numeric:
        if col not in cols:
            continue
        column = frame[col]
        if not _numbers(column):   # numbers stay as they are
            column = pd.to_numeric(column.reset_index(drop=True), errors="coerce")
        values = column.to_numpy(dtype=float, na_value=np.nan)
        bad = ~np.isfinite(values)
        if col in may_be_empty:
            bad &= ~np.isnan(values)
        if bad.any():
            raise InputError(f"column '{col}': missing or not a finite number", source,
                             f"row {_first_bad(bad)}")
        out[col] = values
    lenient = set(lenient)
    for col in optional:
        if col in cols and col not in out:
            column = frame[col]
            if col in lenient and _numbers(column):
                # what their text read back as (the text of each as a float64, exact); the
                # way through text cost a season's household 2 ms of its 13 ms read
                out[col] = column.to_numpy(dtype=float, na_value=np.nan)
                continue
            out[col] = pd.Series(_text_cells(column), dtype=object, copy=False)
    table = pd.DataFrame(out, index=range(len(frame)))
    table.attrs[TIMESTAMP_TEXT] = CellText(stamps)
    return table


def _numbers(column: pd.Series) -> bool:
    """Whether a column is stored as numbers (not booleans, whose text is True/False)."""
    return pd.api.types.is_numeric_dtype(column) and not pd.api.types.is_bool_dtype(column)


def _text_cells(column: pd.Series) -> np.ndarray:
    """A column's cells as stripped text (object array), a null cell the CSV's empty one.

    pandas reads Parquet strings as a string type whose nulls stay NaN through ``astype(str)``
    ("nan" ≠ "nan" would split nights). Each distinct value is converted once: a season's
    file holds ~12,000 rows of a few dozen night ids, three kinds and three labels, and
    converting cell by cell (back to pandas' string type and out again) was a third of reading
    a household of a fleet."""
    if column.dtype == object:  # e.g. 5 and 5.0 in one column: one value to factorize
        text = column.reset_index(drop=True)
        return text.where(text.notna(), "").astype(str).str.strip().to_numpy(dtype=object)
    codes, uniques = pd.factorize(column, use_na_sentinel=True)
    # the sentinel −1 takes the last entry: the empty cell
    text = np.empty(len(uniques) + 1, dtype=object)
    text[:-1] = [str(u).strip() for u in uniques]
    text[-1] = ""
    return text[codes]


def _refuse_ragged_rows(path: Path, n_columns: int) -> None:
    """A row with fewer cells than the header (pandas would fill them in as empty — e.g. a
    last line cut off when the logger lost power) is refused; too many cells pandas refuses
    itself."""
    import csv

    data = path.read_bytes()
    if b'"' not in data and b"\r" not in data:
        # no quoted cell and no \r: a row is a line and its cells are its commas + 1 (what
        # the csv module reads, a fifth of the time: it cost a season's file 20 ms)
        for number, line in enumerate(data.split(b"\n"), start=1):
            cells = line.count(b",") + 1
            if line and cells < n_columns:
                raise InputError(f"{cells} cells where the header has {n_columns}", path,
                                 f"row {number}")
        return
    with path.open(newline="", encoding="utf-8", errors="replace") as fh:
        for number, row in enumerate(csv.reader(fh), start=1):
            if row and len(row) < n_columns:
                raise InputError(f"{len(row)} cells where the header has {n_columns}", path,
                                 f"row {number}")


def step_seconds(timestamps: pd.DatetimeIndex | pd.Series, path: str | Path) -> float | None:
    """The constant spacing of ``timestamps`` [s]; ``None`` for a single row.

    Raises
    ------
    InputError
        Non-increasing or unequal spacing, naming the first offending row.
    """
    ts = pd.DatetimeIndex(timestamps)
    if len(ts) < 2:
        return None
    deltas = (ts[1:] - ts[:-1]).total_seconds().to_numpy()
    if deltas[0] <= 0:
        raise InputError("timestamps must increase", path, "row 3")
    bad = deltas != deltas[0]
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(
            f"unequal steps: {deltas[i]:g} s here, {deltas[0]:g} s before", path, f"row {i + 3}"
        )
    return float(deltas[0])
