"""FLEET.parquet: its columns, and writing it batch by batch so that an interrupted run loses
at most one batch.

``FLEET.parquet`` is a Parquet *dataset* folder (what Dask, Spark and pyarrow write and read):
one ``part-<run>-<batch>.parquet`` per finished batch, each written under a hidden temporary
name and renamed into place, so a reader — ``pandas.read_parquet("FLEET.parquet")``,
``dask.dataframe.read_parquet`` — sees whole batches only. ``--resume`` reads the ``household``
column and skips those households.

Columns (units in the names; one row per household):

``household, status`` (ok | insufficient | error), ``reason`` (short, for grouping), ``error``
(the whole message), ``nights_used, nights_constrained, nights_normal, nights_skipped``;
``hlc_w_per_k, c_m_j_per_k, tau_h`` each with ``_low``, ``_high`` (95 % interval) and
``_determined``; ``floor_area_class, c_f_class, u_walls_class`` (the classifiers' range labels,
empty without classifiers), ``class_contradicted``; ``coast_h, coast_h_low, coast_h_high,
rebound_kwh, switch_off_drop_k`` (:mod:`impctl.flex` at 21 °C / 0 °C / 1 K); the seven fitted
parameters (``floor_area_m2`` … ``u_windows_w_per_m2k``) and the fixed ``ach_vent_per_h``,
``ach_infl_per_h`` (enough to re-simulate the house, e.g. ``impctl flex``); the fit's
switch-off terms ``night_gain_w, emitter_tau_h, furniture_j_per_m2k`` each with ``_low``,
``_high`` (empty when the fit did not keep them; :mod:`impctl.flex.switch_off`) and
``night_gain_assumed`` (the gain is the fit's assumption, :mod:`impctl.imp.gain`, not fitted),
``night_gain_source`` (declared | measured | estimated | assumed);
``season_hlc_w_per_k, season_tau_h, season_c_m_j_per_k`` each with ``_low``, ``_high`` (the
season model of the owner and IMP nights together, :mod:`impctl.season`; empty without owner
nights), ``season_owner_nights``, ``season_signature_hlc_w_per_k`` (its baseline),
``season_note`` (why it did not run); ``season_emitter`` (radiators | underfloor, empty when
not known) and ``season_emitter_source`` (declared: the household's NIGHTS column
``emitter`` | measured: the heating water | assumed); ``season_defrost_draw_source`` (where
the heat the defrosts drew from the water comes from: heat meter | flow-return spread, both
measured | estimated; empty without a defrost); ``season_changed`` (the change test
on the owner nights found a step in the heat loss; empty when it could not run),
``season_changed_since`` (the evening of the first night after it),
``season_change_w_per_k`` with ``_low``, ``_high`` (the step and its 95 % interval [W/K]) and
``season_change_nights_after`` (owner nights since) — empty without a change;
``season_tau_mm_s, season_w,
season_tau_e_s, season_f_sun, season_tau_r_s`` (its nonlinear parameters, where a later run's
search starts) and
``season_warm_start`` (this run's search started there);
``imp_nights_digest`` (a digest of the household's IMP nights) and ``imp_fit_reused`` (the IMP
fit's columns were carried over from ``--previous``: the same IMP nights, options and impctl
version, its code included); ``nights_digest`` (a digest of all its nights) and
``nights_unchanged`` (every night as in ``--previous``: the whole row carried over, nothing
fitted);
``needs_more_nights`` (HLC, C_m or τ not determined by the nights), ``loss``, ``eps_pct``
(in-sample heat-demand error); ``batch_size, wall_s_per_household, cpu_s_per_household``
(the worker process's CPU time), ``worker`` (host:pid) and
``worker_rss_mb`` (its resident memory after the batch [MB]); ``impctl_version`` (the
release and a digest of its code, ``0.1.0+src.1f2e3d4c``) and ``fitted_at`` (UTC) — so that a
fleet can be re-fitted when the model improves.
"""

from __future__ import annotations

import functools
import uuid
from pathlib import Path

import pyarrow as pa

from ...atomic import replacing
from ...flex.switch_off import ASSUMED_COLUMN
from ...flex.switch_off import COLUMNS as SWITCH_OFF_COLUMNS

