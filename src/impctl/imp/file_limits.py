"""How large an input file ``impctl`` reads: refused before it is read, with what to do instead.

One guard for every command that reads a household's nights — ``impctl fit``, ``classify``,
``campaign`` and each household of ``impctl fleet fit`` — so a file one of them refuses is
refused by all. Pure standard library: imported by the CLI's option checks.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError

#: Largest NIGHTS.csv read [MB] (~600,000 rows, 5.7 years of 5-minute data): 576,000 rows
#: (24 MB) took 47 s and 531 MB peak RSS with 30 nights fitted (bench/fit_large.py); a gateway
#: has 1–4 GB.
MAX_FILE_MB = 25.0
#: Largest number of rows of one household read from Parquet [rows]: the rows MAX_FILE_MB of
#: CSV holds (a Parquet file is several times smaller than the CSV of the same rows, so its
#: size in MB says little about the memory its rows take).
MAX_ROWS = 600_000

_WHAT_TO_DO = ("a gateway has 1–4 GB of memory): keep the campaign's weeks only, e.g. the last "
               "60 days")


def file_mb(path: str | Path) -> float:
    """Size of ``path`` [MB]; 0 when it cannot be read (the reader then names the problem)."""
    try:
        return Path(path).stat().st_size / 1e6
    except OSError:
        return 0.0


def refuse_large_file(path: str | Path, max_mb: float = MAX_FILE_MB) -> None:
    """A file above ``max_mb`` [MB] is refused before it is read, with what to do instead."""
    size_mb = file_mb(path)
    if size_mb > max_mb:
        raise InputError(
            f"{size_mb:.0f} MB is more than the {max_mb:g} MB read here (about 600,000 rows; "
            + _WHAT_TO_DO, path)


def refuse_many_rows(rows: int, source: str | Path, max_rows: int | None = None) -> None:
    """``rows`` rows of one household above ``max_rows`` (default :data:`MAX_ROWS`) are
    refused before they are read."""
    max_rows = MAX_ROWS if max_rows is None else max_rows
    if rows > max_rows:
        raise InputError(f"{rows:,} rows are more than the {max_rows:,} read for one household "
                         "(about 25 MB of CSV; " + _WHAT_TO_DO, source)
