"""The season model: the 5R1C heat balance in demand form, as regressors of a linear problem.

ISO 13790's 5R1C has a massless air and surface node; eliminating the surface node leaves three
conductances between air, mass and outside (a star–delta transform): K_ao (air–outside: the
ventilation and the windows' path), K_am (air–mass) and K_mo (mass–outside), and one capacity
C_m at the mass. Read in *demand form* — the measured room temperature drives the model, the
heat is its output — the heat the house needs is

    Φ_room = K_ao·(T_air − T_out) + K_am·(T_air − T_m) − Φ_air
    τ_mm·dT_m/dt = w·T_air + (1 − w)·T_out + Φ_mass/(K_am + K_mo) − T_m

with w = K_am/(K_am + K_mo) and τ_mm = C_m/(K_am + K_mo): the mass is a low-pass filter of the
measured temperatures, so it is carried from day to night by what was measured, never simulated
open loop. The heat reaches the room through the emitter, a first-order lag τ_e of what the
meter reads (radiators minutes, a screed hours), less what a defrost drew from the water and a
positive-only meter did not read (D·defrost share):

    LP_τr(LP_τe(Φ_meter − D·defrost)) = LP_τr(Φ_room).

A record that holds the draw — a signed meter's, whose defrost steps go negative, or one whose
defrost steps were read from the flow–return spread (:mod:`..defrost`;
:meth:`~..record.SeasonRecord.meter_reads_defrosts`) — has it in Φ_meter already: there D is
0, not fitted. Free, D trades with the HLC, because the heat pump defrosts most on the cold
nights (with a signed meter, HLC P90 11.1 → 9.6 % on 200 households of seed 4444, 11.4 → 8.5 %
on seed 31: decision record 0040).

The second lag τ_r is the room's: the room sensor reads the air late (a first-order lag of
5–15 min in its housing) and the air and furniture take up heat before the walls do. The
balance is linear, so a lagged sensor is the same balance lagged as a whole: the model's
temperatures are the measured ones and the meter's side is lagged once more (the outdoor
temperature and the gains move too slowly for a lag of minutes to matter). Without it the
fast fall of a switch-off, read late, was taken for a slower house (τ and C_m −10 % on the
bench's development households).

The gains Φ = G_night or G_day (people asleep or about; the level also takes in the sensors'
offsets times the HLC — it is an intercept, not the gain) plus a slow part g(t) wandering from
day to day (linear between values g_k at local midnights; :mod:`.solve` puts a random-walk
prior on their steps) plus, where measured, the household electricity times a share s_p, all
split half to the air, half to the mass; plus each day's sun a_d·shape(hour) split f_s to the
air and 1 − f_s to the mass.

For given nonlinear parameters θ = (τ_mm, w, τ_e, f_s, τ_r) the balance is *linear* in
β = (K_ao, K_am, G_night, G_day, D, s_p, one initial mass and emitter state per segment,
a_1 … a_days, g_1 … g_k), so the fit solves β by least squares inside the search over θ
(variable projection). :func:`columns` filters the measured temperatures and the meter on the
5-min grid (the mass sees the switch-off within a block) and the gains' known shapes at the
likelihood's 30-min block scale (:func:`held_lowpass`), and gives the block means.

Derived: HLC = K_ao + K_am·(1 − w); K_mo = K_am·(1 − w)/w; C_m = τ_mm·K_am/w;
τ = C_m/(K_mo + K_am·K_ao/(K_am + K_ao)) (ISO's free-running time constant).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from ..record import NIGHT_HOURS, SeasonRecord, sun_shape

Array = NDArray[np.float64]

#: Share of the internal gains at the air node (ISO 13790 C.1: Φ_ia = 0.5 Φ_int).
AIR_SHARE = 0.5
#: Names of the nonlinear parameters (θ), in order, with their units.
THETA = ("tau_mm_s", "w", "tau_e_s", "f_sun", "tau_r_s")
#: Names of the fixed linear parameters (β) before the per-day and per-segment ones.
BETA = ("k_ao_w_per_k", "k_am_w_per_k", "g_night_w", "g_day_w", "defrost_w", "p_house_share")
#: Fewest usable blocks with the household electricity measured for it to be read [-].
P_HOUSE_MIN_SHARE = 0.8


def lowpass(x: Array, tau_s: float, step_s: float, runs: list[tuple[int, int]],
            then_tau_s: float | None = None) -> Array:
    """First-order low-pass y' = (x − y)/τ on each segment, starting at its first value
    (exact for inputs held over each step), then, with ``then_tau_s``, a second one on its
    output (one second-order filter: both start at rest at the first value). ``x`` (n,) or
    (m, n): time on the last axis; ``runs`` (start, end) of the segments (:func:`_runs`); NaN
    outside them."""
    b = math.exp(-step_s / max(tau_s, 1e-9))
    num, den = [1.0 - b], [1.0, -b]
    if then_tau_s is not None:
        b2 = math.exp(-step_s / max(then_tau_s, 1e-9))
        num, den = [(1.0 - b) * (1.0 - b2)], [1.0, -(b + b2), b * b2]
    # the filter's state at rest at a unit input (scipy.signal.lfilter_zi's, in closed form)
    rest = np.array([1.0 - num[0], *(-np.asarray(den[2:]))])
    out = np.full(x.shape, np.nan)
    # Runs of one length in one call (the IMP nights are cut alike): each row is the same
    # recursion as alone, and scipy's per-call cost is most of a short run's.
    by_length: dict[int, list[int]] = {}
    for lo, hi in runs:
        by_length.setdefault(hi - lo, []).append(lo)
    for n, starts in by_length.items():
        if len(starts) == 1:
            sel: slice | Array = slice(starts[0], starts[0] + n)
        else:
            sel = np.asarray(starts)[:, None] + np.arange(n)
        seg = x[..., sel]
        out[..., sel] = lfilter(num, den, seg, axis=-1, zi=seg[..., :1] * rest)[0]
    return out


def _runs(segments: NDArray[np.int64]) -> list[tuple[int, int]]:
    """(start, end) of each segment's steps."""
    ok = segments >= 0
    edges = np.flatnonzero(np.diff(np.r_[-2, segments, -2]) != 0)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True) if ok[a]]