LUMPED_COLUMNS = {"hlc": "hlc_w_per_k", "c_m": "c_m_j_per_k", "tau": "tau_h"}
PARAM_COLUMNS = {
    "floor_area": "floor_area_m2", "wall_height": "wall_height_m",
    "walls_area": "walls_area_m2", "windows_area": "windows_area_m2",
    "c_f": "c_f_1e5_j_per_m2k", "u_walls": "u_walls_w_per_m2k",
    "u_windows": "u_windows_w_per_m2k",
}
CLASS_COLUMNS = ("floor_area_class", "c_f_class", "u_walls_class")
STATUSES = ("ok", "insufficient", "error")

_FIELDS: list[tuple[str, pa.DataType]] = [
    ("household", pa.string()), ("status", pa.string()), ("reason", pa.string()),
    ("error", pa.string()),
    ("nights_used", pa.int32()), ("nights_constrained", pa.int32()),
    ("nights_normal", pa.int32()), ("nights_skipped", pa.int32()),
]
for _col in LUMPED_COLUMNS.values():
    _FIELDS += [(_col, pa.float64()), (f"{_col}_low", pa.float64()),
                (f"{_col}_high", pa.float64()), (f"{_col}_determined", pa.bool_())]
_FIELDS += [(c, pa.string()) for c in CLASS_COLUMNS]
_FIELDS += [("class_contradicted", pa.bool_())]
_FIELDS += [(c, pa.float64()) for c in ("coast_h", "coast_h_low", "coast_h_high",
                                        "rebound_kwh", "switch_off_drop_k")]
_FIELDS += [(c, pa.float64()) for c in PARAM_COLUMNS.values()]
_FIELDS += [(c, pa.float64()) for c in SWITCH_OFF_COLUMNS] + [(ASSUMED_COLUMN, pa.bool_())]
_FIELDS += [("night_gain_source", pa.string())]
SEASON_COLUMNS = ("season_hlc_w_per_k", "season_tau_h", "season_c_m_j_per_k")
for _col in SEASON_COLUMNS:
    _FIELDS += [(_col, pa.float64()), (f"{_col}_low", pa.float64()),
                (f"{_col}_high", pa.float64())]
_FIELDS += [("season_owner_nights", pa.int32()),
            ("season_signature_hlc_w_per_k", pa.float64()), ("season_note", pa.string()),
            ("season_emitter", pa.string()), ("season_emitter_source", pa.string()),
            ("season_defrost_draw_source", pa.string()),
            ("season_changed", pa.bool_()), ("season_changed_since", pa.date32()),
            ("season_change_w_per_k", pa.float64()), ("season_change_w_per_k_low", pa.float64()),
            ("season_change_w_per_k_high", pa.float64()),
            ("season_change_nights_after", pa.int32())]
#: The season model's nonlinear parameters (:data:`impctl.season.projection.columns.THETA`):
#: where the next run's search starts (``--previous``).
THETA_COLUMNS = ("season_tau_mm_s", "season_w", "season_tau_e_s", "season_f_sun",
                 "season_tau_r_s")
_FIELDS += [(c, pa.float64()) for c in THETA_COLUMNS]
_FIELDS += [("season_warm_start", pa.bool_()), ("imp_nights_digest", pa.string()),
            ("imp_fit_reused", pa.bool_()), ("nights_digest", pa.string()),
            ("nights_unchanged", pa.bool_())]
_FIELDS += [("ach_vent_per_h", pa.float64()), ("ach_infl_per_h", pa.float64()),
            ("needs_more_nights", pa.bool_()), ("loss", pa.float64()),
            ("eps_pct", pa.float64()), ("batch_size", pa.int32()),
            ("wall_s_per_household", pa.float64()), ("cpu_s_per_household", pa.float64()),
            ("worker", pa.string()),
            ("worker_rss_mb", pa.float64()), ("impctl_version", pa.string()),
            ("fitted_at", pa.timestamp("s", tz="UTC"))]
SCHEMA = pa.schema(_FIELDS)
COLUMNS = tuple(SCHEMA.names)
#: What a run measures of itself (its batch, its worker, when, what it carried over, the
#: digest of all the nights it read): never carried over from ``--previous``.
_OWN = {"household", "batch_size", "wall_s_per_household", "cpu_s_per_household", "worker",
        "worker_rss_mb", "impctl_version", "fitted_at", "imp_fit_reused", "nights_digest",
        "nights_unchanged"}
