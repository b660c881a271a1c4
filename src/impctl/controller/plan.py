"""What one night should do, and the rules it runs under (units in the names)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from ..imp import protocol as _protocol


class NightRefused(Exception):
    """The night did not start: the heat pump or the weather is not fit for it."""


@dataclass(frozen=True)
class NightRequest:
    """One IMP night to run.

    Attributes
    ----------
    kind : {"constrained", "normal"}
    setpoint_c : T_set [°C]; a constrained night runs from T_max = T_set + ΔT to T_min = T_set − ΔT
    window_start, window_end : absolute instants (time zone-aware); the window's length is
        real elapsed time, so a night across a DST change lasts 6 or 8 hours of wall clock
    comfort_band_k : ΔT [K]; default the protocol's band
        (:data:`impctl.imp.protocol.DEFAULT_BAND_K`), as in the gateway's ``[night]``
    source : "schedule" or "trigger"
    campaign_seq : the campaign plan entry the night serves, if any
    """

    kind: str
    setpoint_c: float
    window_start: datetime
    window_end: datetime
    comfort_band_k: float = _protocol.DEFAULT_BAND_K
    source: str = "schedule"
    campaign_seq: int | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("constrained", "normal"):
            raise ValueError(f"kind must be constrained or normal, got {self.kind!r}")
        if self.window_start.tzinfo is None or self.window_end.tzinfo is None:
            raise ValueError("window instants must be time zone-aware")
        # instants, not wall-clock times: two times of one zone compare as wall clocks
        if not self.window_end.timestamp() > self.window_start.timestamp():
            raise ValueError("window_end must follow window_start")

    @property
    def t_max_c(self) -> float:
        """Upper comfort limit T_set + ΔT [°C]."""
        return self.setpoint_c + self.comfort_band_k

    @property
    def t_min_c(self) -> float:
        """Lower comfort limit T_set − ΔT [°C]."""
        return self.setpoint_c - self.comfort_band_k

    @property
    def duration_h(self) -> float:
        """Window length in absolute time [h]."""
        # Not `window_end - window_start`: with the same tzinfo on both (the local zone)
        # Python subtracts wall-clock times, so a night across a DST change would be 7 h.
        return (self.window_end.timestamp() - self.window_start.timestamp()) / 3600.0


@dataclass(frozen=True)
class NightPolicy:
    """How nights run; every field from the ``[night]`` config section.

    Attributes
    ----------
    sample_interval_s : one snapshot per interval [s]
    abort_margin_k : abort when T_air < T_min − margin [K]
    link_lost_limit_s : abort when the last good read is older than this [s]
    t_out_min_c, t_out_max_c : outdoor band a night may start in [°C]
    constrained_action : "loop_off" (loop-1 mode 0, DHW unaffected) or "setpoint_floor"
    setpoint_floor_c : loop-1 setpoint used by "setpoint_floor" [°C]
    preheat_h : the setpoint (T_max on constrained nights, T_set on normal ones) is written
        this long before the window, so the house starts the window settled [h]
    start_grace_s : how long refusal conditions (defrost, alarm, outdoor band) may be
        re-checked before the night is given up [s]
    deadline_grace_s : hard deadline after the window's end [s]
    min_coverage : fraction of the expected samples a valid night needs
    emission_lag_h : the paper's emitter lag after switch-off [h] (for the assessment)
    restore_timeout_s : how long a restore keeps retrying a lost link before giving up for
        now (the journal keeps it pending for the next attempt) [s]
    anticipate_s : a constrained night also ends when the trend of T_air (least squares over
        the last ``trend_window_s``) reaches T_min within this time [s]: the room sensor lags,
        and radiators or a screed must warm up again before the room does, so a house that
        is still falling fast keeps falling for a while after the restore. 0 = end at T_min.
    switch_off_min_k : a constrained night switches the heating off only if T_air is at least
        this far above T_min at the window's start [K]; a house that the preheat could not
        lift that far would only drop under T_min at once and keep falling after the restore
    anticipate_within_k : the trend counts only this close above T_min [K] (not in the fast
        drop right after the switch-off, while the emitter cools)
    trend_window_s : span of the T_air trend [s]
    """

    sample_interval_s: float = 60.0
    abort_margin_k: float = 0.5
    link_lost_limit_s: float = 900.0
    t_out_min_c: float = -25.0
    t_out_max_c: float = 8.0
    constrained_action: str = "loop_off"
    setpoint_floor_c: float = 18.0
    preheat_h: float = _protocol.DEFAULT_PREHEAT_H
    start_grace_s: float = 1800.0
    deadline_grace_s: float = 600.0
    min_coverage: float = 0.8
    emission_lag_h: float = 1.0
    restore_timeout_s: float = 3600.0
    anticipate_s: float = _protocol.ANTICIPATE_S
    switch_off_min_k: float = _protocol.SWITCH_OFF_MIN_K
    anticipate_within_k: float = _protocol.ANTICIPATE_WITHIN_K
    trend_window_s: float = _protocol.TREND_WINDOW_S


#: The T_air trend of the anticipated end needs samples over at least this span [s].
MIN_TREND_SPAN_S = _protocol.MIN_TREND_SPAN_S


def anticipated_end(trend: list[tuple[float, float]], policy: NightPolicy,
                    t_min_c: float) -> str | None:
    """Why a constrained night ends now although T_air is still above T_min, or None.

    ``trend`` holds (POSIX s, T_air °C) readings since the switch-off, the newest last; readings
    older than ``policy.trend_window_s`` are dropped from it. The night ends when the
    least-squares trend over at least :data:`MIN_TREND_SPAN_S` reaches T_min within
    ``policy.anticipate_s`` while T_air is within ``policy.anticipate_within_k`` of T_min: the
    room sensor lags, and radiators or a screed must warm up again
    before the room does, so a room still falling fast keeps falling after the restore.
    """
    now_s, t_air = trend[-1]
    trend[:] = [(t, v) for t, v in trend if now_s - t <= policy.trend_window_s]
    if (policy.anticipate_s <= 0 or now_s - trend[0][0] < MIN_TREND_SPAN_S
            or t_air > t_min_c + policy.anticipate_within_k):
        return None
    mean_t = sum(t for t, _ in trend) / len(trend)
    mean_v = sum(v for _, v in trend) / len(trend)
    slope = (sum((t - mean_t) * (v - mean_v) for t, v in trend)
             / sum((t - mean_t) ** 2 for t, _ in trend))  # K/s
    if _protocol.anticipates_t_min(t_air, slope, t_min_c, policy.anticipate_within_k,
                                   policy.anticipate_s):
        return (f"T_min {t_min_c:.1f} °C anticipated: T_air {t_air:.1f} °C falling "
                f"{-slope * 3600:.2f} K/h")
    return None


def preheat_short(snap, req: NightRequest, policy: NightPolicy) -> str | None:
    """Why a constrained night must not switch the heating off (T_air, as last read, less than
    ``policy.switch_off_min_k`` above T_min at the window's start), or None."""
    t_air = None if snap is None else snap.t_air_c.value
    if t_air is None or t_air >= req.t_min_c + policy.switch_off_min_k:
        return None
    return (f"preheat reached only {t_air:.1f} °C (< T_min + {policy.switch_off_min_k:g} K): "
            "heating left on")