@dataclass
class Design:
    """The fixed parts of one record the regressors are built from (computed once).

    Two time scales: the measured temperatures and the meter are filtered on the record's
    5-min grid (the mass sees a switch-off within a block); the gains' known shapes — night and
    day levels, each day's sun, the slow gain's knots — are held over each 30-min block and
    filtered exactly at that scale, which is six times less work and changes nothing the
    likelihood can see (its blocks are 30 min).
    """

    rec: SeasonRecord
    segments: NDArray[np.int64]       # the meter's runs: the emitter restarts after a gap
    runs: list[tuple[int, int]]
    stretch: NDArray[np.int64]        # the heat store's: short gaps bridged, whole blocks
    block_runs: list[tuple[int, int]]  # the stretches in blocks
    t_air_c: Array                    # bridged
    t_out_c: Array
    blocks: NDArray[np.bool_]         # usable blocks
    gains_b: Array      # (m, nb) block means of the gains' shapes: night, day, suns, knots,
    #                     the household electricity [W] (zeros when not measured)
    n_days: int
    n_knots: int
    dt_b: Array         # (nu,) block mean of T_air − T_out at the usable blocks [K]
    ta_b: Array         # (nu,) block mean of T_air [°C]
    defrost: Array      # the defrost share the draw D multiplies (zeros: the meter reads it)
    defrost_read: bool | None  # the record holds the draw (SeasonRecord.meter_reads_defrosts)
    # the filtered series of the last few θ: a finite-difference step moves one coordinate of
    # θ, so most of its filters are the base point's (a third of the search's work)
    filtered: dict = field(default_factory=dict, repr=False, compare=False)
    fixed: dict = field(default_factory=dict, repr=False, compare=False)

    def once(self, key: str, make):
        """``make()``, computed on the first call (what depends on the record alone)."""
        if key not in self.fixed:
            self.fixed[key] = make()
        return self.fixed[key]

    def remembered(self, key: tuple):
        """What :meth:`cached` keeps under ``key``, or None."""
        return self.filtered.get(key[0], {}).get(key)

    def cached(self, key: tuple, make):
        """``make()``, remembered under ``key`` for the next few calls (the last
        :data:`FILTERED_KEPT` of each kind, ``key[0]``)."""
        kind = self.filtered.setdefault(key[0], {})
        if key not in kind:
            if len(kind) >= FILTERED_KEPT:
                kind.pop(next(iter(kind)))
            kind[key] = make()
        return kind[key]

    @classmethod
    def of(cls, rec: SeasonRecord) -> Design:
        seg = rec.segments()
        stretch, ta, to = rec.stretches()
        k = rec.per_block
        nb = rec.n // k
        # a stretch starts and ends on block boundaries (a partial block is never usable)
        sb = np.full(nb, -1)
        whole = stretch[: nb * k].reshape(nb, k)
        full = (whole >= 0).all(axis=1) & (whole == whole[:, :1]).all(axis=1)
        sb[full] = whole[full, 0]
        aligned = np.repeat(sb, k)
        aligned = np.r_[aligned, np.full(rec.n - nb * k, -1)]
        h = rec.hour
        night = ((h >= NIGHT_HOURS[0]) | (h < NIGHT_HOURS[1])).astype(float)
        days = rec.day - rec.day.min()
        n_days = int(days.max()) + 1
        knots = knot_block_means(rec, nb)
        shapes = np.zeros((3 + n_days + len(knots), nb))

        def mean(x: Array) -> Array:
            return x[: nb * k].reshape((nb, k) + x.shape[1:]).mean(axis=1)

        shapes[0] = mean(night)
        shapes[1] = 1.0 - shapes[0]
        # each day's sun, block means (a block of another day's hours holds zeros)
        shapes[2:2 + n_days] = _block_sums(days[: nb * k], sun_shape(h)[: nb * k], n_days,
                                           nb, k) / k
        shapes[2 + n_days:-1] = knots
        blocks = rec.usable_blocks() & (sb >= 0)
        if len(rec.p_house_w) == rec.n:
            # the household electricity ends as heat in the house: a measured gain
            p = mean(rec.p_house_w)
            if blocks.any() and np.isfinite(p[blocks]).mean() >= P_HOUSE_MIN_SHARE:
                shapes[-1] = np.where(np.isfinite(p), p, np.nanmean(p[blocks]))
        read = rec.meter_reads_defrosts()
        return cls(rec, seg, _runs(seg), aligned, _runs(sb), ta, to, blocks,
                   np.ascontiguousarray(shapes), n_days, len(knots),
                   mean(ta - to)[blocks], mean(ta)[blocks],
                   np.zeros(rec.n) if read else np.nan_to_num(rec.defrost), read)

    def block_day(self) -> NDArray[np.int64]:
        """Local day of each usable block (the clusters of the interval)."""
        k = self.rec.per_block
        nb = len(self.blocks)
        return (self.rec.day[: nb * k].reshape(nb, k)[:, 0])[self.blocks]

    def block_mean(self, x: Array) -> Array:
        """Means of ``x`` ((n,) or (m, n): time on the last axis) over the usable likelihood
        blocks."""
        k = self.rec.per_block
        nb = len(self.blocks)
        xb = x[..., : nb * k].reshape(x.shape[:-1] + (nb, k)).mean(axis=-1)
        return xb[..., self.blocks]


