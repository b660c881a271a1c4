"""Is a finished night good data? Coverage, defrost, DHW priority, errors, missing sensors."""

from __future__ import annotations

import sqlite3
from datetime import datetime

from ..errors import sqlite_problem
from ..imp.protocol import MIN_NIGHT_H, Q_ON_W, SHORT_NIGHT
from ..store import Night, Store
from .heat_output import heat_output_problems
from .plan import NightPolicy, NightRequest

#: Working function code of domestic hot water (2001 = 1): heating is interrupted meanwhile.
_DHW = 1


def assess_night(store: Store, night_id: int, policy: NightPolicy,
                 ended: datetime | None = None) -> tuple[bool, list[str]]:
    """Judge the samples of one night inside its window, ended at ``ended`` (default: the
    stored end; the window's end when there is none).

    Returns
    -------
    (valid, reasons) — reasons say why a night is not valid, and note minor issues of a
    valid one. Thresholds: coverage ≥ ``policy.min_coverage`` of the expected samples up to the
    night's end; at least :data:`~impctl.imp.protocol.MIN_NIGHT_H` (3 h) of data (for
    constrained nights: after switch-off plus the emission lag, which is what the fit uses);
    defrost and DHW each ≤ 10 % of the samples;
    no error bits; T_air, T_out and Q_HC each missing in ≤ 10 % of the samples; Q_HC
    believable against electrical power, COP and compressor state, not stuck, within capacity
    (:mod:`.heat_output`). A constrained night whose only failing check is its length is
    marked :data:`~impctl.imp.protocol.SHORT_NIGHT`: its cooling is the season model's.
    """
    night = store.night(night_id)
    samples = [s for s in store.samples(night_id)
               if night.window_start <= s.ts <= night.window_end]
    reasons: list[str] = []
    # The end as it happened: a night ended at T_min is covered up to there, not to the
    # window's end (the verdict is judged before the end is stored with it).
    end = ended or night.ended or night.window_end
    covered_until = min(end, night.window_end)
    span_s = max(0.0, (covered_until - night.window_start).total_seconds())
    expected = span_s / policy.sample_interval_s
    # The fit uses a constrained night only from switch-off + emission lag, and needs
    # MIN_NIGHT_H of it; a night that reached T_min sooner is complete but carries too little
    # cooling. Measured as the fit measures it (fit.nights.data.prepare_nights): the span of
    # the complete samples from the night's first one + the lag, so a night valid here is
    # never one the fit then skips.
    usable_s = _usable_s([s for s in samples if s.ts <= end], night.kind,
                         policy.emission_lag_h)
    short = None
    if usable_s < MIN_NIGHT_H * 3600 - 1e-6:
        after = " after the emission lag" if night.kind == "constrained" else ""
        short = f"only {max(usable_s, 0) / 3600:.1f} h of data{after} (< {MIN_NIGHT_H:g} h)"
        reasons.append(short)
    if expected > 0:
        coverage = len(samples) / (expected + 1)
        if coverage < policy.min_coverage:
            reasons.append(f"coverage {coverage:.0%} < {policy.min_coverage:.0%}")
    if not samples:
        return False, reasons or ["no samples in the window"]
    n = len(samples)

    def share(pred) -> float:
        return sum(1 for s in samples if pred(s)) / n

    for label, pred in (
        ("defrost", lambda s: s.defrost),
        ("DHW priority interrupting heating", lambda s: s.working_function == _DHW),
    ):
        frac = share(pred)
        if frac > 0.10:
            reasons.append(f"{label} in {frac:.0%} of samples")
    if any(s.error_bits for s in samples):
        reasons.append("heat-pump error bits during the night")
    for label, attr in (("T_air", "t_air_c"), ("T_out", "t_out_c"), ("Q_HC", "q_hc_w")):
        frac = share(lambda s, a=attr: getattr(s, a) is None)
        if frac > 0.10:
            reasons.append(f"{label} missing in {frac:.0%} of samples")
    reasons.extend(heat_output_problems(samples))
    if night.kind == "constrained" and len(reasons) == 1 and reasons[0] == short:
        reasons.append(SHORT_NIGHT)
    return not reasons, reasons


def _usable_s(samples: list, kind: str, emission_lag_h: float) -> float:
    """Seconds between the first and the last sample the fit keeps: T_air, T_out and Q_HC all
    present; on a constrained night at least ``emission_lag_h`` [h] after the first sample
    (time 0 of the exported night) and before the heating resumed (Q_HC > Q_ON_W)."""
    if not samples:
        return 0.0
    t0 = samples[0].ts
    constrained = kind == "constrained"
    lag_s = emission_lag_h * 3600.0 if constrained else 0.0
    kept = []
    for s in samples:
        if None in (s.t_air_c, s.t_out_c, s.q_hc_w) or (s.ts - t0).total_seconds() < lag_s - 1e-6:
            continue
        if constrained and s.q_hc_w > Q_ON_W:
            break
        kept.append(s.ts)
    return (kept[-1] - kept[0]).total_seconds() if len(kept) >= 2 else 0.0


def record_end(store: Store, policy: NightPolicy, night_id: int, req: NightRequest, state: str,
               reasons: list[str], ended: datetime) -> tuple[Night, str | None]:
    """Store the night's end and verdict; returns the night and, when the store cannot
    record it (a full disk), why — the night is then built in memory, not valid, and stays
    "active" in the store until the next start marks it interrupted."""
    try:
        if state == "refused":
            store.end_night(night_id, state, ended, False, reasons)
        else:
            valid, why = assess_night(store, night_id, policy, ended)
            store.end_night(night_id, state, ended, valid and state == "done", reasons + why)
        return store.night(night_id), None
    except sqlite3.Error as exc:
        return Night(night_id, req.kind, req.setpoint_c, req.t_min_c, req.t_max_c,
                     req.window_start, req.window_end, state, req.source, False,
                     tuple(reasons), None, ended), sqlite_problem(exc)
