"""The fleet's input: which households there are and how each one's nights are read.

``INPUT`` is either

* a folder of NIGHTS files — ``*.csv`` and ``*.parquet``, one household per file, the household
  id is the file stem (the format of ``impctl export``); or
* one Parquet file, or a Parquet dataset folder (e.g. written by Dask or Spark, hive partitions
  allowed), with a ``household`` column next to the NIGHTS columns.

Discovery runs on the client and reads only names (files) or the ``household`` column (dataset);
each worker reads its own households' nights, so no sample crosses the scheduler. Every household
is read and checked as ``impctl fit`` reads its file (:mod:`impctl.fit.household`): one too large
is refused before it is read (a CSV by its size, Parquet rows by the count in the metadata).
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from .results.manifest import MANIFEST_FILE

HOUSEHOLD_COLUMN = "household"
#: The name of a FLEET part file (:func:`.results.table.write_part`).
_PART = re.compile(r"part-[0-9a-f]{8}-\d{6}\.parquet")


@dataclass(frozen=True)
class Source:
    """Where one household's nights are: its own file, or its rows of a shared dataset."""

    household: str
    path: str
    kind: str  # "csv" | "parquet" | "dataset"
    rows: int | None = None  # a dataset household's rows (counted at discovery)


def _open_dataset(path: str | Path):
    """The Parquet dataset at ``path``. Partitioned by household (``household=007/``), the id
    is read as the text it is: pyarrow would read "007" and "01" as the numbers 7 and 1, and
    merge "01" with "1"."""
    import pyarrow as pa
    import pyarrow.dataset as ds

    path = Path(path)
    by_household = path.is_dir() and any(
        p.is_dir() and p.name.startswith(f"{HOUSEHOLD_COLUMN}=") for p in path.iterdir())
    partitioning = (ds.partitioning(pa.schema([(HOUSEHOLD_COLUMN, pa.string())]),
                                    flavor="hive") if by_household else "hive")
    return ds.dataset(path, format="parquet", partitioning=partitioning)


def _is_dataset(path: Path) -> bool:
    if path.is_file():
        return path.suffix == ".parquet"
    if any(path.glob("*.csv")):
        return False
    try:
        return HOUSEHOLD_COLUMN in _open_dataset(path).schema.names
    except (OSError, ValueError):  # pyarrow: not a dataset (or an empty one)
        return False


def discover(path: str | Path) -> list[Source]:
    """The households of ``INPUT`` (see the module docstring), sorted by id.

    Raises
    ------
    InputError
        Missing path, a folder with no NIGHTS file, a dataset without a ``household`` column,
        two files with the same household id.
    """

    path = Path(path)
    if not path.exists():
        raise InputError("no such file or folder", path)
    if path.is_dir():
        _refuse_fleet_output(path)
    if _is_dataset(path):
        try:
            table = _open_dataset(path).to_table(columns=[HOUSEHOLD_COLUMN])
        except (OSError, ValueError) as exc:
            raise InputError(f"not a readable Parquet dataset ({exc})", path) from None
        except KeyError:
            raise InputError(f"no '{HOUSEHOLD_COLUMN}' column", path) from None
        counts = Counter(str(x) for x in table.column(HOUSEHOLD_COLUMN).to_pylist()
                         if x is not None)
        if not counts:
            raise InputError("no household in the dataset", path)
        return [Source(h, str(path), "dataset", counts[h]) for h in sorted(counts)]
    if not path.is_dir():
        raise InputError("neither a folder of NIGHTS files nor a Parquet file/dataset", path)
    files = sorted(p for p in path.iterdir()
                   if p.is_file() and p.suffix in (".csv", ".parquet") and
                   not p.name.startswith((".", "_")))
    if not files:
        raise InputError("no NIGHTS file (*.csv, *.parquet) in this folder", path)
    seen: dict[str, Path] = {}
    for f in files:
        if f.stem in seen:
            raise InputError(f"household '{f.stem}' twice: {seen[f.stem].name} and {f.name}",
                             path)
        seen[f.stem] = f
    return [Source(f.stem, str(f), f.suffix[1:]) for f in files]


#: A dataset's row groups larger than this many batches' rows get a note (:func:`layout_note`).
_ROW_GROUP_BATCHES = 8
#: Fragments (files) whose row groups :func:`layout_note` looks at.
_FRAGMENTS_LOOKED_AT = 20


def layout_note(sources: list[Source], batch_size: int) -> str | None:
    """A line for a dataset INPUT whose Parquet row groups are much larger than a batch's rows,
    else None. A worker reads its batch by a filter on ``household``; Parquet skips a row group
    only as a whole (by its statistics), so each batch decodes every row group that holds one of
    its households — with row groups of a million rows, 10,000 households' batches cost about
    four times the reading of row groups near a batch's size (``bench/fleet.py`` layouts)."""
    import statistics


    rows = [s.rows for s in sources if s.kind == "dataset" and s.rows]
    if not rows:
        return None
    dataset = _open_dataset(next(s.path for s in sources if s.kind == "dataset"))
    groups = []
    for i, fragment in enumerate(dataset.get_fragments()):
        if i == _FRAGMENTS_LOOKED_AT:
            break
        meta = fragment.metadata
        groups += [meta.row_group(j).num_rows for j in range(meta.num_row_groups)]
    if not groups:
        return None
    group = statistics.median(groups)
    batch_rows = batch_size * statistics.median(rows)
    if group <= _ROW_GROUP_BATCHES * batch_rows:
        return None
    return (f"INPUT's Parquet row groups hold about {group:,.0f} rows and a batch of "
            f"{batch_size} households about {batch_rows:,.0f}: every batch decodes whole row "
            "groups for its own rows. Written sorted by household in row groups of about "
            f"{max(batch_rows, 10_000):,.0f} rows, each batch reads little more than its own")