#: Filtered series a :class:`Design` keeps of each kind (a base point and its five steps) [-].
FILTERED_KEPT = 12
#: Spacing of the slow gain's knots [s]: the occupants' heat wanders from day to day.
KNOT_S = 86400.0


def gain_knots(rec: SeasonRecord) -> Array:
    """Hat functions of the slow gain (n, k): piecewise linear between knots every
    :data:`KNOT_S` at local midnight, so a night sits on one knot and the level never jumps."""
    t = rec.day + rec.hour / 24.0                     # local days since the first midnight
    k = int(np.ceil(t.max())) + 1
    x = np.clip(t * 86400.0 / KNOT_S, 0, k - 1)
    lo = np.floor(x).astype(int)
    frac = x - lo
    out = np.zeros((rec.n, k))
    out[np.arange(rec.n), lo] = 1.0 - frac
    out[np.arange(rec.n), np.minimum(lo + 1, k - 1)] += frac
    used = out.any(axis=0)
    return out[:, used]


def _block_sums(row: NDArray[np.int64], w: Array, rows: int, nb: int, k: int) -> Array:
    """(rows, nb): the sums of weights ``w`` of the steps in each row (``row``) and block."""
    block = np.arange(len(w)) // k
    return np.bincount(row * nb + block, weights=w, minlength=rows * nb).reshape(rows, nb)


