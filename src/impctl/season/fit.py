"""The season fit: HLC, τ and C_m of a house from everything the gateway recorded.

:func:`fit_season` reads a :class:`~.record.SeasonRecord` (:func:`~.nights.record_from_nights`)
with the demand-form 5R1C (:mod:`.projection.columns`, :mod:`.projection.solve`) and gives each
quantity a 95 % interval: the day-clustered sandwich covariance carried to log HLC, log τ and
log C_m by the delta method, scaled by :data:`INTERVAL_SCALE` and combined with a model-error
floor (:data:`MODEL_FLOOR`) — more nights shrink the statistical part, not what the model leaves
out of a real house (a second thermal mass, the furniture, the sun's real shape, the emitter's
own capacity). Both are estimated per quantity on simulated seasons that the bench's tables do
not use — 450 realistic households (seeds 31, 77, 4343) cut after 7, 14, 28 and 56 owner nights
and 100 with the household electricity measured (seed 31) cut after 14 and 28
(``bench/season.py --calibrate … --json``, pooled by ``--calibrate-from``): at least 92 %
coverage at every count of every variant, the narrowest median interval of those
(decision 0038). Every count: the sandwich part shrinks with the nights and the model's own
error does not, so a pooled coverage hid too-narrow intervals at 56 nights behind too-wide ones
at 7.

The energy signature on the same owner nights (:func:`signature`) is reported beside it: the
baseline the season model has to beat. Units in every name.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from threadpoolctl import ThreadpoolController

from ..change import detect_change
from ..imp.protocol import EMITTER_KINDS
from .emitter import (
    emitter_kind,
    lag_bound_s,
    tau_e_max_s,
    water_decay_h,
    water_excess_k,
    water_recorded,
)
from .projection.columns import lumped
from .projection.solve import FULL_STEP, beta_dict, bounds_for, search
from .projection.uncertainty import LUMPED, covariance, lumped_log_se
from .record import SeasonRecord
from .result import SeasonFit

#: Scale of the sandwich standard errors per quantity [-] (estimated, module docstring).
INTERVAL_SCALE = {"hlc_w_per_k": 2.5, "tau_h": 2.25, "c_m_j_per_k": 2.5}
#: Model-error floor of each log quantity [-] (estimated, module docstring).
MODEL_FLOOR = {"hlc_w_per_k": 0.029, "tau_h": 0.051, "c_m_j_per_k": 0.063}
#: Normal quantile of a two-sided 95 % interval.
Z95 = 1.959964
#: Widest 95 % interval given, as the log of its high/value ratio [-] (a factor of 1000 up
#: and down): wider, the nights do not determine the quantity and it is missing.
MAX_LOG_HALF_WIDTH = math.log(1000.0)
#: Why τ and C_m are not given from owner nights alone.
NEEDS_IMP = ("needs the IMP nights, a constrained and a normal one: without them its interval "
             "does not hold (on the bench 50–74 % of the houses inside, not 95 %)")
#: Fewest owner nights the season model is run on.
MIN_OWNER_NIGHTS = 5
#: The signature's window: local hours after midnight [h] (heat and ΔT means over it).
SIGNATURE_HOURS = (0.0, 5.0)


def nights_used(rec: SeasonRecord, used: np.ndarray) -> tuple[int, int]:
    """(owner nights, IMP nights) with at least one step in the likelihood's blocks."""
    k = rec.per_block
    nb = len(used)
    steps = np.repeat(used, k)
    ids, kinds = rec.night_id[: nb * k][steps], rec.kind[: nb * k][steps]
    owner = {i for i in set(ids[kinds == "owner"].tolist()) if i}
    imp = set(ids[(kinds == "constrained") | (kinds == "normal")].tolist())
    return len(owner), len(imp)


def imp_kinds(rec: SeasonRecord, used: np.ndarray) -> set[str]:
    """The IMP night kinds with at least one step in the likelihood's blocks."""
    k = rec.per_block
    steps = np.repeat(used, k)
    return set(np.unique(rec.kind[: len(used) * k][steps])) & {"constrained", "normal"}


@functools.cache
def _thread_pools() -> ThreadpoolController:
    """This process's thread pools, found once: finding them scans the loaded libraries (about
    1 ms a call, more in a fleet worker, where a morning refit costs ~70 ms). numpy's and
    scipy's BLAS, the only ones a season fit calls, are loaded before the first call."""
    return ThreadpoolController()


def _lumped(theta: tuple, pr) -> tuple[dict, dict]:
    """(β by name, HLC, τ and C_m) of a search's θ and projection."""
    b = beta_dict(pr)
    return b, lumped(theta, b["k_ao_w_per_k"], b["k_am_w_per_k"])


