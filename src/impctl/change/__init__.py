"""Has the house changed? A step in the heat-loss coefficient, found in the owner's nights.

A window left open for days raises the HLC; loft insulation lowers it. Either shows in the
owner's ordinary nights as more (or less) heat for the same indoor–outdoor difference. The
nights become one row each (:mod:`.nights`); the test (:mod:`.glr`) looks for one step in the
HLC among them and says from which night and by how much [W/K].

>>> from impctl.change import detect_change
>>> found = detect_change(nights)          # doctest: +SKIP
"""

from .glr import (
    MIN_NIGHTS,
    MIN_SIDE,
    SIZE_SCALE,
    THRESHOLD,
    THRESHOLD_NO_HOUSE,
    Z95,
    Change,
    change_of,
    detect_change,
    detect_sequence,
    glr,
    threshold_for,
    whitener,
)
from .nights import MEMORY_H, WINDOW_H, NightRows, night_rows

__all__ = ["MEMORY_H", "MIN_NIGHTS", "MIN_SIDE", "SIZE_SCALE", "THRESHOLD", "THRESHOLD_NO_HOUSE",
           "WINDOW_H", "Z95", "Change", "NightRows", "change_of", "detect_change",
           "detect_sequence", "glr", "night_rows", "threshold_for", "whitener"]
