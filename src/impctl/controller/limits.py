"""When a night's samples end it or abort it.

Aborts (:class:`NightAbort`, the night not valid): the heat-pump link or the indoor
temperature lost for longer than ``link_lost_limit_s``, an alarm, the room under the comfort
floor. Ends (a reason returned): a constrained night that reached T_min, or whose cooling
trend will reach it before the next sample could see it (:func:`.plan.anticipated_end`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime

from ..heatpump import Snapshot
from .plan import NightPolicy, NightRequest, anticipated_end
from .poll import alarm_reason


class NightAbort(Exception):
    """Ends the running night at once, not valid; its restore follows."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


@dataclass
class SampleLimits:
    """One night's limits on its samples.

    Parameters
    ----------
    policy : NightPolicy
    floor_c : the room temperature under which the night aborts [°C]; None until the night's
        first write sets it (T_min − margin until then)
    trend : (POSIX time [s], T_air [°C]) of the samples since the switch-off
    """

    policy: NightPolicy
    floor_c: float | None = None
    trend: list[tuple[float, float]] = field(default_factory=list)

    def set_floor(self, req: NightRequest, owner_setpoint_c: float | None) -> None:
        """The comfort floor: T_min − margin, but never above the owner's own setpoint − ΔT
        − margin. A normal night at 24 °C starts from a house held at the owner's 21 °C;
        that is not a cold house and must not abort the night."""
        floor = (req.t_min_c if owner_setpoint_c is None
                 else min(req.t_min_c, owner_setpoint_c - req.comfort_band_k))
        self.floor_c = floor - self.policy.abort_margin_k

    def judge(self, snap: Snapshot | None, req: NightRequest, switched_off: bool,
              now: datetime, last_good_read: datetime | None,
              last_t_air: datetime | None) -> str | None:
        """Raise :class:`NightAbort`, return why the night ends, or None to go on.

        ``last_good_read`` / ``last_t_air``: when the link last answered / the last sample
        with an indoor temperature was taken (None: not yet this night).
        """
        limit_s = self.policy.link_lost_limit_s
        if snap is None:
            lost_s = (now - (last_good_read or now)).total_seconds()
            if lost_s > limit_s:
                raise NightAbort(f"heat-pump link lost for {lost_s / 60:.0f} min")
            return None
        alarm = alarm_reason(snap)
        if alarm:
            raise NightAbort(alarm)
        t_air = snap.t_air_c.value
        if t_air is None:
            # A missing sample is judged by the assessment (coverage); a night without its
            # indoor temperature for as long as the link-lost limit is aborted (blind).
            blind_s = (now - (last_t_air or now)).total_seconds()
            if blind_s > limit_s:
                raise NightAbort(f"no indoor temperature for {blind_s / 60:.0f} min "
                                 f"({snap.t_air_c.reason})")
            return None
        floor = self.floor_c
        if floor is None:
            floor = req.t_min_c - self.policy.abort_margin_k
        if t_air < floor:
            raise NightAbort(f"T_air {t_air:.1f} °C below T_min − margin ({floor:.1f} °C)")
        if req.kind == "constrained" and switched_off and t_air <= req.t_min_c:
            return f"reached T_min {req.t_min_c:.1f} °C"
        if req.kind == "constrained" and switched_off:
            self.trend.append((now.timestamp(), t_air))
            return anticipated_end(self.trend, self.policy, req.t_min_c)
        return None
