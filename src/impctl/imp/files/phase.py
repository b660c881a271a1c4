"""The optional NIGHTS.csv column ``phase``: an IMP night's pre-heat rows.

``impctl export`` writes an IMP night's pre-heat — the heat pump raised to T_max before a
constrained night's switch-off, or held at the setpoint before a normal night — as the night's
first rows, marked ``phase`` = ``preheat``; every other row has an empty ``phase``. The reader
(:func:`~impctl.imp.files.nights_csv.read_nights`) gives the pre-heat as a
:class:`~impctl.imp.night.NightSamples` of its own: the night's id and kind, ``phase``
``preheat``, time 0 at its first row. The season model reads it (the house between the owner's
last row and the night is no gap); the IMP fit, the classifiers and the campaign do not
(:func:`~impctl.imp.night.split_owner`): their night starts at its window.

A ``phase`` other than ``preheat`` or empty, pre-heat rows after a row of the window, on an
owner night, or in a file without the ``night`` column refuse the file with one line naming
the row.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ...errors import InputError

PHASE = "phase"
#: The value of ``phase`` on an IMP night's pre-heat rows (empty on every other row).
PREHEAT = "preheat"


def check_phases(table: pd.DataFrame, groups, kind_of, path, row) -> None:
    """Refuse a bad ``phase`` (module docstring). ``groups``: (night id, row indices) of an
    explicit ``night`` column, None without one; ``kind_of(indices)``: the night's kind when
    the file says it, else None."""
    if PHASE not in table:
        return
    phases = table[PHASE].to_numpy(dtype=object)
    bad = (phases != "") & (phases != PREHEAT)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"column '{PHASE}': {phases[i]!r} is not '{PREHEAT}' or empty", path,
                         row(i))
    if groups is None:
        if (phases == PREHEAT).any():
            raise InputError(f"column '{PHASE}': pre-heat rows need the 'night' column (the "
                             "night they belong to)", path, row(int(np.argmax(phases == PREHEAT))))
        return
    for night_id, idx in groups:
        pre = phases[idx] == PREHEAT
        if not pre.any():
            continue
        after = pre & np.maximum.accumulate(~pre)  # a pre-heat row after a window row
        if after.any():
            raise InputError(f"column '{PHASE}': night {night_id!r} has a pre-heat row after "
                             "a row of its window (the pre-heat comes first)", path,
                             row(int(idx[int(np.argmax(after))])))
        if kind_of(idx) == "owner":
            raise InputError(f"column '{PHASE}': only IMP nights have a pre-heat (night "
                             f"{night_id!r} is an owner night)", path, row(int(idx[0])))


def split_preheat(phase: np.ndarray | None, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the pre-heat rows, the window's rows) of a night's rows ``idx`` (checked by
    :func:`check_phases`: the pre-heat rows come first); ``phase``: the file's ``phase``
    column (None without one)."""
    if phase is None:
        return idx[:0], idx
    n_pre = int(np.sum(phase[idx] == PREHEAT))
    return idx[:n_pre], idx[n_pre:]
