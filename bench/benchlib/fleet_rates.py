"""Throughput of a fleet run from its FLEET parts (for the fleet benches)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd


def steady_rate(out: Path, started: float) -> tuple[float, float]:
    """(households/s once every worker runs, seconds from the call to the first batch): per
    worker, the households of its batches after its first over the time from its first to its
    last, summed over the workers — the throughput without the start (the plugin loading torch
    in each worker, the first batches' imports), which a longer run spreads thinner. From the
    FLEET parts' modification times (each is renamed into place when its batch is done) and
    their ``worker`` column. Taken over all parts at once, the batches the other workers had
    in hand at the first one's end counted as made after it: with three batches of 64 a
    worker, 31 households/s where two workers at 0.078 CPU-s a household make 25.6."""
    parts = sorted(out.glob("part-*.parquet"), key=lambda p: p.stat().st_mtime)
    if len(parts) < 2:
        return float("nan"), float("nan")
    by_worker: dict[str, list[tuple[float, int]]] = {}
    for p in parts:
        rows = pd.read_parquet(p, columns=["household", "worker"])
        by_worker.setdefault(str(rows["worker"].iloc[0]), []).append(
            (p.stat().st_mtime, len(rows)))
    rate = 0.0
    for done in by_worker.values():
        if len(done) >= 2:
            rate += sum(n for _, n in done[1:]) / max(done[-1][0] - done[0][0], 1e-9)
    return (rate if rate > 0 else float("nan")), parts[0].stat().st_mtime - started
