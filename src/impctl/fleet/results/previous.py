"""The last run's FLEET as a start: a household's IMP fit carried over, its season search warm.

An aggregator fits its fleet every morning, and between two mornings most households gained an
owner night and no IMP night: their IMP fit — most of a row's cost, with the classes — would
come out the same. Given the last run's FLEET dataset (``impctl fleet fit --previous``), a
household whose IMP nights are the same (:func:`nights_digest`), fitted with the same options,
classifiers and impctl version, keeps that run's IMP columns (``imp_fit_reused``), and its
season model starts its search only where that run's ended (``season_warm_start``), as the
daemon's morning refit does (:func:`impctl.season.fit.fit_nights`). A household whose nights
are all the same (no new night: a gateway that did not report, or the same run again) keeps
its whole row (``nights_unchanged``). A household with a new or changed IMP night, or one the
last run did not fit, is fitted afresh, the full search included.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from ...errors import InputError
from .manifest import read_manifest
from .table import CARRIED_COLUMNS, ROW_COLUMNS, THETA_COLUMNS

#: Statuses whose IMP columns are carried over: what the same nights give again. An
#: ``error`` row is fitted afresh (a lost worker or an unreadable file may have been passing).
CARRIED_STATUSES = ("ok", "insufficient")


def _night_bytes(night) -> list[bytes]:
    """What a digest reads of one night (:class:`~impctl.imp.night.NightSamples`): every field
    and every sample."""
    out = []
    for f in dataclasses.fields(night):
        v = getattr(night, f.name)
        out.append(f.name.encode())
        if isinstance(v, np.ndarray):
            a = np.ascontiguousarray(v)
            out.append(str(a.dtype).encode() + str(a.shape).encode())
            out.append(a.tobytes())
        else:
            out.append(repr(v).encode())
    return out


def nights_digest(nights: Iterable) -> str:
    """A digest of nights: equal digests, the same input (to the IMP fit for the IMP nights,
    to the whole row for all of them)."""
    return nights_digests(nights, lambda _: False)[1]


def nights_digests(nights: Iterable, part: Callable[[object], bool]) -> tuple[str, str]:
    """(:func:`nights_digest` of the nights ``part`` picks, of all of them), each night read
    once for both."""
    some, every = hashlib.blake2b(digest_size=16), hashlib.blake2b(digest_size=16)
    for n in nights:
        picked = part(n)
        for chunk in _night_bytes(n):
            every.update(chunk)
            if picked:
                some.update(chunk)
    return some.hexdigest(), every.hexdigest()


def previous_rows(path: str | Path, options: dict, version: str) -> tuple[dict[str, dict], str]:
    """The rows of the FLEET dataset ``path`` a run with ``options`` (the manifest's: fit
    options, time zone, classifiers) and impctl ``version`` can start from, by household, and a
    line saying how many. InputError when ``path`` is not a FLEET dataset."""
    import pyarrow.dataset as ds

    path = Path(path)
    manifest = read_manifest(path) if path.is_dir() else None
    if manifest is None or not any(path.glob("part-*.parquet")):
        raise InputError("is not a FLEET dataset (no manifest or no parts); give the folder "
                         "an earlier impctl fleet fit wrote", path, "--previous")
    changed = sorted(k for k in {*options, *manifest.options}
                     if options.get(k) != manifest.options.get(k))
    if changed:
        return {}, (f"--previous was fitted with other options ({', '.join(changed)}): every "
                    "household is fitted afresh")
    dataset = ds.dataset(path, format="parquet")
    if "imp_nights_digest" not in dataset.schema.names:
        return {}, ("--previous was written by an impctl that did not keep the IMP nights' "
                    "digest: every household is fitted afresh")
    rows = dataset.to_table().to_pylist()
    kept = {r["household"]: r for r in rows
            if r.get("impctl_version") == version and r.get("imp_nights_digest")
            and r.get("status") in CARRIED_STATUSES}
    return kept, (f"--previous: {len(kept)} of {len(rows)} households can keep their IMP fit "
                  "where their IMP nights are unchanged")


def carry_over(row: dict, previous: dict, whole: bool = False) -> None:
    """``row`` takes the IMP fit's columns of ``previous`` (its row of the last run), or, with
    ``whole`` (the nights all unchanged), every column but the run's own."""
    for col in ROW_COLUMNS if whole else CARRIED_COLUMNS:
        row[col] = previous.get(col)
    row["imp_fit_reused"] = True
    row["nights_unchanged"] = whole


def theta_start(previous: dict | None) -> tuple[float, ...] | None:
    """The season search's start from a previous row (None where it had no season fit), by
    the rule a fit JSON's θ is read with (:func:`impctl.season.result.theta_of`)."""
    if previous is None:
        return None
    from ...season.projection.columns import THETA
    from ...season.result import theta_of

    return theta_of({"season": {"theta": {
        name: previous.get(col) for name, col in zip(THETA, THETA_COLUMNS, strict=True)}}})