#: The columns the same nights give again: all but the run's own (:mod:`.previous`).
ROW_COLUMNS = tuple(c for c in COLUMNS if c not in _OWN)
#: The IMP fit's columns, the same for the same IMP nights (:mod:`.previous`).
CARRIED_COLUMNS = tuple(c for c in ROW_COLUMNS if not c.startswith("season_"))


def empty_row(household: str) -> dict:
    """A row with every column None (status error until something better is known)."""
    row = dict.fromkeys(COLUMNS)
    row.update(household=household, status="error", reason="not fitted", error="")
    return row


@functools.cache
def version() -> str:
    """impctl's version as the FLEET rows record it: the installed version and, as a local
    label, a digest of the package's own files (``0.1.0+src.1f2e3d4c``).

    ``--previous`` keeps a row only where this matches, so code changed between two releases
    (a checkout, an editable install) never hands a row its older code computed to a run of
    the newer one."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed

    try:
        release = installed("impctl")
    except PackageNotFoundError:
        release = "unknown"
    return f"{release}+src.{source_digest(Path(__file__).resolve().parents[2])}"


def source_digest(root: Path) -> str:
    """8 hex digits over a package folder's modules and data files (path and bytes, in path
    order)."""
    import hashlib

    digest = hashlib.blake2b(digest_size=4)
    files = sorted(p for p in root.rglob("*")
                   if p.suffix in (".py", ".json", ".toml") and "__pycache__" not in p.parts)
    for p in files:
        digest.update(p.relative_to(root).as_posix().encode() + b"\0")
        digest.update(p.read_bytes())
    return digest.hexdigest()


def to_table(rows: list[dict]) -> pa.Table:
    """Rows (dicts) → an Arrow table with :data:`SCHEMA` (versions and time filled in)."""
    import datetime as dt

    now = dt.datetime.now(dt.UTC).replace(microsecond=0)
    written_by = version()
    cols = {name: [] for name in COLUMNS}
    for row in rows:
        for name in COLUMNS:
            v = row.get(name)
            if isinstance(v, float) and v != v:  # NaN → null
                v = None
            cols[name].append(v)
        cols["impctl_version"][-1] = cols["impctl_version"][-1] or written_by
        cols["fitted_at"][-1] = cols["fitted_at"][-1] or now
    return pa.table({n: pa.array(cols[n], type=SCHEMA.field(n).type) for n in COLUMNS},
                    schema=SCHEMA)


def new_run_id() -> str:
    """A short id that keeps the part files of different runs (``--resume``) apart."""
    return uuid.uuid4().hex[:8]


def write_part(out: Path, run_id: str, index: int, rows: list[dict]) -> Path:
    """Write one batch as ``out/part-<run>-<index>.parquet``, atomically (hidden temp + rename)."""
    import pyarrow.parquet as pq

    out.mkdir(parents=True, exist_ok=True)
    target = out / f"part-{run_id}-{index:06d}.parquet"
    with replacing(target, fsync=True) as tmp:  # on disk before it becomes visible
        pq.write_table(to_table(rows), tmp)
    return target


#: The reason of the rows a batch gets when its task failed as a whole (a lost worker): they
#: say nothing of the household, and a resumed run fits it again.
WORKER_FAILED = "worker failed"


def done_households(out: Path) -> set[str]:
    """Households that already have a row in the FLEET dataset ``out`` (empty if none), but
    for the rows of a batch whose worker failed (:data:`WORKER_FAILED`)."""
    import pyarrow.dataset as ds

    if not out.exists() or not any(out.glob("part-*.parquet")):
        return set()
    table = ds.dataset(out, format="parquet").to_table(columns=["household", "reason"])
    return {str(h) for h, why in zip(table.column("household").to_pylist(),
                                      table.column("reason").to_pylist(), strict=True)
            if why != WORKER_FAILED}


def drop_failed_parts(out: Path) -> int:
    """Remove the parts of batches whose worker failed (every row :data:`WORKER_FAILED`), so
    that a resumed run's new rows of those households are their only ones; how many."""
    import pyarrow.parquet as pq

    dropped = 0
    for part in sorted(out.glob("part-*.parquet")):
        reasons = pq.read_table(part, columns=["reason"]).column(0).to_pylist()
        if reasons and all(r == WORKER_FAILED for r in reasons):
            part.unlink()
            dropped += 1
    return dropped


def read_fleet(out: str | Path):
    """The FLEET dataset as a pandas DataFrame (all parts)."""
    import pandas as pd

    return pd.read_parquet(out)
