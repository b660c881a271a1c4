"""How large an input file ``impctl`` reads: refused before it is read, with what to do instead.

One guard for every command that reads a household's nights — ``impctl fit``, ``classify``,
``campaign`` and each household of ``impctl fleet fit`` — so a file one of them refuses is
refused by all. Pure standard library: imported by the CLI's option checks.
"""

from __future__ import annotations

from pathlib import Path

from ...errors import InputError

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


def size_above(size_bytes: int, max_mb: float) -> str:
    """``size_bytes`` as "N MB is more than the M MB" with as many digits as it takes to show
    the difference (never "25 MB is more than the 25 MB"), in bytes when MB cannot."""
    size_mb = size_bytes / 1e6
    for digits in range(4):
        text = f"{size_mb:,.{digits}f}"
        if float(text.replace(",", "")) > max_mb:
            return f"{text} MB is more than the {max_mb:g} MB"
    return f"{size_bytes:,} bytes are more than the {round(max_mb * 1e6):,} bytes"


#: Rows closer than this [s] are finer than the fit needs (it works on 5-minute blocks).
FINE_STEP_S = 60.0
#: Bytes of a file read to find its sampling step.
_HEAD_BYTES = 16384


def head_step_s(path: str | Path) -> float | None:
    """The median step [s] between the first rows' ``timestamp`` cells, or None when it cannot
    be told (no such column, unreadable stamps). Reads the first few kilobytes only."""
    import csv
    import itertools
    import statistics
    from datetime import datetime

    try:
        with Path(path).open("rb") as fh:
            head = fh.read(_HEAD_BYTES).decode("utf-8-sig", errors="replace")
    except OSError:
        return None
    lines = head.splitlines()[:-1]  # the last line may be cut
    rows = list(csv.reader(lines))
    if len(rows) < 3 or "timestamp" not in [c.strip() for c in rows[0]]:
        return None
    col = [c.strip() for c in rows[0]].index("timestamp")
    stamps = []
    for row in rows[1:]:
        try:
            stamps.append(datetime.fromisoformat(row[col].strip()))
        except (IndexError, ValueError):
            return None
    try:
        steps = [(b - a).total_seconds() for a, b in itertools.pairwise(stamps)]
    except TypeError:  # naive and aware stamps mixed: the reader says so
        return None
    steps = [s for s in steps if s > 0]
    return statistics.median(steps) if steps else None


def refuse_large_file(path: str | Path, max_mb: float = MAX_FILE_MB) -> None:
    """A file above ``max_mb`` [MB] is refused before it is read, with what to do instead:
    for rows closer than :data:`FINE_STEP_S`, averaging them to one a minute."""
    try:
        size = Path(path).stat().st_size
    except OSError:
        return  # the reader names the problem
    if size <= max_mb * 1e6:
        return
    step = head_step_s(path)
    if step is not None and step < FINE_STEP_S:
        raise InputError(
            f"{size_above(size, max_mb)} read here (about 600,000 rows): its rows are "
            f"{step:g} s apart, finer than the fit uses (5-minute blocks) — average them to "
            "one a minute first, which makes the file about "
            f"{FINE_STEP_S / step:.0f} times smaller (pandas: "
            "df.resample('60s', on='timestamp').mean(); docs: NIGHTS files, 'Sampling')",
            path)
    raise InputError(f"{size_above(size, max_mb)} read here (about 600,000 rows; "
                     + _WHAT_TO_DO, path)


def refuse_many_rows(rows: int, source: str | Path, max_rows: int | None = None) -> None:
    """``rows`` rows of one household above ``max_rows`` (default :data:`MAX_ROWS`) are
    refused before they are read."""
    max_rows = MAX_ROWS if max_rows is None else max_rows
    if rows > max_rows:
        raise InputError(f"{rows:,} rows are more than the {max_rows:,} read for one household "
                         "(about 25 MB of CSV; " + _WHAT_TO_DO, source)
