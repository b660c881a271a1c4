"""Steady blocks: the heated rows averaged over the night (22:00–06:00) and the two halves of
the day (06:00–14:00, 14:00–22:00) of the local clock, one block per setpoint held in them.

A heat pump cycles, defrosts and charges hot water; an emitter stores heat — a screed for
hours, under a room thermostat from one burst of heating to the next. Averaged over hours,
the heat it delivered and the water and room temperatures it did it at describe the house and
its emitter; a block is kept only when it is such an average:

* every row has the heating on (not a constrained night, ``heating`` not 0) and a heat reading;
* its rows cover at least :data:`MIN_BLOCK_H` hours (a campaign's held night, 22:00–05:00,
  is one block);
* hot water took at most :data:`MAX_DHW_SHARE` of it;
* the setpoint did not change in it nor in the :data:`SETTLE_H` before (the house and the
  emitter are still charging or discharging after a step);
* the room moved by at most :data:`MAX_ROOM_CHANGE_K` across it.

A defrost draws heat from the water, which a meter that integrates positive heat only never
reads, and the heat pump then heats the water back: the rows of a defrost and the
:data:`RECOVERY_MIN` minutes after it are left out of the block's means (the heat, the water
and the room of the other rows describe the emitter as it works between defrosts), and at
least :data:`MIN_CLEAN` of the block must remain.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ...imp.features import Q_ON_W
from .rows import HEATED_KINDS

#: Block length [h], aligned on the local clock at 22:00 (22–06, 06–14, 14–22).
BLOCK_H = 8.0
#: Local hour the blocks are aligned on [h]: the first block is the night.
NIGHT_START_H = 22.0
#: Fewest hours a block's rows must cover [h].
MIN_BLOCK_H = 4.0
#: Largest share of a block spent heating hot water.
MAX_DHW_SHARE = 0.1
#: Time after a setpoint change before a block counts as steady [h].
SETTLE_H = 2.0
#: Largest change of the room temperature across a block [K].
MAX_ROOM_CHANGE_K = 1.0
#: Share of a block's rows that must carry an optional column for its mean to count.
PRESENT = 0.8
#: Minutes after a defrost left out with it (the heat pump heats the water back).
RECOVERY_MIN = 10.0
#: Share of a block that must remain once defrosts are left out.
MIN_CLEAN = 0.5


def _clean(rows: pd.DataFrame) -> np.ndarray:
    """Rows neither in a defrost nor within :data:`RECOVERY_MIN` after one."""
    t = seconds(rows["timestamp"])
    defrost = rows["defrost"].to_numpy(dtype=float) >= 0.5
    last = pd.Series(np.where(defrost, t, np.nan)).ffill().to_numpy()
    return ~defrost & ~(t - last <= RECOVERY_MIN * 60.0)


def seconds(stamps: pd.Series) -> np.ndarray:
    """POSIX seconds of tz-aware timestamps (whatever their unit)."""
    return (stamps - pd.Timestamp(0, tz="UTC")).dt.total_seconds().to_numpy()


def heated(rows: pd.DataFrame) -> np.ndarray:
    """Rows with the heating on: a heated night kind (or unlabelled), ``heating`` not 0."""
    kind = rows["kind"].astype(str)
    ok_kind = kind.isin(HEATED_KINDS).to_numpy() | (kind == "").to_numpy()
    heating = rows["heating"].to_numpy(dtype=float)
    return ok_kind & ~(heating == 0.0) & np.isfinite(rows["q_hc"].to_numpy(dtype=float))


def _settled(rows: pd.DataFrame) -> np.ndarray:
    """Rows at least :data:`SETTLE_H` after the last setpoint change (True without one)."""
    sp = rows["setpoint"].to_numpy(dtype=float)
    t = seconds(rows["timestamp"])
    changed = np.zeros(len(sp), bool)
    prev = pd.Series(sp).ffill().to_numpy()
    changed[1:] = np.abs(np.diff(np.nan_to_num(prev, nan=-99.0))) > 0.05
    last = np.where(changed, t, np.nan)
    last = pd.Series(last).ffill().to_numpy()
    return ~(t - last < SETTLE_H * 3600.0)


def _most_common(values: np.ndarray) -> str:
    """The most common string of ``values`` ("" for none)."""
    if not len(values):
        return ""
    names, counts = np.unique(values, return_counts=True)
    return str(names[int(np.argmax(counts))])


def _mean_if_present(x: pd.Series) -> float:
    v = x.to_numpy(dtype=float)
    ok = np.isfinite(v)
    return float(v[ok].mean()) if len(v) and ok.mean() >= PRESENT else np.nan


def row_step_s(rows: pd.DataFrame) -> float:
    """The median spacing of the rows [s] (300 s for a single row)."""
    d = np.diff(seconds(rows["timestamp"]))
    d = d[d > 0]
    return float(np.median(d)) if len(d) else 300.0


def steady_blocks(rows: pd.DataFrame) -> pd.DataFrame:
    """One row per steady block (module docstring), in time order.

    Columns: ``start`` (local, the block's grid start), ``night`` (the 22:00–06:00 block),
    ``evening`` (the local date the block's night or day began: the blocks of one night share
    it), ``hours`` (covered), ``q_w``, ``t_air_c``, ``t_out_c``, ``t_water_c`` (mean of flow
    and return), ``spread_k`` (flow − return), ``t_flow_run_c`` (flow while the heat pump
    delivers heat), ``p_el_w``, ``t_flow_target_c``, ``setpoint_c`` (NaN where a column is
    absent), ``kind``.
    """
    step = row_step_s(rows)
    need_rows = MIN_BLOCK_H * 3600.0 / step
    ts = rows["timestamp"]
    wall = ts.dt.tz_localize(None)
    shift = pd.Timedelta(hours=24.0 - NIGHT_START_H)
    key = (wall + shift).dt.floor(f"{int(BLOCK_H * 60)}min") - shift
    sp_key = rows["setpoint"].round(1).fillna(-99.0)
    frame = rows.assign(_key=key, _sp=sp_key, _ok=heated(rows) & _settled(rows),
                        _clean=_clean(rows), _dhw=rows["dhw"].fillna(0.0))
    water = (rows["t_flow_c"] + rows["t_return_c"]) / 2.0
    frame = frame.assign(_water=water, _spread=rows["t_flow_c"] - rows["t_return_c"],
                         _flow_run=rows["t_flow_c"].where(rows["q_hc"] > Q_ON_W))
    frame = frame[frame["_ok"].to_numpy()]
    out = []
    for (start, _), g in frame.groupby(["_key", "_sp"], sort=True):
        if len(g) < need_rows or g["_dhw"].mean() > MAX_DHW_SHARE:
            continue
        if g["_clean"].sum() < MIN_CLEAN * len(g):
            continue
        hours = len(g) * step / 3600.0
        g = g[g["_clean"].to_numpy()]
        q = float(g["q_hc"].mean())
        air = g["t_air"].to_numpy(dtype=float)
        if q <= Q_ON_W or abs(air[-1] - air[0]) > MAX_ROOM_CHANGE_K:
            continue
        sp = g["setpoint"].to_numpy(dtype=float)
        start = pd.Timestamp(start)
        kinds = g["kind"].astype(str).to_numpy()
        out.append({
            "start": start, "night": start.hour == int(NIGHT_START_H),
            "evening": start.date(), "hours": hours,
            "q_w": q, "t_air_c": float(air.mean()), "t_out_c": float(g["t_out"].mean()),
            "t_water_c": _mean_if_present(g["_water"]),
            "spread_k": _mean_if_present(g["_spread"]),
            "t_flow_run_c": (float(g["_flow_run"].mean()) if g["_flow_run"].notna().any()
                             else np.nan),
            "p_el_w": _mean_if_present(g["p_el_w"]),
            "t_flow_target_c": _mean_if_present(g["t_flow_target_c"]),
            "setpoint_c": float(np.nanmean(sp)) if np.isfinite(sp).any() else np.nan,
            "kind": _most_common(kinds),
        })
    columns = ["start", "night", "evening", "hours", "q_w", "t_air_c", "t_out_c", "t_water_c",
               "spread_k", "t_flow_run_c", "p_el_w", "t_flow_target_c", "setpoint_c", "kind"]
    return pd.DataFrame(out, columns=columns).sort_values("start", ignore_index=True)


def hourly(rows: pd.DataFrame, column: str, mask: np.ndarray | None = None) -> pd.DataFrame:
    """Hourly means of ``column`` and of ``t_out`` over the rows (``mask``: those only), hours
    with the column on at least :data:`PRESENT` of their rows; columns ``hour``, ``t_out_c``,
    ``value``, ``setpoint_c``, ``kind``."""
    sel = rows if mask is None else rows[mask]
    if sel.empty:
        return pd.DataFrame(columns=["hour", "t_out_c", "value", "setpoint_c", "kind"])
    key = sel["timestamp"].dt.floor("1h")
    grouped = sel.assign(_key=key, _has=sel[column].notna()).groupby("_key", sort=True)
    frame = pd.DataFrame({
        "t_out_c": grouped["t_out"].mean(),
        "value": grouped[column].mean(),
        "share": grouped["_has"].mean(),
        "setpoint_c": grouped["setpoint"].mean(),
        "kind": grouped["kind"].first(),
    })
    frame = frame[frame["share"] >= PRESENT].drop(columns="share")
    return frame.rename_axis("hour").reset_index()
