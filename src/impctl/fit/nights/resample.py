"""Rows finer than the fit needs, combined into blocks (numpy only).

1-minute rows hold no more about a house's hours-long mass dynamics than 5-minute rows, but they
cost five times the integration. Finer rows are therefore combined before the fit:

* nodes every ``step_s`` from the night's first sample (a node only where the block holds a
  sample, so gaps stay gaps);
* temperatures at a node: the mean of the readings within ±step/2 of it — an estimate of the
  value *at* the node (the centred window cancels the slope; only curvature·step²/24 remains,
  < 0.01 K for the slowest air transients the fit models) with √n less reading noise;
* heat power at a node: the exact time-weighted mean over the block up to the next node, the
  "mean until the next row" convention of the instant stamps. Averaging power over 5–15 minutes
  is what field practice recommends anyway for cycling heat pumps (real-houses.md §3, §7).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...imp.night import NightSamples


def median_step_s(night: NightSamples) -> float:
    """Median spacing of a night's rows [s] (inf with fewer than two rows)."""
    t = np.asarray(night.time_s, float)
    return float(np.median(np.diff(t))) if len(t) > 1 else float("inf")


def coarsen(night: NightSamples, step_s: float) -> NightSamples:
    """``night`` on nodes every ``step_s`` [s] (module docstring); unchanged if its rows are
    not finer than about ``step_s`` (median spacing ≥ 2/3 of it)."""
    t = np.asarray(night.time_s, float)
    if step_s <= 0 or len(t) < 3 or median_step_s(night) >= step_s / 1.5:
        return night
    t_air = np.asarray(night.t_air_c, float)
    t_out = np.asarray(night.t_out_c, float)
    q = np.asarray(night.q_hc_w, float)
    block = np.floor((t - t[0]) / step_s + 1e-9).astype(int)
    nodes = t[0] + np.unique(block) * step_s
    nodes[-1] = min(nodes[-1], t[-1])
    lo = np.searchsorted(t, nodes - step_s / 2, side="left")
    hi = np.searchsorted(t, nodes + step_s / 2, side="right")
    c_air = np.concatenate([[0.0], np.cumsum(t_air)])
    c_out = np.concatenate([[0.0], np.cumsum(t_out)])
    n = hi - lo
    # ∫q dt with q held from each row to the next: the energy up to time x by interpolation
    energy = np.concatenate([[0.0], np.cumsum(q[:-1] * np.diff(t))])
    ends = np.append(nodes[1:], t[-1])
    span = ends - nodes
    e = np.interp(ends, t, energy) - np.interp(nodes, t, energy)
    q_node = np.where(span > 0, e / np.where(span > 0, span, 1.0),
                      q[np.searchsorted(t, nodes, side="right") - 1])
    return dataclasses.replace(night, time_s=nodes, t_air_c=(c_air[hi] - c_air[lo]) / n,
                               t_out_c=(c_out[hi] - c_out[lo]) / n, q_hc_w=q_node)
