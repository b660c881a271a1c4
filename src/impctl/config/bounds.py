"""Upper (and lower) bounds a person would defend for the numbers of ``config.toml`` that the
sections' own checks leave open: the night's length, the pre-heat, the campaign's nights, the
clock. Each bound says why; :func:`bound_problems` adds one line per value outside them.

The heat pump's link and write policy are bounded where they are read
(:mod:`impctl.heatpump.config`, :mod:`impctl.modbus.config`; the write budget against the
controller's EEPROM endurance there), the ``[mqtt]`` durations in :mod:`impctl.mqtt.config`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

#: Night window [h]: at least 1 h (a shorter night holds too little cooling to be a night at
#: all; the fit wants MIN_NIGHT_H = 3 h of it) and at most 12 h — 19:00 to 07:00 already; a
#: longer heating-off window takes the heat from a home in the daytime.
NIGHT_WINDOW_H = (1.0, 12.0)
#: Pre-heat [h]: the default 2 h brings T_air to T_max; 4 h covers a slow underfloor house.
#: More heats the home above the owner's setpoint for half a day for no information.
PREHEAT_MAX_H = 4.0
#: Outdoor band of a night [°C]: −40 °C lies below the heating design temperature of any
#: European site (EN 12831 national annexes reach about −30 °C); above 20 °C outdoors a house
#: needs no heating, so no night could carry information.
T_OUT_BAND_C = (-40.0, 20.0)
#: Nights one campaign may ask of a household: 60 is two winter months. The fixed plan runs 5,
#: the benches never needed more than 8; a number in the hundreds is a typo, not a plan.
NIGHTS_MAX = 60
#: Different normal setpoints one plan may cycle through: ten 1 K steps already span the
#: heat pump's clamp of room setpoints (10–30 °C) at its widest useful part.
NORMAL_SETPOINTS_MAX = 10
#: ``campaign.min_each_kind`` [nights]: the fit needs one of each kind; ten of each is already
#: a third of NIGHTS_MAX spent before the campaign may stop.
MIN_EACH_KIND_MAX = 10
#: ``campaign.misfire_grace_s`` [s]: a night whose start was missed by more than the longest
#: window (12 h) has no window left.
MISFIRE_GRACE_MAX_S = NIGHT_WINDOW_H[1] * 3600.0
#: ``clock.speed``: at 100,000× one millisecond of real time (about a Modbus round trip on
#: loopback) is 100 simulated seconds, longer than a sample interval; faster cannot be sampled.
CLOCK_SPEED_MAX = 100_000.0
#: ``clock.wall_epoch_s`` [POSIX s]: before 2100-01-01 (a typo in the exponent is not a date).
WALL_EPOCH_MAX_S = 4_102_444_800.0


def window_hours(start_min: int, end_min: int) -> float:
    """Length of a local HH:MM-HH:MM window [h]; an end before the start crosses midnight."""
    return ((end_min - start_min) % (24 * 60)) / 60.0


def bound_problems(cfg: Any, window: tuple[int, int] | None,
                   bad: Callable[[str, str], None]) -> None:
    """Every bound of this module that ``cfg`` violates, one ``bad(key, text)`` each.

    ``window`` is the night window in minutes after midnight, None when it could not be read
    (then its length is not checked again).
    """
    night, camp, clock = cfg.night, cfg.campaign, cfg.clock
    if window is not None and window[0] != window[1]:
        hours = window_hours(*window)
        lo, hi = NIGHT_WINDOW_H
        if not lo <= hours <= hi:
            bad("night.window", f"{night.window!r} lasts {hours:.4g} h; a night window lasts "
                f"{lo:g}–{hi:g} h (longer takes the heat from a home in daytime)")
    if not 0 <= night.preheat_h <= PREHEAT_MAX_H:
        bad("night.preheat_h", f"must lie in 0–{PREHEAT_MAX_H:g} h, got {night.preheat_h:g}")
    t_lo, t_hi = T_OUT_BAND_C
    for key in ("t_out_min_c", "t_out_max_c"):
        value = getattr(night, key)
        if not t_lo <= value <= t_hi:
            bad(f"night.{key}", f"must lie in {t_lo:g}…{t_hi:g} °C (below: colder than any "
                                f"heating design; above: no heating needed), got {value:g}")
    nights = [("campaign.max_nights", camp.max_nights),
              ("campaign.constrained_nights", camp.constrained_nights),
              ("campaign.normal_nights_per_setpoint", camp.normal_nights_per_setpoint),
              ("campaign.stall_nights", camp.stall_nights),
              ("campaign.max_invalid_nights", camp.max_invalid_nights)]
    over = False
    for key, value in nights:
        if value > NIGHTS_MAX:
            over = True
            bad(key, f"{value} nights: at most {NIGHTS_MAX} (two winter months) are asked of "
                     "a household")
    planned = camp.constrained_nights + len(camp.normal_setpoints_c) * \
        camp.normal_nights_per_setpoint
    if not over and planned > NIGHTS_MAX:
        bad("campaign.normal_nights_per_setpoint",
            f"the fixed plan asks for {planned} nights (constrained_nights + "
            f"normal_setpoints_c × normal_nights_per_setpoint); at most {NIGHTS_MAX}")
    if len(camp.normal_setpoints_c) > NORMAL_SETPOINTS_MAX:
        bad("campaign.normal_setpoints_c", f"{len(camp.normal_setpoints_c)} setpoints: at "
                                           f"most {NORMAL_SETPOINTS_MAX}")
    if camp.min_each_kind > MIN_EACH_KIND_MAX:
        bad("campaign.min_each_kind", f"must be at most {MIN_EACH_KIND_MAX}, got "
                                      f"{camp.min_each_kind}")
    if camp.misfire_grace_s > MISFIRE_GRACE_MAX_S:
        bad("campaign.misfire_grace_s", f"must be at most {MISFIRE_GRACE_MAX_S:g} s (the "
            "longest night window): a night missed by more has no window left")
    if clock.speed > CLOCK_SPEED_MAX:
        bad("clock.speed", f"must be at most {CLOCK_SPEED_MAX:g}×, got {clock.speed:g}")
    if clock.wall_epoch_s > WALL_EPOCH_MAX_S:
        bad("clock.wall_epoch_s", f"must be a POSIX second before 2100 (at most "
                                  f"{WALL_EPOCH_MAX_S:.0f}), got {clock.wall_epoch_s:g}")
