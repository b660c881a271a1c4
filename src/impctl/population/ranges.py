"""Parameter ranges the classifiers put a house into (the paper's Table III), and their labels."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError

Ranges = Mapping[str, tuple[tuple[float, float], ...]]

#: The paper's Table III ranges: floor_area [m²], c_f [1e5 J/(m²K)], u_walls [W/(m²K)].
DEFAULT_RANGES: dict[str, tuple[tuple[float, float], ...]] = {
    "floor_area": ((60.0, 100.0), (100.0, 200.0), (200.0, 300.0)),
    "c_f": ((0.8, 1.65), (1.65, 3.7)),
    "u_walls": ((0.2, 1.0), (1.0, 2.0)),
}
#: Units of the parameters that can be classified.
UNITS = {
    "floor_area": "m²",
    "c_f": "1e5 J/(m²K)",
    "u_walls": "W/(m²K)",
    "u_windows": "W/(m²K)",
    "wall_height": "m",
}
#: The paper's names for the c_f ranges (display only).
CF_NAMES = {(0.8, 1.65): "LIGHT", (1.65, 3.7): "HEAVY"}
#: The paper's Table III: parameter → (training accuracy, test accuracy).
PAPER_TABLE_III = {"floor_area": (0.93, 0.87), "c_f": (0.85, 0.78), "u_walls": (0.86, 0.84)}


def range_label(lo: float, hi: float) -> str:
    """Label of one range, e.g. ``"60-100"``."""
    return f"{lo:g}-{hi:g}"


def labels_of(ranges: tuple[tuple[float, float], ...]) -> list[str]:
    """Labels of a parameter's ranges, in order."""
    return [range_label(lo, hi) for lo, hi in ranges]


def validate_ranges(ranges: Ranges) -> dict[str, tuple[tuple[float, float], ...]]:
    """Check ranges: known parameters, ≥ 2 ranges each, increasing and contiguous.

    Contiguity keeps every sampled house inside exactly one range (the population is drawn over
    the hull of each parameter's ranges).

    Raises
    ------
    InputError
        Naming the parameter and the problem.
    """
    out: dict[str, tuple[tuple[float, float], ...]] = {}
    if not ranges:
        raise InputError("no parameter ranges given", place="ranges")
    for name, rs in ranges.items():
        if name not in UNITS:
            raise InputError(f"cannot classify {name!r} (known: {', '.join(UNITS)})",
                             place="ranges")
        rs = tuple((float(lo), float(hi)) for lo, hi in rs)
        if len(rs) < 2:
            raise InputError("needs at least two ranges", place=f"ranges '{name}'")
        for (lo, hi), nxt in zip(rs, rs[1:] + ((None, None),), strict=True):
            if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo < hi):
                raise InputError(f"range ({lo:g}, {hi:g}) must satisfy 0 < low < high",
                                 place=f"ranges '{name}'")
            if nxt[0] is not None and nxt[0] != hi:
                raise InputError(f"ranges must be contiguous: {hi:g} then {nxt[0]:g}",
                                 place=f"ranges '{name}'")
        out[name] = rs
    return out


def bin_values(values: ArrayLike, ranges: tuple[tuple[float, float], ...]) -> NDArray[np.int64]:
    """Index of the range each value falls in (a shared edge goes to the upper range).

    Values below the first or above the last range are clipped to it.
    """
    edges = np.array([lo for lo, _ in ranges[1:]])
    return np.searchsorted(edges, np.asarray(values, dtype=float), side="right").astype(np.int64)


def hull(ranges: tuple[tuple[float, float], ...]) -> tuple[float, float]:
    """(lowest low, highest high) of a parameter's ranges."""
    return ranges[0][0], ranges[-1][1]
