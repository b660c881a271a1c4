"""The fleet's input: which households there are and how each one's nights are read.

``INPUT`` is either

* a folder of NIGHTS files — ``*.csv`` and ``*.parquet``, one household per file, the household
  id is the file stem (the format of ``impctl export``); or
* one Parquet file, or a Parquet dataset folder (e.g. written by Dask or Spark, hive partitions
  allowed), with a ``household`` column next to the NIGHTS columns.

Discovery runs on the client and reads only names (files) or the ``household`` column (dataset);
each worker reads its own households' nights, so no sample crosses the scheduler.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError

HOUSEHOLD_COLUMN = "household"


@dataclass(frozen=True)
class Source:
    """Where one household's nights are: its own file, or its rows of a shared dataset."""

    household: str
    path: str
    kind: str  # "csv" | "parquet" | "dataset"


def _is_dataset(path: Path) -> bool:
    import pyarrow.dataset as ds

    if path.is_file():
        return path.suffix == ".parquet"
    if any(path.glob("*.csv")):
        return False
    try:
        return HOUSEHOLD_COLUMN in ds.dataset(path, format="parquet",
                                              partitioning="hive").schema.names
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
    import pyarrow.dataset as ds

    path = Path(path)
    if not path.exists():
        raise InputError("no such file or folder", path)
    if _is_dataset(path):
        try:
            table = ds.dataset(path, format="parquet", partitioning="hive").to_table(
                columns=[HOUSEHOLD_COLUMN])
        except (OSError, ValueError) as exc:
            raise InputError(f"not a readable Parquet dataset ({exc})", path) from None
        except KeyError:
            raise InputError(f"no '{HOUSEHOLD_COLUMN}' column", path) from None
        ids = sorted({str(x) for x in table.column(HOUSEHOLD_COLUMN).to_pylist()
                      if x is not None})
        if not ids:
            raise InputError("no household in the dataset", path)
        return [Source(h, str(path), "dataset") for h in ids]
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


def read_sources(sources: list[Source], tz: str) -> dict[str, list | InputError]:
    """Each household's nights (``impctl.imp.NightSamples``), or the InputError saying why not.

    Households of one dataset are read in one pass, filtered on the ``household`` column.
    """
    import pandas as pd

    from ..imp.nights_csv import read_nights, read_nights_frame

    out: dict[str, list | InputError] = {}
    by_dataset: dict[str, list[str]] = {}
    for s in sources:
        if s.kind == "dataset":
            by_dataset.setdefault(s.path, []).append(s.household)
            continue
        try:
            if s.kind == "csv":
                out[s.household] = read_nights(s.path, tz)
            else:
                out[s.household] = read_nights_frame(_read_parquet(s.path), s.path, tz)
        except InputError as exc:
            out[s.household] = exc
    for path, households in by_dataset.items():
        try:
            frame = _read_parquet(path, households)
        except InputError as exc:
            out.update(dict.fromkeys(households, exc))
            continue
        frame[HOUSEHOLD_COLUMN] = frame[HOUSEHOLD_COLUMN].astype(str)
        groups = dict(tuple(frame.groupby(HOUSEHOLD_COLUMN, sort=False)))
        for h in households:
            part = groups.get(h, pd.DataFrame(columns=frame.columns))
            try:
                out[h] = read_nights_frame(part, f"{path} (household {h})", tz)
            except InputError as exc:
                out[h] = exc
    return out


def _read_parquet(path: str, households: list[str] | None = None):
    import pyarrow.dataset as ds

    try:
        dataset = ds.dataset(path, format="parquet", partitioning="hive")
        if households is None:
            return dataset.to_table().to_pandas()
        col = ds.field(HOUSEHOLD_COLUMN)
        field_type = dataset.schema.field(HOUSEHOLD_COLUMN).type
        import pyarrow as pa

        values = pa.array(households).cast(field_type) if not pa.types.is_string(
            field_type) else pa.array(households)
        return dataset.to_table(filter=col.isin(values)).to_pandas()
    except (OSError, ValueError, TypeError) as exc:
        raise InputError(f"not a readable Parquet file ({str(exc).splitlines()[0]})",
                         path) from None