def knot_block_means(rec: SeasonRecord, nb: int) -> Array:
    """Block means of :func:`gain_knots` (knots, nb), without the (steps × knots) matrix."""
    t = rec.day + rec.hour / 24.0
    k = int(np.ceil(t.max())) + 1
    x = np.clip(t * 86400.0 / KNOT_S, 0, k - 1)
    lo = np.floor(x).astype(int)
    frac = x - lo
    hi = np.minimum(lo + 1, k - 1)
    used = (np.bincount(lo, weights=1.0 - frac, minlength=k)
            + np.bincount(hi, weights=frac, minlength=k)) > 0
    m = nb * rec.per_block
    sums = (_block_sums(lo[:m], 1.0 - frac[:m], k, nb, rec.per_block)
            + _block_sums(hi[:m], frac[:m], k, nb, rec.per_block))
    return sums[used] / rec.per_block


def held_lowpass(u: Array, tau_s: float, block_s: float,
                 runs: list[tuple[int, int]]) -> Array:
    """Block means of the first-order low-pass of inputs ``u`` (m, nb) held over each block,
    exact; each run starts with the state at its first input (as :func:`lowpass`)."""
    e = math.exp(-block_s / tau_s)
    f = tau_s / block_s * (1.0 - e)
    out = np.zeros_like(u)
    for lo, hi in runs:
        x = u[:, lo:hi]
        end = lfilter([1.0 - e], [1.0, -e], x, axis=1, zi=e * x[:, :1])[0]
        prev = np.concatenate([x[:, :1], end[:, :-1]], axis=1)
        out[:, lo:hi] = x + (prev - x) * f
    return out


def _block_decay(beta: float, k: int, steps: NDArray[np.int64]) -> Array:
    """Block means of β^i over blocks whose first step is ``steps`` after the run's start."""
    return beta ** steps * (1.0 - beta ** k) / (k * (1.0 - beta))


def _run_blocks(d: Design, stretches: bool) -> list[tuple[NDArray[np.int64], NDArray[np.int64]]]:
    """Per run of the heat store (``stretches``) or of the meter: the usable blocks inside it
    (indices) and their first steps counted from the run's start."""
    k = d.rec.per_block
    first = np.flatnonzero(d.blocks) * k            # first step of each usable block
    out = []
    if stretches:  # block runs: a block is inside when it starts inside
        for lo, hi in d.block_runs:
            sel = np.flatnonzero((first >= lo * k) & (first < hi * k))
            out.append((sel, first[sel] - lo * k))
    else:  # step runs: a block is inside when all its steps are
        for lo, hi in d.runs:
            sel = np.flatnonzero((first >= lo) & (first + k <= hi))
            out.append((sel, first[sel] - lo))
    return out


def column_names(d: Design) -> list[str]:
    """Names of :func:`columns`' regressors, in order."""
    return d.once("names", lambda: [
        *BETA, *(f"mass0_{i}" for i in range(len(d.block_runs))),
        *(f"emitter0_{i}" for i in range(len(d.runs))),
        *(f"sun_{i}_w" for i in range(d.n_days)), *(f"gain_{i}_w" for i in range(d.n_knots))])


def gain_family(d: Design) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """(column of each of ``d.gains_b``'s shapes in X, whether it is a day's sun). A shape's
    column is −(a·shape + w·(1 − a)·held_lowpass(shape)): a = f_sun for the sun, else
    :data:`AIR_SHARE` — the shape at the air, its low-pass (τ_mm) at the mass."""
    def make():
        n_s, n_e, nd = len(d.block_runs), len(d.runs), d.n_days
        first = len(BETA) + n_s + n_e
        col = np.r_[2, 3, first + np.arange(nd), first + nd + np.arange(d.n_knots), 5]
        sun = np.zeros(len(col), bool)
        sun[2:2 + nd] = True
        return col, sun
    return d.once("gain_family", make)


def gain_coefficients(theta: tuple[float, ...], d: Design) -> tuple[Array, Array]:
    """(α, β) of each shape's column α·shape + β·held_lowpass(shape) (:func:`gain_family`)."""
    w, f_sun = theta[1], theta[3]
    _, sun = gain_family(d)
    a = np.where(sun, f_sun, AIR_SHARE)
    return -a, -w * (1.0 - a)


