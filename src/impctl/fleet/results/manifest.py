"""FLEET.parquet's manifest: what was asked for and how much of it is there.

``impctl fleet fit`` writes ``_manifest.json`` into the FLEET dataset folder when it starts and
rewrites it (atomically) after every batch written: the input, the options, the households
expected and those with a row, and ``complete``. An interrupted run (Ctrl-C, a crash, kill -9)
leaves a manifest that says ``complete: false`` and how many households it has; ``impctl flex``
and the fleet report read it and say "partial: 16 of 40 households". A resumed run
(``--resume``) must read the same input with the same options, else the dataset would mix two
different fits. The leading underscore keeps Parquet readers (pyarrow, pandas, Spark) from
taking the file for data.
"""

from __future__ import annotations

import datetime as dt
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ...atomic import replacing
from ...errors import InputError

MANIFEST_FILE = "_manifest.json"
FORMAT = "impctl-fleet/1"


@dataclass
class Manifest:
    """The manifest of one FLEET dataset (JSON keys as the attributes).

    ``options``: what decides the numbers (:class:`impctl.fit.household.FitOptions`, the time
    zone, the classifiers' directory or "prior"); ``households``: expected (found in
    ``input``); ``done``: with a row; ``runs``: the run ids of its part files; ``expected``:
    the expected households' ids (a resumed input may have lost some: their rows are not
    counted as done).
    """

    input: str
    options: dict
    households: int
    done: int = 0
    runs: list[str] = field(default_factory=list)
    started_at: str = ""
    updated_at: str = ""
    format: str = FORMAT
    expected: list[str] = field(default_factory=list)

    @property
    def complete(self) -> bool:
        """Every expected household has a row."""
        return self.done >= self.households

    def status(self, out: str | Path) -> str:
        """"complete: N households", or "partial: K of N households" and how to finish it
        (the dataset is ``out``)."""
        if self.complete:
            return f"complete: {self.households} households"
        return (f"partial: {self.done} of {self.households} households (an interrupted run; "
                f"finish it with: impctl fleet fit {self.input} --out {out} --resume)")


def _now() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="seconds")


def write_manifest(out: Path, manifest: Manifest) -> Path:
    """Write ``out/_manifest.json`` atomically (hidden temp file, fsync, rename)."""
    manifest.updated_at = _now()
    manifest.started_at = manifest.started_at or manifest.updated_at
    out.mkdir(parents=True, exist_ok=True)
    target = out / MANIFEST_FILE
    with replacing(target, fsync=True) as tmp:
        tmp.write_text(json.dumps({**asdict(manifest), "complete": manifest.complete},
                                  indent=2) + "\n")
    return target


def read_manifest(path: str | Path) -> Manifest | None:
    """The manifest of the FLEET dataset ``path``; None when it has none (a single Parquet
    file, or a dataset written before manifests).

    Raises
    ------
    InputError
        An unreadable or foreign manifest.
    """
    target = Path(path) / MANIFEST_FILE
    if not target.is_file():
        return None
    try:
        data = json.loads(target.read_text())
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ValueError(f"format {data.get('format') if isinstance(data, dict) else None!r}"
                             f", expected {FORMAT!r}")
        data.pop("complete", None)
        return Manifest(**data)
    except (OSError, ValueError, TypeError) as exc:
        raise InputError(f"unreadable FLEET manifest ({str(exc).splitlines()[0]})",
                         target) from None


def completeness(path: str | Path) -> str | None:
    """A line for a reader of the FLEET dataset ``path`` when it is not known complete:
    "partial: K of N households …", or that it has no manifest; None when complete."""
    if not Path(path).is_dir():
        return None
    manifest = read_manifest(path)
    if manifest is None:
        return (f"completeness unknown: no {MANIFEST_FILE} beside the parts (impctl fleet fit "
                "writes one; a copy may have left it behind)")
    recount(Path(path), manifest)
    return None if manifest.complete else manifest.status(path)


def recount(out: Path, manifest: Manifest) -> Manifest:
    """Set ``manifest.done`` from the part files in ``out``, the dataset's truth.

    A run stopped between a part's rename and the manifest's rewrite (Ctrl-C, kill -9, a power
    cut) leaves a manifest one batch behind its parts; counting the parts keeps "partial: K of
    N" equal to the rows a reader finds."""
    from .table import done_households

    done = done_households(out)
    manifest.done = len(done & set(manifest.expected)) if manifest.expected else len(done)
    return manifest
