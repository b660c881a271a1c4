"""The season's record as the season model reads it: one regular grid of the gateway's rows.

The gateway records the house around the clock (the owner's days and nights, kind ``owner``, and
its own IMP nights). :class:`SeasonRecord` puts every row on one regular grid of ``step_s``
(5 min) — means of the samples in each step, NaN where nothing was recorded — and says which
30-min blocks the likelihood may use and why the others are left out:

* a hot-water charge (space heating paused, the meter may read the tank) and the hour after it
  (the emitter refills);
* a night the owner's own changes or a missing reading spoiled (its ``label``);
* a constrained night the gateway judged invalid;
* a gap: the record is cut into segments, each with its own initial heat store.

No torch, no pandas: arrays in, arrays out. Units: °C, W, s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..imp.protocol import Q_ON_W

Array = NDArray[np.float64]

#: Grid step of the record [s] (the gateway's owner rows).
STEP_S = 300.0
#: Block over which the model's heat balance is compared [s].
BLOCK_S = 1800.0
#: After a hot-water charge, the emitter refills: blocks left out [s].
DHW_AFTER_S = 3600.0
#: A gap up to this long is bridged for the heat store: the room and outdoor temperatures are
#: interpolated across it (an IMP night's pre-heat, a restart) [s]; a longer one starts a new
#: stretch with a heat store of its own.
MAX_BRIDGE_S = 4 * 3600.0
#: Share of the defrost steps that must read negative heat for the meter to count as signed
#: [-] (:meth:`SeasonRecord.meter_reads_defrosts`).
SIGNED_SHARE = 0.1
#: Local hours of the night level of internal gains [h] (people asleep).
NIGHT_HOURS = (22.0, 7.0)
#: Local hours of daylight for the solar gains [h] (a winter day) [assumption].
SUN_HOURS = (8.0, 16.0)


def sun_shape(hour_local: Array) -> Array:
    """Clear-day shape of the solar gain at local hour ``hour_local`` [h]: a half-sine over
    :data:`SUN_HOURS`, 1 at its middle [-] — only its daily amplitude is fitted."""
    h = np.asarray(hour_local, float)
    span = SUN_HOURS[1] - SUN_HOURS[0]
    inside = (h >= SUN_HOURS[0]) & (h <= SUN_HOURS[1])
    return np.where(inside, np.clip(np.sin(np.pi * (h - SUN_HOURS[0]) / span), 0.0, None), 0.0)


@dataclass
class SeasonRecord:
    """One household's season on a regular grid (arrays of length ``n`` at ``step_s``).

    Attributes
    ----------
    t0_s : epoch seconds of the first step's start
    hour : local hour of each step's middle [h]
    day : local day number of each step (0 = the first)
    t_air_c, t_out_c : room and outdoor temperature, step means [°C] (NaN: not recorded)
    q_hc_w : heat output read by the meter, step mean [W] (NaN: not recorded)
    defrost : share of the step the heat pump defrosted [0–1] (0 when not logged)
    kind : per step "owner", "constrained", "normal" or "" (not recorded)
    night_id : per step the record (night) it belongs to ("" when none)
    excluded : per step why its block is left out of the likelihood ("" when used)
    p_house_w : household electricity, step mean [W] (NaN when not measured)
    t_water_c : the heating water's mean temperature, (flow + return)/2, step mean [°C]
        (NaN where the heat pump did not report both; empty when no row did)
    t_spread_k : the flow–return spread, flow − return, step mean [K] (NaN and empty as
        ``t_water_c``)
    defrost_from_spread : the defrost steps' heat was read from the spread, the meter reading
        positive heat only (:mod:`.defrost`)
    spread_unread : why the spread was not read where the draw stays estimated ("" else)
    """

    t0_s: float
    step_s: float
    hour: Array
    day: NDArray[np.int64]
    t_air_c: Array
    t_out_c: Array
    q_hc_w: Array
    defrost: Array
    kind: NDArray[np.str_]
    night_id: NDArray[np.object_]
    excluded: NDArray[np.object_]
    p_house_w: Array = field(default_factory=lambda: np.zeros(0))
    t_water_c: Array = field(default_factory=lambda: np.zeros(0))
    t_spread_k: Array = field(default_factory=lambda: np.zeros(0))
    defrost_from_spread: bool = False
    spread_unread: str = ""

    @property
    def n(self) -> int:
        """Steps on the grid."""
        return len(self.t_air_c)

    @property
    def per_block(self) -> int:
        """Grid steps per likelihood block."""
        return int(round(BLOCK_S / self.step_s))

    def meter_reads_defrosts(self) -> bool | None:
        """Whether the heat meter reads the heat a defrost draws from the water: True when
        steps with a defrost read below −:data:`~impctl.imp.protocol.Q_ON_W` — at least two of
        them and :data:`SIGNED_SHARE` of all (a signed meter shows itself so: 41–88 % of its
        defrost steps on the realistic plant; one odd reading does not make a meter signed) —,
        False when the record has defrosts and too few such steps (a positive-only meter, or
        one whose defrosts hide in steps of heating: the draw is then fitted), None without a
        defrost. True as well once the defrost steps' heat was read from the flow–return
        spread (:mod:`.defrost`)."""
        on = self.defrost > 0
        if not on.any():
            return None
        if self.defrost_from_spread:
            return True
        with np.errstate(invalid="ignore"):
            negative = int((self.q_hc_w[on] < -Q_ON_W).sum())
        return negative >= 2 and negative >= SIGNED_SHARE * int(on.sum())

    def segments(self) -> NDArray[np.int64]:
        """Segment number of each step: a new segment after a gap (a step with T_air, T_out or
        the heat reading missing, or longer gaps); -1 for the missing steps themselves."""
        ok = np.isfinite(self.t_air_c) & np.isfinite(self.t_out_c) & np.isfinite(self.q_hc_w)
        start = ok & ~np.r_[False, ok[:-1]]
        seg = np.cumsum(start) - 1
        return np.where(ok, seg, -1)

    def stretches(self) -> tuple[NDArray[np.int64], Array, Array]:
        """(stretch number of each step, -1 outside; T_air and T_out with the bridged gaps
        interpolated [°C], T_air's steps undone by :func:`unstep`): the heat store runs on
        through gaps up to :data:`MAX_BRIDGE_S`."""
        ok = np.isfinite(self.t_air_c) & np.isfinite(self.t_out_c)
        idx = np.flatnonzero(ok)
        stretch = np.full(self.n, -1)
        ta, to = self.t_air_c.copy(), self.t_out_c.copy()
        if not len(idx):
            return stretch, ta, to
        resolution = resolution_k(self.t_air_c)
        jump = np.diff(idx) * self.step_s > MAX_BRIDGE_S + self.step_s
        number = np.r_[0, np.cumsum(jump)]
        for k in range(int(number[-1]) + 1):
            mine = idx[number == k]
            lo, hi = int(mine[0]), int(mine[-1]) + 1
            stretch[lo:hi] = k
            span = np.arange(lo, hi)
            ta[lo:hi] = unstep(np.interp(span, mine, self.t_air_c[mine]), resolution)
            to[lo:hi] = np.interp(span, mine, self.t_out_c[mine])
        return stretch, ta, to

    def usable_blocks(self) -> NDArray[np.bool_]:
        """Blocks whose every step is recorded, in one segment and not excluded."""
        k = self.per_block
        nb = self.n // k
        seg = self.segments()[: nb * k].reshape(nb, k)
        exc = (self.excluded[: nb * k] != "").reshape(nb, k)
        whole = (seg >= 0).all(axis=1) & (seg == seg[:, :1]).all(axis=1)
        return whole & ~exc.any(axis=1)

    def owner_windows(self, hours: tuple[float, float],
                      also: tuple[Array, ...] = ()) -> list[NDArray[np.bool_]]:
        """Per owner night whose window of local ``hours`` [h] is whole — every step there
        recorded (T_air, the meter and each of ``also`` finite) and none left out — the mask of
        its steps, in day order."""
        h0, h1 = hours
        inside = (self.hour >= h0) & (self.hour < h1) & (self.kind == "owner")
        ok = inside & (self.excluded == "") & np.isfinite(self.t_air_c) & np.isfinite(self.q_hc_w)
        for x in also:
            ok &= np.isfinite(x)
        want = int(round((h1 - h0) * 3600 / self.step_s))
        out = []
        for day in np.unique(self.day[inside]):
            sel = ok & (self.day == day)
            if sel.sum() >= want and not (inside & (self.day == day) & ~ok).any():
                out.append(sel)
        return out

    def exclusion_counts(self) -> dict[str, float]:
        """Hours left out of the likelihood, by reason [h]."""
        out: dict[str, float] = {}
        for reason in set(self.excluded) - {""}:
            out[str(reason)] = float(np.sum(self.excluded == reason)) * self.step_s / 3600.0
        return out


def exclude_after(flag: NDArray[np.bool_], steps: int) -> NDArray[np.bool_]:
    """``flag`` widened by ``steps`` steps after each flagged step."""
    if steps <= 0:
        return flag.copy()
    window = np.convolve(flag.astype(float), np.ones(steps + 1), mode="full")[: len(flag)]
    return window > 0


#: Resolutions a coarse room sensor reports in, largest first [K].
COARSE_RESOLUTIONS_K = (1.0, 0.5, 0.25, 0.2)
#: Share of the readings on a resolution's grid for the sensor to be read as that coarse [-]:
#: a 0.5 K unit's rows are 90 % on its grid (an IMP night's 1-min samples, averaged into a
#: row, fall between), a 0.1 K sensor's 20 % on the 0.5 K grid and 50 % on the 0.2 K one.
ON_GRID_SHARE = 0.8


def resolution_k(t_c: Array) -> float | None:
    """The room sensor's resolution [K] when it is coarse (at least :data:`ON_GRID_SHARE` of the
    finite readings on one of :data:`COARSE_RESOLUTIONS_K`), else None."""
    y = np.asarray(t_c, dtype=float)
    y = y[np.isfinite(y)]
    if len(y) < 2:
        return None
    for q in COARSE_RESOLUTIONS_K:
        if np.mean(np.abs(y / q - np.round(y / q)) < 1e-6) >= ON_GRID_SHARE:
            return q
    return None


def unstep(t_c: Array, resolution: float | None) -> Array:
    """A coarse room sensor's steps undone: the temperature between its readings [°C].

    Some room units report whole half kelvins. Read as it is, a room held at 20.2 °C is
    20.0 °C for hours and then, for a tenth of a kelvin, 20.5 °C — a jump the model has to
    explain with a kilowatt into the mass. A reading that moves by one step of the sensor's
    ``resolution`` [K] or less changed when the air crossed the midpoint of the two values
    (less: a row that averages readings over the change): this puts that midpoint at the
    change and the run of equal readings on each side at its value in its middle, linear
    between (on the development households with 0.5 K sensors: HLC 9 → 6 %, P90 29 → 24 %).
    A larger jump (a new setpoint) stays a jump; without a coarse resolution (None) the
    readings come back as they were.
    """
    y = np.asarray(t_c, dtype=float).copy()
    if resolution is None or len(y) < 2:
        return y
    change = np.flatnonzero(np.diff(y) != 0) + 1   # the first step of each later run
    # at most one step: a change of the air (a row averaged over a change falls between);
    # more is a new setpoint
    one = np.abs(y[change] - y[change - 1]) <= resolution * (1 + 1e-6)
    starts, ends = np.r_[0, change], np.r_[change, len(y)]
    mid = (starts + ends - 1) / 2.0
    # each run: its value from its middle towards a one-step change, from its end otherwise
    left = np.where(np.r_[False, one], mid, starts)
    right = np.where(np.r_[one, False], mid, ends - 1)
    t = np.concatenate([left, right, change[one] - 0.5])
    v = np.concatenate([y[starts], y[starts],
                        (y[change[one] - 1] + y[change[one]]) / 2.0])
    order = np.argsort(t, kind="stable")
    return np.interp(np.arange(len(y), dtype=float), t[order], v[order])
