"""Stored nights → the measured-data format read by ``impctl classify`` and ``impctl fit``.

Columns: ``timestamp`` (ISO 8601, UTC offset), ``t_air`` and ``t_out`` [°C], ``q_hc`` [W thermal],
``setpoint`` [°C], ``heating`` (1 normal night, 0 constrained), ``night`` (id), ``kind``.
An IMP night's samples are those of its window and, before them, of its pre-heat (the heat
pump raised to T_max before a constrained night's switch-off, or held at the setpoint before a
normal night), marked ``phase`` = ``preheat`` with the setpoint and ``heating`` the heat pump
read; samples with a missing T_air, T_out or Q_HC are left out.

The owner records (``kind`` owner: the house recorded read-only between IMP nights, one per
local day from noon to noon) are written whole, every row the mean over [timestamp, timestamp
+ the row interval), labelled or not: ``label`` says why one is not the owner's ordinary night
(empty when it is), ``setpoint`` is the owner's setpoint in that row, ``heating`` 0 where loop 1
or the heating system was off. Nights and records are sorted by their first row.

What the heat pump said besides: ``p_el_w`` (its electrical power, W), ``t_flow_c`` and
``t_return_c`` (supply and return water, °C), ``t_flow_target_c`` (its calculated flow
target: the heating curve it runs, °C), ``dhw`` (an owner row's share of time charging hot
water, 0–1; an IMP night's sample 1 or 0).

What the house's own sensors said at each sample (``[inputs]``, empty when not configured,
stale or malformed): ``p_house_w`` (the household's electricity other than the heat pump, W),
``t_rooms_c`` (mean of the room sensors, °C), ``t_out_ref_c`` (the reference outdoor
temperature, °C), ``occupants`` (people at home).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from ..atomic import replacing
from ..errors import InputError
from ..imp.protocol import SHORT_NIGHT
from .db import Store

COLUMNS = ("timestamp", "t_air", "t_out", "q_hc", "setpoint", "heating", "night", "kind",
           "p_house_w", "t_rooms_c", "t_out_ref_c", "occupants", "defrost", "p_el_w",
           "t_flow_c", "t_return_c", "t_flow_target_c", "dhw", "label", "phase")
#: The ``house_inputs`` column behind each export column of the house's own sensors.
HOUSE_COLUMNS = ("p_house_w", "t_rooms_c", "t_out_ref_c", "occupants")
#: Export columns that are numbers (empty where missing).
NUMBER_COLUMNS = (*HOUSE_COLUMNS, "p_el_w", "t_flow_c", "t_return_c", "t_flow_target_c", "dhw")


def nights_rows(store: Store, night_ids: Iterable[int] | None = None,
                valid_only: bool = True, owner: bool = True) -> list[dict]:
    """One dict per usable sample of the selected nights (valid ones by default) and, with
    ``owner``, of every closed owner record (labelled or not; with ``night_ids`` those among
    them), nights and records in the order of their first row. A constrained night too short
    for the IMP fit and wrong in nothing else comes too, labelled
    :data:`~impctl.imp.protocol.SHORT_NIGHT` (the season model's). A record still recording is
    left out: its labels (a setpoint changed, hot water, data missing) come when it closes. A
    night or record with a single row is left out: nothing can be read from one row, and the
    NIGHTS reader refuses it."""
    kinds = ("constrained", "normal", "owner") if owner else ("constrained", "normal")
    nights = [n for n in store.nights(ids=night_ids, kinds=kinds)
              if (n.state == "done" if n.kind == "owner"
                  else not valid_only or n.valid or _short(n))]
    blocks = []
    for night in nights:
        rows = _night_rows(store, night)
        if len(rows) >= 2:  # e.g. a daemon started a minute before its record's noon
            blocks.append(rows)
    blocks.sort(key=lambda rows: rows[0]["_ts"])
    out = []
    for rows in blocks:
        for row in rows:
            del row["_ts"]
            out.append(row)
    return out


def _short(night) -> bool:
    """A constrained night that reached T_min too soon for the IMP fit and failed nothing
    else: exported, labelled, for the season model."""
    return night.kind == "constrained" and night.state == "done" and SHORT_NIGHT in night.reasons


def _night_rows(store: Store, night) -> list[dict]:
    house = {r.ts: r for r in store.house_inputs(night.id)}
    owner = night.kind == "owner"
    label = "; ".join(night.reasons) if owner else SHORT_NIGHT if _short(night) else ""
    rows = []
    for s in store.samples(night.id):
        # An IMP night samples from the moment it raises the setpoint: its pre-heat comes
        # first, marked, for the season model (the house is no gap there); `impctl fit`
        # reads the window alone, whose first row is the switch-off of a constrained night.
        # Nothing after the window. An owner record is its window.
        preheat = not owner and s.ts < night.window_start
        if s.ts > night.window_end or (owner and s.ts < night.window_start):
            continue
        if s.t_air_c is None or s.t_out_c is None or s.q_hc_w is None:
            continue
        if owner or preheat:  # as the heat pump ran it, read at the row
            heating, setpoint = int(not (s.loop_mode == 0 or s.system_on == 0)), s.setpoint_c
        else:
            heating, setpoint = int(night.kind == "normal"), night.setpoint_c
        if owner:
            dhw = s.dhw_share
        else:
            dhw = None if s.dhw_active is None else int(s.dhw_active)
        rows.append({
            "_ts": s.ts, "timestamp": s.ts.isoformat(), "t_air": s.t_air_c, "t_out": s.t_out_c,
            "q_hc": s.q_hc_w, "setpoint": setpoint, "heating": heating, "night": night.id,
            "kind": night.kind,
            **{c: getattr(house.get(s.ts), c, None) for c in HOUSE_COLUMNS},
            "defrost": None if s.defrost is None else int(s.defrost),
            "p_el_w": s.p_el_w, "t_flow_c": s.t_supply_c, "t_return_c": s.t_return_c,
            "t_flow_target_c": s.t_flow_target_c, "dhw": dhw, "label": label,
            "phase": "preheat" if preheat else "",
        })
    return rows


#: The first bytes of every SQLite database file.
_SQLITE_MAGIC = b"SQLite format 3\0"


def check_output_file(out: Path, force: bool = False, protect: Iterable[Path] = ()) -> None:
    """Refuse an output path that would destroy data (raises :class:`InputError`).

    Never onto a directory, a database (the store, its journal and write counters live in
    SQLite files: refused even with ``force``) or a file in ``protect`` or next to it
    (``-wal``/``-shm``); never into a directory that does not exist (it is not created); an
    existing file only with ``force``.
    """
    out = Path(out)
    if out.is_dir():
        raise InputError("is a directory; give the file to write", out, "--out")
    if not out.parent.is_dir():
        raise InputError("directory does not exist (export does not create it)", out.parent,
                         "--out")
    target = out.resolve()
    for path in protect:
        path = Path(path).resolve()
        if target in (path, Path(f"{path}-wal"), Path(f"{path}-shm"), Path(f"{path}-journal")):
            raise InputError("is the impctl store; export never writes onto it", out, "--out")
    if out.exists():
        try:
            with out.open("rb") as fh:
                head = fh.read(len(_SQLITE_MAGIC))
        except OSError as exc:
            raise InputError(f"cannot read: {exc.strerror}", out, "--out") from None
        if head == _SQLITE_MAGIC:
            raise InputError("is an SQLite database; export never writes onto a database", out,
                             "--out")
        if not force:
            raise InputError("exists; add --force to overwrite it", out, "--out")


def export_nights(store: Store, out: Path, fmt: str, night_ids: Iterable[int] | None = None,
                  valid_only: bool = True, *, force: bool = False, owner: bool = True,
                  emitter: str | None = None) -> int:
    """Write the selected nights to ``out`` as CSV or Parquet, atomically; returns the row count.
    ``emitter``: the emitter the installer declared ([fit] emitter), written as the NIGHTS
    column ``emitter`` on every row.

    Raises :class:`InputError` (nothing written) for an unsafe ``out`` (see
    :func:`check_output_file`; ``force`` allows overwriting a plain file), an unknown night id,
    or a selection without a usable sample.
    """
    import pandas as pd

    out = Path(out)
    check_output_file(out, force, protect=[store.path])
    if night_ids is not None:
        night_ids = list(night_ids)
        known = {n.id for n in store.nights(ids=night_ids,
                                            kinds=("constrained", "normal", "owner"))}
        missing = [i for i in night_ids if i not in known]
        if missing:
            raise InputError(f"no such night(s) in the store: {', '.join(map(str, missing))}",
                             store.path, "--nights")
    rows = nights_rows(store, night_ids, valid_only, owner)
    if not rows:
        what = "the selected nights have no usable sample" if night_ids is not None else (
            "no valid night in the store has a usable sample" if valid_only
            else "the store has no usable sample")
        raise InputError(f"nothing to export: {what} (see impctl nights)", store.path)
    df = pd.DataFrame(rows, columns=list(COLUMNS))
    # Numbers even when every cell is missing (a column of None would be text in Parquet).
    df[list(NUMBER_COLUMNS)] = df[list(NUMBER_COLUMNS)].astype(float)
    df["defrost"] = df["defrost"].astype("Int8")   # 1/0, empty where not logged
    if emitter is not None:
        df["emitter"] = emitter
    if fmt not in ("csv", "parquet"):
        raise ValueError(f"unknown format {fmt!r}")
    with replacing(out, mode=0o600) as tmp:
        if fmt == "csv":
            df.to_csv(tmp, index=False)
        else:
            df.to_parquet(tmp, index=False)
    return len(df)


def refuse_database(out: Path | None, option: str) -> None:
    """Refuse an output path that is an SQLite database or one of its side files (raises
    :class:`InputError`): the store holds the restore journal, and no command may write onto
    it (``fit --json``, ``fit --plot``, ``simulate --out``; ``export`` checks more)."""
    if out is None:
        return
    out = Path(out)
    candidates = [out] + [out.with_name(out.name[: -len(suffix)])
                          for suffix in ("-wal", "-shm", "-journal")
                          if out.name.endswith(suffix)]
    for path in candidates:
        try:
            with path.open("rb") as fh:
                head = fh.read(len(_SQLITE_MAGIC))
        except OSError:
            continue
        if head == _SQLITE_MAGIC:
            raise InputError("is an SQLite database (or its journal); impctl never writes onto "
                             "one", out, option)