def _refuse_fleet_output(path: Path) -> None:
    """A FLEET dataset (or a run's output written into a folder of nights) is no input: its
    parts are results, and read as households they would be phantom ones."""
    parts = sorted(p.name for p in path.iterdir() if _PART.fullmatch(p.name))
    if parts or (path / MANIFEST_FILE).exists():
        more = f" and {len(parts) - 1} more" if len(parts) > 1 else ""
        raise InputError(f"holds the output of impctl fleet fit ({(parts or [MANIFEST_FILE])[0]}"
                         f"{more}), not households' nights: give the folder of NIGHTS files, "
                         "or move the FLEET files out of it", path)


def read_sources(sources: list[Source], tz: str) -> dict[str, list | InputError]:
    """Each household's nights (``impctl.imp.NightSamples``), or the refusal saying why not
    (an :class:`impctl.fit.household.Refusal`: the line ``impctl fit`` prints, and a reason).

    Households of one dataset are read in one pass, filtered on the ``household`` column;
    those with too many rows are left out of it.
    """
    import pandas as pd

    from ..fit.household import guard_household, read_household

    out: dict[str, list | InputError] = {}
    by_dataset: dict[str, list[Source]] = {}
    for s in sources:
        if s.kind == "dataset":
            by_dataset.setdefault(s.path, []).append(s)
            continue
        try:
            if s.kind == "csv":
                out[s.household] = read_household(s.path, tz)
            else:
                guard_household(s.path, _parquet_rows(s.path))
                out[s.household] = read_household(
                    s.path, tz, read_frame=lambda s=s: _read_parquet(s.path))
        except InputError as exc:
            out[s.household] = exc
        except Exception as exc:  # noqa: BLE001 — one household's file never fails its batch
            out[s.household] = _unreadable(s.path, exc)
    for path, members in by_dataset.items():
        households = []
        for s in members:
            try:
                guard_household(_in_dataset(path, s.household), s.rows)
                households.append(s.household)
            except InputError as exc:
                out[s.household] = exc
        if not households:
            continue
        try:
            frame = _read_parquet(path, households)
        except InputError as exc:
            out.update(dict.fromkeys(households, exc))
            continue
        frame[HOUSEHOLD_COLUMN] = frame[HOUSEHOLD_COLUMN].astype(str)
        groups = dict(tuple(frame.groupby(HOUSEHOLD_COLUMN, sort=False)))
        columns = frame.columns
        del frame
        for h in households:
            part = groups.pop(h, None)
            if part is None:
                part = pd.DataFrame(columns=columns)
            try:
                out[h] = read_household(_in_dataset(path, h), tz, read_frame=lambda p=part: p)
            except InputError as exc:
                out[h] = exc
            except Exception as exc:  # noqa: BLE001 — one household never fails its batch
                out[h] = _unreadable(_in_dataset(path, h), exc)
    return out


def _unreadable(where: str, exc: Exception) -> InputError:
    """An error the NIGHTS reader did not foresee, as one household's refusal naming its
    file."""
    return InputError(f"cannot read this household's nights ({type(exc).__name__}: "
                      f"{str(exc).splitlines()[0] if str(exc) else ''})", where)


def _in_dataset(path: str, household: str) -> str:
    return f"{path} (household {household})"


def _parquet_rows(path: str) -> int | None:
    """Rows of a Parquet file from its footer (nothing else read); None when unreadable (the
    reader then names the problem)."""
    import pyarrow.parquet as pq

    try:
        return pq.ParquetFile(path).metadata.num_rows
    except (OSError, ValueError):
        return None


def _read_parquet(path: str, households: list[str] | None = None):

    try:
        dataset = _open_dataset(path)
        if households is None:
            return dataset.to_table().to_pandas()
        flt = households_filter(households, dataset.schema.field(HOUSEHOLD_COLUMN).type)
        return dataset.to_table(filter=flt).to_pandas()
    except (OSError, ValueError, TypeError) as exc:
        raise InputError(f"not a readable Parquet file ({str(exc).splitlines()[0]})",
                         path) from None


def households_filter(households: list[str], field_type):
    """The dataset filter of a batch's rows: ``household`` among ``households``, and between
    their least and greatest. pyarrow skips a row group by its statistics for the range, but
    not for a membership test of more than a few values: a batch of 64 households read every
    row group of a 10,000-household dataset (0.28–0.40 CPU-s a batch against 0.01)."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.dataset as ds

    col = ds.field(HOUSEHOLD_COLUMN)
    if pa.types.is_dictionary(field_type):   # a pandas categorical: compare its values
        col, field_type = col.cast(field_type.value_type), field_type.value_type
    values = (pa.array(households) if pa.types.is_string(field_type)
              else pa.array(households).cast(field_type))
    bounds = pc.min_max(values)
    return (col >= bounds["min"]) & (col <= bounds["max"]) & col.isin(values)