def fit_season(rec: SeasonRecord, calibrated: bool = True,
               start: tuple | None = None, max_nfev: int = 60,
               emitter: str | None = None, start_bound_s: float | None = None) -> SeasonFit:
    """Fit the season model to ``rec`` (module docstring); ``calibrated=False`` gives the raw
    intervals (the bench calibrates on them); ``max_nfev`` caps each search's evaluations of
    the residual; ``start`` warm-starts the search at a known θ
    (:attr:`SeasonFit.theta` of a fit of the same house); ``emitter`` ("radiators" or
    "underfloor"): the emitter as the installer declares it, known — its bound on the lag
    whatever the water reads (:mod:`.emitter`); ``start_bound_s``: the bound on the emitter's
    lag [s] the fit ``start`` comes from ended under (its emitter's :func:`tau_e_max_s`; None:
    read from the start's lag). Raises ValueError when fewer than
    :data:`MIN_OWNER_NIGHTS` owner nights have usable rows."""
    if emitter not in (None, *EMITTER_KINDS):
        raise ValueError(f"emitter {emitter!r}: give one of {', '.join(EMITTER_KINDS)}")
    from .projection.columns import Design

    d = Design.of(rec)
    owner, imp = nights_used(rec, d.blocks)
    sig = signature(rec)
    if owner < MIN_OWNER_NIGHTS:
        raise ValueError(f"{owner} owner nights with usable rows, fewer than "
                         f"{MIN_OWNER_NIGHTS}")
    # Small matrices (thousands × hundreds): BLAS threads only contend — three times slower
    # with two threads on a 2-core gateway, more beside torch's.
    with _thread_pools().limit(limits=1, user_api="blas"):
        decay = water_decay_h(rec)
        if emitter is None and math.isfinite(decay):
            # Measured: the emitter's own fade after a switch-off bounds its lag (the lag
            # takes in the room's and the furniture's too, and unbounded trades with the
            # mass): one search, whatever the start, and from one start: under this bound
            # the near-zero lag's start moved 58 of 2,368 held-out fits by more than 1 % and
            # no median, for two fifths of a fit's CPU (decision record 0031).
            bounds = bounds_for(lag_bound_s(decay))
            theta, pr, res = search(d, max_nfev=max_nfev, start=start, bounds=bounds,
                                    one_start=True)
            b, values = _lumped(theta, pr)
            excess = water_excess_k(rec, values["hlc_w_per_k"])
            kind = emitter_kind(excess, decay)
        else:
            # The emitter from the water (:mod:`.emitter`), scaled by this fit's HLC (the energy
            # signature of a few weeks can be off by half): searched first as radiators where the
            # water is recorded, and again from that θ when it is a screed or not to be read.
            first = tau_e_max_s("radiators" if water_recorded(rec) else None)
            start_bound = False
            if emitter is not None:
                first = tau_e_max_s(emitter)
            elif start is not None and water_recorded(rec) and (
                    start_bound_s if start_bound_s is not None else start[2]) > first:
                # The fit it starts from ended under a wider bound than the radiators' — a screed,
                # or no emitter where the water could not tell: one search under that bound (the
                # screed's when only the start's lag says so). A house whose water could not tell,
                # searched under the screed's, searched again in full: three searches a morning.
                first = start_bound_s if start_bound_s is not None else tau_e_max_s("underfloor")
                start_bound = True
            bounds = bounds_for(first)
            theta, pr, res = search(d, max_nfev=max_nfev, start=start, bounds=bounds)
            b, values = _lumped(theta, pr)
            excess = (water_excess_k(rec, values["hlc_w_per_k"]) if water_recorded(rec)
                      else float("nan"))
            kind = emitter if emitter is not None else emitter_kind(excess, decay)
            if start_bound and tau_e_max_s(kind) != first:
                # The water, scaled by this fit's HLC, now reads radiators where the fit it
                # started from read a screed. A fit without a start reads the water at the HLC of
                # its search under the radiators' bound, and may read a screed again: so does
                # this one, from a warm search under that bound. Where the water then reads what
                # the start was fitted under, this fit stands (a house near the radiators'
                # excess flipped every morning, and each flip cost a full search: 12 % of a
                # morning's fits); else the full search decides — searching on under the
                # radiators' bound from here kept a cost ten times the full search's (a research
                # household of bench/fleet_season.py --next-morning: HLC −34 %).
                # (a water that cannot tell — too few nights read — goes to the full search)
                r_excess = float("nan")
                if math.isfinite(excess):
                    r_theta, r_pr, _ = search(d, max_nfev=max_nfev, start=start,
                                              bounds=bounds_for(tau_e_max_s("radiators")))
                    r_excess = water_excess_k(rec, _lumped(r_theta, r_pr)[1]["hlc_w_per_k"])
                r_kind = emitter_kind(r_excess, decay)
                if not math.isfinite(r_excess) or tau_e_max_s(r_kind) != first:
                    return fit_season(rec, calibrated, None, max_nfev, emitter)
                excess, kind = r_excess, r_kind
            if tau_e_max_s(kind) != first:
                bounds = bounds_for(tau_e_max_s(kind))
                # from the first search's θ, but under another bound: maybe far (MINPACK's step)
                theta, pr, res = search(d, max_nfev=max_nfev, start=theta, bounds=bounds,
                                        step=FULL_STEP)
                b, values = _lumped(theta, pr)
        se = lumped_log_se(res.x, pr, covariance(res.x, pr, d, bounds), bounds)
    low, high = {}, {}
    for k in LUMPED:
        if not (math.isfinite(values[k]) and values[k] > 0 and math.isfinite(se[k])):
            # e.g. a negative air path: no time constant to give — missing, never a number
            values[k] = low[k] = high[k] = float("nan")
            continue
        half = Z95 * (math.hypot(INTERVAL_SCALE[k] * se[k], MODEL_FLOOR[k]) if calibrated
                      else se[k])
        if half > MAX_LOG_HALF_WIDTH:  # the data leave it open: not a value either
            values[k] = low[k] = high[k] = float("nan")
            continue
        low[k], high[k] = values[k] * math.exp(-half), values[k] * math.exp(half)
    missing = {}
    if calibrated and imp_kinds(rec, d.blocks) != {"constrained", "normal"}:
        # The intervals' floors were set on seasons with the IMP campaign in them; without a
        # constrained and a normal night τ's cover half the houses: not given, HLC's hold.
        for k in ("tau_h", "c_m_j_per_k"):
            values[k] = low[k] = high[k] = float("nan")
            missing[k] = NEEDS_IMP
    return SeasonFit({k: float(values[k]) for k in LUMPED}, low, high, owner, imp,
                     float(d.blocks.sum()) * rec.per_block * rec.step_s / 3600.0,
                     rec.exclusion_counts(), tuple(float(t) for t in theta), b,
                     sig, missing=missing, emitter=kind, water_excess_k=excess,
                     water_decay_h=decay, lag_bound_s=bounds[2][1],
                     emitter_declared=emitter is not None, warm_start=start is not None,
                     defrost_read=d.defrost_read, defrost_from_spread=rec.defrost_from_spread,
                     spread_unread=rec.spread_unread)