def dense_groups(theta: tuple[float, ...], d: Design) -> list[tuple[tuple, Array, Array]]:
    """The regressors outside the gains' family, by what they depend on: (key, rows over the
    usable blocks, their columns in X; −1 marks y, the emitter-lagged meter reading). The
    temperature difference; the mass (τ_mm, w); the defrost and y (τ_e, τ_r); each stretch's
    initial heat store (τ_mm); each meter run's initial emitter (τ_e)."""
    tau_mm, w, tau_e, _f_sun, tau_r = theta
    r, dt, k = d.rec, d.rec.step_s, d.rec.per_block
    m_t = d.cached(("mass", tau_mm, w), lambda: d.block_mean(
        lowpass(w * d.t_air_c + (1.0 - w) * d.t_out_c, tau_mm, dt,
                d.once("stretch_runs", lambda: _runs(d.stretch)))))
    e = d.cached(("emitter", tau_e, tau_r), lambda: d.block_mean(lowpass(
        d.once("meter", lambda: np.stack([r.q_hc_w, d.defrost])), tau_e, dt, d.runs, tau_r)))
    n_s, n_e = len(d.block_runs), len(d.runs)

    def decays(which: str, beta: float, sign: float) -> Array:
        # Each stretch's own initial heat store: a free offset of the mass, decaying with
        # τ_mm; each run of the meter its own initial emitter: the filter starts at the run's
        # first reading, the water and the screed at whatever a pre-heat or a gap left them.
        runs = d.once(which, lambda: _run_blocks(d, which == "stretch_blocks"))
        out = np.zeros((len(runs), int(d.blocks.sum())))
        for i, (sel, steps) in enumerate(runs):
            out[i, sel] = sign * _block_decay(beta, k, steps)
        return out

    first = len(BETA)
    return [
        (("dt",), d.dt_b[None, :], np.array([0])),
        (("mass", tau_mm, w), (d.ta_b - m_t)[None, :], np.array([1])),
        (("emitter", tau_e, tau_r), e[::-1], np.array([4, -1])),
        (("stretch", tau_mm), d.cached(("stretch", tau_mm), lambda: decays(
            "stretch_blocks", math.exp(-dt / tau_mm), -1.0)), first + np.arange(n_s)),
        (("meter", tau_e), d.cached(("meter", tau_e), lambda: decays(
            "meter_blocks", math.exp(-dt / tau_e), 1.0)), first + n_s + np.arange(n_e)),
    ]


def columns(theta: tuple[float, ...], d: Design) -> tuple[Array, Array, list[str]]:
    """(X, y, names): the block means of the regressors and of the emitter-lagged meter reading
    for nonlinear parameters ``theta`` (:data:`THETA`), over the usable blocks."""
    tau_mm = theta[0]
    g = d.cached(("gains", tau_mm), lambda: held_lowpass(
        d.gains_b, tau_mm, d.rec.per_block * d.rec.step_s, d.block_runs)[:, d.blocks])
    shapes = d.once("shapes", lambda: d.gains_b[:, d.blocks])
    gcols, _ = gain_family(d)
    alpha, beta = gain_coefficients(theta, d)
    # Built row by row as Xᵀ: every write contiguous (X is handed on as its transpose).
    XT = np.empty((len(column_names(d)), len(d.dt_b)))
    for _key, rows, cols in dense_groups(theta, d):
        for row, col in zip(rows, cols, strict=True):
            if col >= 0:
                XT[col] = row
            else:
                y = row
    XT[gcols] = alpha[:, None] * shapes + beta[:, None] * g
    return XT.T, y, column_names(d)


def lumped(theta: tuple[float, ...], k_ao: float, k_am: float) -> dict[str, float]:
    """HLC [W/K], C_m [J/K], τ [h] and K_mo [W/K] of a solution (module docstring)."""
    tau_mm, w = theta[0], theta[1]
    k_mo = k_am * (1.0 - w) / w
    hlc = k_ao + k_am * (1.0 - w)
    c_m = tau_mm * k_am / w
    free = k_mo + k_am * k_ao / (k_am + k_ao) if k_am + k_ao > 0 else float("nan")
    return {"hlc_w_per_k": hlc, "c_m_j_per_k": c_m, "tau_h": c_m / free / 3600.0,
            "k_mo_w_per_k": k_mo}
