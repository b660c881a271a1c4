"""The optional NIGHTS.csv columns a night carries besides the fitted series.

* ``p_house_w`` — household electricity not used by the heat pump [W] (nearly all of it ends
  as heat indoors): the measured night gain (:mod:`impctl.imp.gain`);
* ``occupants`` — sleepers in the house (≈ 75 W each, :data:`impctl.imp.gain.SLEEPER_W`);
* ``t_rooms_c`` — mean of the room sensors [°C]: on a night where it is present it is the
  indoor temperature of the fit, the controller's own ``t_air`` kept as a cross-check;
* ``t_out_ref_c`` — a reference outdoor temperature [°C] (a weather service, a second
  sensor): the night's mean offset of ``t_out`` from it is reported;
* ``night_gain_w`` — the night gain declared for the household [W] (known, as ``impctl fit
  --night-gain-w``): a fleet's per-household declaration;
* ``defrost`` — 1 while the heat pump defrosts (Kronoterm register 2011), else 0: the hours
  of defrost, and of those the hours whose heat reading did not go negative (the draw not
  read: the heat reads high, :func:`defrost_fields`);
* ``p_el_w`` — the heat pump's own electrical power [W]: where it is given, a ``q_hc`` that
  is this electrical power rather than the heat is refused
  (:func:`impctl.imp.plausibility.electrical_problem`).

A cell that is empty, not a number or outside its plausible range is missing (NaN), never a
number: these columns inform the fit, they do not refuse a file whose series are sound.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..tables import text_floats

#: The optional columns and their plausible ranges (outside: missing).
EXTRA_COLUMNS: dict[str, tuple[float, float]] = {
    "p_house_w": (0.0, 30_000.0),
    "occupants": (0.0, 20.0),
    "t_rooms_c": (-40.0, 60.0),
    "t_out_ref_c": (-60.0, 60.0),
    "night_gain_w": (0.0, 2000.0),   # impctl.imp.gain.NIGHT_GAIN_LIMITS_W
    "defrost": (0.0, 1.0),
    "p_el_w": (0.0, 30_000.0),
}
#: Share of a night's rows that must carry a value for the night to have it.
PRESENT_FRACTION = 0.8


def extra_columns(table: pd.DataFrame) -> dict[str, np.ndarray]:
    """The optional columns present in ``table`` as float arrays, implausible cells NaN."""
    out = {}
    for col, (lo, hi) in EXTRA_COLUMNS.items():
        if col not in table:
            continue
        column = table[col]
        # a copy: the implausible cells are set to NaN below
        values = np.array(column.to_numpy(dtype=float, na_value=np.nan)
                          if pd.api.types.is_numeric_dtype(column) else text_floats(column))
        values[~np.isfinite(values) | (values < lo) | (values > hi)] = np.nan
        out[col] = values
    return out


def _present(x: np.ndarray) -> bool:
    return len(x) > 0 and float(np.isfinite(x).mean()) >= PRESENT_FRACTION


def night_extras(extras: dict[str, np.ndarray], idx: np.ndarray, t_air_c: np.ndarray,
                 t_out_c: np.ndarray) -> tuple[np.ndarray, dict]:
    """The rows ``idx`` of one night: (its indoor temperature [°C], the NightSamples fields
    ``p_house_w`` (and its rows, ``p_house_series_w``), ``occupants``, ``night_gain_w``,
    ``t_air_offset_k``, ``t_out_offset_k``).

    The indoor temperature is the room sensors' mean where ``t_rooms_c`` is present on the
    night (its missing rows filled with ``t_air_c`` less the night's mean offset), else the
    controller's ``t_air_c``. A column counts for a night only when at least
    :data:`PRESENT_FRACTION` of its rows carry a value."""
    fields: dict = {}
    for col in ("p_house_w", "occupants", "night_gain_w"):
        x = extras.get(col)
        if x is not None and _present(x[idx]):
            fields[col] = float(np.nanmean(x[idx]))
    if "p_house_w" in fields:
        fields["p_house_series_w"] = np.asarray(extras["p_house_w"][idx], float)
    rooms = extras.get("t_rooms_c")
    if rooms is not None and _present(rooms[idx]):
        r = rooms[idx]
        offset = float(np.nanmean(t_air_c - r))
        t_air_c = np.where(np.isfinite(r), r, t_air_c - offset)
        fields["t_air_offset_k"] = offset
    ref = extras.get("t_out_ref_c")
    if ref is not None and _present(ref[idx]):
        fields["t_out_offset_k"] = float(np.nanmean(t_out_c - ref[idx]))
    return t_air_c, fields


def defrost_fields(extras: dict[str, np.ndarray], idx: np.ndarray, time_s: np.ndarray,
                   q_hc_w: np.ndarray, read_below_w: float) -> dict[str, float]:
    """The NightSamples fields ``defrost_h`` and ``defrost_unread_h`` [h] of the rows ``idx``
    of one night (``time_s`` [s], ``q_hc_w`` [W] those rows'), when the ``defrost`` column is
    present on the night. A row stands for the interval up to the next one (the last row for
    the median interval). The defrost rows did not read the heat the defrosts drew from the
    water when none of them is below −``read_below_w`` [W]: a signed reading shows itself by
    its negative rows, and a row that is a mean over a defrost and some heating may still be
    positive."""
    flag = extras.get("defrost")
    if flag is None or len(idx) < 2:
        return {}
    rows = flag[idx]
    if not _present(rows):
        return {}
    on = rows >= 0.5
    if not on.any():   # most nights: nothing to add up
        return {"defrost_h": 0.0, "defrost_unread_h": 0.0}
    step = np.diff(np.asarray(time_s, float))
    # the last row's interval (the median one) counts only where that row defrosts
    span_h = np.append(step, np.median(step) if on[-1] else 0.0) / 3600.0
    signed = bool((on & (np.asarray(q_hc_w, float) < -read_below_w)).any())
    hours = float(span_h[on].sum())
    return {"defrost_h": hours, "defrost_unread_h": 0.0 if signed else hours}