def signature(rec: SeasonRecord) -> float:
    """The energy signature's HLC [W/K]: per owner night the mean heat over
    :data:`SIGNATURE_HOURS` against the mean (T_air − T_out), least squares; nights with a
    left-out or missing row in the window are skipped. NaN with fewer than three nights."""
    x, y = [], []
    for sel in rec.owner_windows(SIGNATURE_HOURS, (rec.t_out_c,)):
        x.append(float(np.mean(rec.t_air_c[sel] - rec.t_out_c[sel])))
        y.append(float(np.mean(rec.q_hc_w[sel])))
    if len(x) < 3:
        return float("nan")
    A = np.c_[x, np.ones(len(x))]
    return float(np.linalg.lstsq(A, np.asarray(y), rcond=None)[0][0])


def fit_nights(nights, start: tuple | None = None, emitter: str | None = None,
               start_bound_s: float | None = None) -> tuple[SeasonFit | None, str | None]:
    """(the season fit, None) of a household's nights (NightSamples of every kind), or
    (None, why not) — no owner nights, too few usable ones, or no usable record. ``start``:
    θ of an earlier fit of the same house (:func:`theta_of`), the search's only start, and
    ``start_bound_s`` the bound on the emitter's lag that fit ended under (:func:`fit_season`);
    ``emitter``: the declared emitter (:func:`fit_season`), else the one the nights declare
    (NIGHTS column ``emitter``), else none. Raises InputError when the nights declare two."""
    from ..imp.night import declared_emitter
    from .nights import record_from_nights

    owner = [n for n in nights if n.kind == "owner"]
    if not owner:
        return None, None
    nights = list(nights)
    if emitter is None:   # the file's own declaration (NIGHTS column ``emitter``)
        emitter = declared_emitter(nights)
    found = detect_change(nights)
    # A change is reported, not acted on: the test's false alarms (up to one season in 20)
    # would otherwise throw away weeks of good nights.
    try:
        fit = fit_season(record_from_nights(nights), start=start, emitter=emitter,
                         start_bound_s=start_bound_s)
    except (ValueError, np.linalg.LinAlgError) as exc:
        return None, f"season model not fitted: {exc}"
    fit.change = found
    return fit, None
