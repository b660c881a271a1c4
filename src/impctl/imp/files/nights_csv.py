"""NIGHTS.csv: measured IMP nights, the input of ``impctl classify`` and ``impctl fit``.

Format (one header row, then one row per sample; row numbers in errors are file lines)::

    timestamp,t_air,t_out,q_hc[,setpoint][,heating][,night][,kind]

* ``timestamp`` — ISO 8601, strictly increasing (within each night when ``night`` is given);
  naive times are local time in ``tz``.
* ``t_air``, ``t_out`` — indoor air and outdoor temperature [°C].
* ``q_hc`` — thermal heat output of the heating [W] (not electrical power); negative only
  while a defrost draws heat from the heating water (a signed heat reading), ≥ −25 kW.
* ``setpoint`` (optional, may be empty) — T_set [°C]; for constrained nights the band centre.
* ``heating`` (optional) — 1 while the heating is enabled, 0 while it is switched off.
* ``night`` (optional) — night identifier; rows of one night must be contiguous.
* ``kind`` (optional) — ``constrained``, ``normal`` or ``owner`` (the house as its owner runs
  it, recorded read-only between IMP nights; the fit leaves these out), the same on every row
  of a night.
* ``p_house_w``, ``occupants``, ``t_rooms_c``, ``t_out_ref_c``, ``night_gain_w``, ``defrost``,
  ``p_el_w`` (optional) — household electricity besides the heat pump [W], sleepers, mean of
  the room sensors and a reference outdoor temperature [°C], a declared night gain [W], 1 while
  the heat pump defrosts, the heat pump's electrical power [W] (:mod:`.extras`: a bad
  cell there is missing, not refused).
* ``t_flow_c``, ``t_return_c``, ``t_flow_target_c``, ``dhw``, ``label``, ``emitter``
  (optional) — supply, return and target flow water [°C], the share of time charging hot
  water, an owner night's label, the emitter as the installer declares it (``radiators`` |
  ``underfloor``; :mod:`.series`: a bad value there refuses the file).
* ``phase`` (optional, with ``night``) — ``preheat`` on an IMP night's first rows, its pre-heat,
  read as a piece of its own that only the season model takes (:mod:`.phase`).

Without ``night`` the samples are cut into the local windows 22:00–05:00 (end inclusive); samples
outside every window are ignored, and windows with fewer than two samples are dropped. Without
``kind`` a night is ``constrained`` when the heating is off (``heating`` = 0, or without that
column Q_HC ≤ :data:`~impctl.imp.features.Q_ON_W`) in at least :data:`OFF_FRACTION` of its samples
during the first hour, else ``normal``; such a night on which the setpoint is not held (heat
pulses, T_air falling under a fixed heat input: :mod:`.held`) carries the reason in ``not_held``
and is not fitted.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import InputError
from ..features import Q_ON_W
from ..night import NightSamples
from ..plan import DEFAULT_WINDOW, NightPlan
from ..plausibility import electrical_problem
from ..tables import TIMESTAMP_TEXT, frame_table, read_table
from .extras import EXTRA_COLUMNS, defrost_fields, extra_columns, night_extras
from .held import not_held
from .phase import PHASE, PREHEAT, check_phases, split_preheat
from .series import (
    EMITTER,
    LABEL,
    SERIES_COLUMNS,
    check_emitter,
    check_labels,
    series_arrays,
    series_fields,
)
from .values import PLAUSIBLE as PLAUSIBLE  # re-exported: curve.data.rows reads the ranges
from .values import _row, check_values

REQUIRED_COLUMNS = ("timestamp", "t_air", "t_out", "q_hc")
#: Share of the first hour's samples that must be "heating off" for an unlabelled constrained night.
OFF_FRACTION = 0.8


def _window_ids(
    stamps: pd.Series, tz: str, window: tuple[dt.time, dt.time]
) -> tuple[pd.Series, dict[str, pd.Timestamp]]:
    """Night id (ISO date of the window start, '' outside every window) and window starts."""
    local = stamps.dt.tz_convert(tz)
    day = local.dt.tz_localize(None).dt.normalize()
    tod = (local.dt.tz_localize(None) - day).dt.total_seconds()
    start_s = window[0].hour * 3600 + window[0].minute * 60 + window[0].second
    end_s = window[1].hour * 3600 + window[1].minute * 60 + window[1].second
    if end_s < start_s:  # the window spans midnight
        late, early = tod >= start_s, tod <= end_s
        date = day.where(~early, day - pd.Timedelta(days=1))
        inside = late | early
    else:
        inside = (tod >= start_s) & (tod <= end_s)
        date = day
    ids = date.dt.strftime("%Y-%m-%d").where(inside, "")
    plan = NightPlan("normal", window_start=window[0], window_end=window[1])
    starts = {d: plan.window(d, tz)[0] for d in ids.unique() if d}
    return ids, starts


def _infer_kind(time_s: np.ndarray, off: np.ndarray) -> str:
    first_hour = time_s < 3600.0
    sel = off[first_hour] if first_hour.any() else off[:1]
    return "constrained" if sel.mean() >= OFF_FRACTION else "normal"


def read_nights(
    path: str | Path,
    tz: str = "Europe/Ljubljana",
    *,
    window: tuple[dt.time, dt.time] = DEFAULT_WINDOW,
) -> list[NightSamples]:
    """Read NIGHTS.csv (format in the module docstring) into one :class:`NightSamples` per night.

    Parameters
    ----------
    path : str or Path
    tz : str
        Time zone of naive timestamps and of the night windows.
    window : (time, time)
        Local window used to cut nights when the file has no ``night`` column.

    Returns
    -------
    list of NightSamples, in time order

    Raises
    ------
    InputError
        One line naming the file, the row and the problem: missing column, bad number or
        timestamp, implausible value, timestamps not increasing, a night split or with a changing
        ``kind``, a labelled night with fewer than two samples, no night at all.
    """
    path = Path(path)
    try:
        table = read_table(path, required=REQUIRED_COLUMNS, numeric=_NUMERIC, optional=_OPTIONAL,
                           may_be_empty=_MAY_BE_EMPTY, tz=tz)
    except InputError:
        from .hints import layout_problem

        cause = layout_problem(path, REQUIRED_COLUMNS)  # ';' separators, decimal commas
        if cause is None:
            raise
        raise InputError(cause[0], path, cause[1]) from None
    return nights_from_table(table, path, tz, window=window)


_NUMERIC = ("t_air", "t_out", "q_hc", "setpoint", "heating", *SERIES_COLUMNS)
#: numeric columns whose empty cells are missing values
_MAY_BE_EMPTY = ("setpoint", *SERIES_COLUMNS)
_TEXT = ("night", "kind", LABEL, PHASE, EMITTER)
# read as text, then each cell a number or missing (:mod:`.extras`), never a refusal
_OPTIONAL = (*_TEXT, *EXTRA_COLUMNS)


def read_nights_frame(
    frame: pd.DataFrame,
    source: str | Path,
    tz: str = "Europe/Ljubljana",
    *,
    window: tuple[dt.time, dt.time] = DEFAULT_WINDOW,
) -> list[NightSamples]:
    """:func:`read_nights` for a DataFrame in the same format (e.g. read from Parquet).

    ``timestamp`` may be datetimes (naive = local time in ``tz``) or ISO 8601 strings; errors
    name ``source`` and the row (counted as in the CSV form: the first data row is row 2).
    """
    table = frame_table(frame.reset_index(drop=True), source, required=REQUIRED_COLUMNS,
                        numeric=_NUMERIC, optional=_OPTIONAL, may_be_empty=_MAY_BE_EMPTY,
                        lenient=EXTRA_COLUMNS, tz=tz)
    return nights_from_table(table, Path(source), tz, window=window)


def nights_from_table(
    table: pd.DataFrame,
    path: Path,
    tz: str,
    *,
    window: tuple[dt.time, dt.time] = DEFAULT_WINDOW,
) -> list[NightSamples]:
    """Checked table (``timestamp`` tz-aware, numbers float) → nights; see :func:`read_nights`."""
    # The timestamp texts kept for messages go to the one message that quotes them, and off
    # the table before it is copied: pandas deep-copies attrs into every copy and every column
    # taken below (a season's file: a second per read). The table is this module's own.
    stamp_text = table.attrs.get(TIMESTAMP_TEXT)
    table.attrs = {}
    table = table.copy(deep=False)
    # Plain arrays, cut per night by index: pandas per night cost a fleet ~15 ms per household.
    stamps = pd.DatetimeIndex(table["timestamp"])
    try:
        stamp_ns = stamps.as_unit("ns").asi8
    except (OverflowError, pd.errors.OutOfBoundsDatetime):
        bad = np.asarray((stamps.year < 1678) | (stamps.year > 2261))
        i = int(np.argmax(bad))
        raise InputError(f"timestamp {stamps[i].isoformat()} is outside the years 1678–2261 "
                         "a time in nanoseconds can hold", path, _row(i)) from None
    check_values(table, path, stamp_text, stamp_ns)
    explicit = "night" in table
    starts: dict = {}  # without ``night``: each window's start (else a night's first row)
    if explicit:
        ids = table["night"].to_numpy(dtype=object)
        change = np.ones(len(ids), bool)
        change[1:] = ids[1:] != ids[:-1]
        first = np.flatnonzero(change)
        run_ids = pd.Series(ids[first])
        dup = run_ids.duplicated().to_numpy()
        if dup.any():
            i = int(first[np.argmax(dup)])
            raise InputError(f"night {ids[i]!r} is split: its rows must be contiguous",
                             path, _row(i))
        bounds = np.append(first, len(ids))
        groups = [(ids[a], np.arange(a, b)) for a, b in zip(bounds[:-1], bounds[1:],
                                                              strict=True)]
    else:
        win_ids, starts = _window_ids(table["timestamp"], tz, window)
        groups = [(n, np.asarray(r)) for n, r in
                  table.groupby(win_ids, sort=False).groups.items()]

    off = ((table["heating"] == 0) if "heating" in table else (table["q_hc"] <= Q_ON_W)).to_numpy()
    kinds_all = table["kind"].to_numpy() if "kind" in table else None
    check_labels(table, groups, lambda _, idx: None if kinds_all is None else kinds_all[idx[0]],
                 path, _row)
    check_phases(table, groups if explicit else None,
                 lambda idx: None if kinds_all is None else kinds_all[idx[0]], path, _row)
    emitter = check_emitter(table, path, _row)
    setpoint_all = (table["setpoint"].to_numpy(dtype=float) if "setpoint" in table else None)
    values = {c: table[c].to_numpy(dtype=float) for c in ("t_air", "t_out", "q_hc")}
    # every column a night reads, as arrays once (per night from the table: the whole column
    # converted once per night — a season of nights read a file many times over)
    phase = table[PHASE].to_numpy(dtype=object) if PHASE in table else None
    series = series_arrays(table)
    heating_given = "heating" in table
    extras = extra_columns(table)
    if "p_el_w" in extras:  # the heat pump's electricity: q_hc must be well above it
        why = electrical_problem(values["q_hc"], extras["p_el_w"])
        if why is not None:
            raise InputError(why, path, "column 'q_hc'")
    # a kind column's changes counted up to each row: a night's rows all of one kind unless
    # a change falls between its first and last row (then checked row by row)
    kind_changes = (None if kinds_all is None
                    else np.r_[0, np.cumsum(kinds_all[1:] != kinds_all[:-1])])
    pieces = []
    for night_id, idx in groups:
        if night_id == "":
            continue
        pre, idx = split_preheat(phase, idx)
        if len(idx) == 1 or len(pre) + len(idx) < 2:
            if explicit:
                raise InputError(f"night {night_id!r} has only one sample", path,
                                 _row(idx[0] if len(idx) else pre[0]))
            continue
        ends = [int(a[i]) for a in (pre, idx) if len(a) for i in (0, -1)]
        if kind_changes is not None and kind_changes[max(ends)] != kind_changes[min(ends)]:
            whole = np.r_[pre, idx]
            kinds = kinds_all[whole]
            changed = kinds != kinds[0]
            if changed.any():
                raise InputError(f"night {night_id!r} changes kind from {kinds[0]!r}",
                                 path, _row(whole[int(np.argmax(changed))]))
        pieces.append((night_id, pre, idx))
    # The pieces' first rows as Timestamps, boxed at once (one by one: ~8 µs each, a season's
    # household has ~60 pieces); without a night column a night starts at its window's start.
    firsts = [int(a[0]) for _, pre, idx in pieces
              for a in ((idx,) if explicit else ()) + (pre,) if len(a)]
    boxed = iter(stamps[firsts])
    nights: list[NightSamples] = []
    for night_id, pre, idx in pieces:
        # The pre-heat: the night's id and kind, a piece of its own (the IMP fit's night
        # starts at the window); its kind, without a kind column, that of the window's rows.
        night = None
        if len(idx):
            start = starts[night_id] if not explicit else next(boxed)
            night = _samples(night_id, idx, start, phase, series, heating_given, stamp_ns,
                             off, kinds_all, setpoint_all, values, extras, emitter=emitter)
            nights.append(night)
        if len(pre):
            nights.append(_samples(night_id, pre, next(boxed), phase, series,
                                   heating_given, stamp_ns, off, kinds_all, setpoint_all,
                                   values, extras, kind=None if night is None else night.kind,
                                   emitter=emitter))
    if not nights:
        what = "no night with two or more samples" if explicit else (
            f"no two samples inside one {window[0]:%H:%M}–{window[1]:%H:%M} window")
        raise InputError(what, path)
    return sorted(nights, key=lambda n: n.start)


def _samples(night_id, idx: np.ndarray, start: pd.Timestamp, phase: np.ndarray | None,
             series: dict, heating_given: bool, stamp_ns: np.ndarray, off: np.ndarray,
             kinds_all, setpoint_all, values: dict, extras: dict, kind: str | None = None,
             emitter: str = "") -> NightSamples:
    """The night (or its pre-heat, ``phase`` set) of the rows ``idx``, time 0 at ``start``;
    ``phase``, ``series``, ``values``, ``extras``: the file's columns as arrays."""
    pre = phase is not None and phase[int(idx[0])] == PREHEAT
    time_s = (stamp_ns[idx] - pd.Timestamp(start).as_unit("ns").value) / 1e9
    more: dict = {}
    if kinds_all is not None:
        kind = str(kinds_all[idx[0]])
    elif kind is None:
        kind = _infer_kind(time_s, off[idx])
        if not pre:
            more["not_held"] = not_held(kind, time_s, values["t_air"][idx], off[idx],
                                        heating_given, values["q_hc"][idx])
    setpoint = np.nan
    if setpoint_all is not None and np.isfinite(setpoint_all[idx]).any():
        setpoint = float(np.nanmedian(setpoint_all[idx]))
    t_air, extra = night_extras(extras, idx, values["t_air"][idx], values["t_out"][idx])
    more |= extra
    more |= defrost_fields(extras, idx, time_s, values["q_hc"][idx], Q_ON_W)
    if extras.get("defrost") is not None:
        more["defrost_share"] = np.asarray(extras["defrost"][idx], float)
    return NightSamples(
        night_id=str(night_id),
        kind=kind,  # type: ignore[arg-type]
        start=start,
        time_s=time_s,
        t_air_c=t_air,
        t_out_c=values["t_out"][idx],
        q_hc_w=values["q_hc"][idx],
        setpoint_c=setpoint,
        phase=PREHEAT if pre else "",
        emitter=emitter,
        **more,
        **series_fields(series, idx),
    )


