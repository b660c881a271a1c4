"""Throughput of a fleet run from its FLEET parts (for the fleet benches)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd


def steady_rate(out: Path, started: float) -> tuple[float, float]:
    """(households/s between the first and the last finished batch, seconds from the call to
    the first batch): the throughput once every worker runs, without the start (the plugin
    loading torch in each worker, the first batches' imports), which a longer run spreads
    thinner. From the FLEET parts' modification times (each is renamed into place when its
    batch is done)."""
    parts = sorted(out.glob("part-*.parquet"), key=lambda p: p.stat().st_mtime)
    if len(parts) < 2:
        return float("nan"), float("nan")
    first, last = parts[0].stat().st_mtime, parts[-1].stat().st_mtime
    after = sum(pd.read_parquet(p, columns=["household"]).shape[0] for p in parts[1:])
    return after / max(last - first, 1e-9), first - started
