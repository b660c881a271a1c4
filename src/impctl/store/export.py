"""Stored nights → the measured-data format read by ``impctl classify`` and ``impctl fit``.

Columns: ``timestamp`` (ISO 8601, UTC offset), ``t_air`` and ``t_out`` [°C], ``q_hc`` [W thermal],
``setpoint`` [°C], ``heating`` (1 normal night, 0 constrained), ``night`` (id), ``kind``.
Only samples inside each night's window are written (not the preheat before it), and those
with a missing T_air, T_out or Q_HC are left out (the format has no missing values).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

from .db import Store

COLUMNS = ("timestamp", "t_air", "t_out", "q_hc", "setpoint", "heating", "night", "kind")


def nights_rows(store: Store, night_ids: Iterable[int] | None = None,
                valid_only: bool = True) -> list[dict]:
    """One dict per usable sample of the selected nights (valid ones by default)."""
    nights = store.nights(ids=night_ids, valid=True if valid_only else None)
    rows = []
    for night in nights:
        for s in store.samples(night.id):
            # Only the window: the preheat before it (heating on, also on constrained nights)
            # is not part of the night; `impctl fit` takes a night's first row as its start
            # (the switch-off of a constrained night).
            if not night.window_start <= s.ts <= night.window_end:
                continue
            if s.t_air_c is None or s.t_out_c is None or s.q_hc_w is None:
                continue
            rows.append({
                "timestamp": s.ts.isoformat(), "t_air": s.t_air_c, "t_out": s.t_out_c,
                "q_hc": s.q_hc_w, "setpoint": night.setpoint_c,
                "heating": int(night.kind == "normal"), "night": night.id, "kind": night.kind,
            })
    return rows


def export_nights(store: Store, out: Path, fmt: str, night_ids: Iterable[int] | None = None,
                  valid_only: bool = True) -> int:
    """Write the selected nights to ``out`` as CSV or Parquet, atomically; returns the row count."""
    import pandas as pd

    df = pd.DataFrame(nights_rows(store, night_ids, valid_only), columns=list(COLUMNS))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", dir=out.parent)
    os.close(fd)
    try:
        if fmt == "csv":
            df.to_csv(tmp, index=False)
        elif fmt == "parquet":
            df.to_parquet(tmp, index=False)
        else:
            raise ValueError(f"unknown format {fmt!r}")
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return len(df)