def write_nights(nights: list[NightSamples], path: str | Path) -> Path:
    """Write nights as NIGHTS.csv (all optional columns; timestamps with their UTC offset).

    ``heating`` is 1 on normal nights and pre-heats and, on constrained nights, 1 only where
    Q_HC shows the heating back on. A pre-heat (``phase``) goes right before its night, as
    :func:`read_nights` gives them. :func:`read_nights` reads the file back into the same
    nights.
    """
    frames = []
    for night in nights:
        stamps = night.start + pd.to_timedelta(np.asarray(night.time_s, float), unit="s")
        q = np.asarray(night.q_hc_w, float)
        held = night.kind == "normal" or night.phase == PREHEAT  # the heating enabled
        heating = np.ones(len(q), int) if held else (q > Q_ON_W).astype(int)
        frame = pd.DataFrame({
            "timestamp": stamps.map(lambda t: t.isoformat()),
            "t_air": night.t_air_c, "t_out": night.t_out_c, "q_hc": q,
            "setpoint": night.setpoint_c, "heating": heating,
            "night": night.night_id, "kind": night.kind,
        })
        # The per-sample series the season model reads, where the night carries them.
        for col, values in (("dhw", night.dhw), ("defrost", night.defrost_share),
                            ("t_flow_c", night.t_flow_c), ("t_return_c", night.t_return_c),
                            ("t_flow_target_c", night.t_flow_target_c)):
            if values is not None:
                frame[col] = values
        if night.p_house_series_w is not None:
            frame["p_house_w"] = night.p_house_series_w
        elif np.isfinite(night.p_house_w):
            frame["p_house_w"] = night.p_house_w
        if night.kind == "owner":
            frame["label"] = night.label
        if any(n.phase for n in nights):
            frame[PHASE] = night.phase
        if any(n.emitter for n in nights):
            frame[EMITTER] = night.emitter
        frames.append(frame)
    path = Path(path)
    pd.concat(frames, ignore_index=True).to_csv(path, index=False, float_format="%.9g")
    return path
