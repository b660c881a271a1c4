"""A simulated season as the gateway would export it: one household's nights (NIGHTS rows).

The daemon records the house read-only whenever no IMP night runs, nor its pre-heat: one owner
record per local day from noon to noon, the IMP night's own span left out, labelled with what
spoiled its night (:attr:`Season.labels`). The IMP nights are their window's rows — a constrained
night up to where the gateway ended it; one that reached T_min too soon for the IMP fit is
labelled :data:`~impctl.imp.protocol.SHORT_NIGHT` (the store's export keeps valid nights and
those). Rows are interval means (``timestamps = "interval"``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ...imp.night import NightSamples
from ...imp.protocol import SHORT_NIGHT
from .season import Season


def household_nights(s: Season, h: int, upto_sample: int | None = None) -> list[NightSamples]:
    """Household ``h``'s owner records (named by the day their noon starts) and IMP nights up
    to sample ``upto_sample`` (exclusive; all when None), in time order."""
    n = s.t_air_c.shape[0] if upto_sample is None else min(upto_sample, s.t_air_c.shape[0])
    per = int(round(3600 / s.sample_s))
    preheat = int(round(s.config.preheat_h * per))
    imp = np.zeros(n, bool)      # rows an IMP night, its pre-heat or its restore took
    spans: list[tuple[int, int, str, str, float]] = []
    labels = np.full(n, "", dtype=object)
    for j, (date, kinds, a, b) in enumerate(s.nights):
        kind = str(kinds[h])
        if a >= n:
            break
        if kind == "owner":
            labels[a:min(b, n)] = s.labels[j, h]
            continue
        end = b
        if kind == "constrained" and s.stop_sample[j, h] >= 0:
            end = int(s.stop_sample[j, h])
        imp[max(a - preheat, 0):min(end, n)] = True
        # switched off and ended by T_min before the IMP fit's hours (else it never started)
        label = SHORT_NIGHT if kind == "constrained" and not s.valid[j, h] else ""
        if end - a >= 2 and end <= n:
            spans.append((a, end, kind, date, float(s.t_set_c[j, h]), label))
    out = [_night(s, h, a, b, kind, f"{date} {kind}", sp, lab)
           for a, b, kind, date, sp, lab in spans]
    hours = (s.index.hour + s.index.minute / 60.0).to_numpy()
    noon = np.flatnonzero(hours[:n] == 12.0)
    edges = [0, *[int(x) for x in noon if x > 0], n]
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        rows = np.flatnonzero(~imp[a:b]) + a
        if len(rows) < 2:
            continue
        lab = next((str(x) for x in labels[rows] if x), "")
        day = (s.index[a] - pd.Timedelta(hours=12)).date()
        out.append(_night(s, h, rows, None, "owner", f"{day} owner", np.nan, lab))
    return sorted(out, key=lambda x: x.start)


def _night(s: Season, h: int, a, b, kind: str, night_id: str, setpoint: float,
           label: str) -> NightSamples:
    rows = np.arange(a, b) if b is not None else np.asarray(a)
    start = pd.Timestamp(s.index[rows[0]])
    t = np.asarray((s.index[rows] - start).total_seconds(), float)
    return NightSamples(
        night_id=night_id, kind=kind, start=start, time_s=t,  # type: ignore[arg-type]
        t_air_c=s.t_air_c[rows, h], t_out_c=s.t_out_c[rows, h], q_hc_w=s.q_hc_w[rows, h],
        setpoint_c=setpoint, p_house_w=float(np.mean(s.p_house_w[rows, h])),
        p_house_series_w=s.p_house_w[rows, h],
        dhw=s.dhw[rows, h].astype(float), defrost_share=s.defrost[rows, h].astype(float),
        label=label,
        t_flow_c=None if s.t_flow_c is None else s.t_flow_c[rows, h],
        t_return_c=None if s.t_return_c is None else s.t_return_c[rows, h])
