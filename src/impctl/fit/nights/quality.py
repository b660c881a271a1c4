"""Night quality and model adequacy: what each night holds, and whether the fit describes it.

Numbers only from the measured series (numpy, no torch), so that a reader sees *why* a night
helps or not before trusting a fitted value:

* :func:`night_quality` — per night: rows, hours, T_air resolution, heat-pump cycling (cycles/h),
  DHW/defrost interruptions, emitter discharge time after switch-off;
  :func:`used_nights_quality` — the same for each night given to a fit, with whether it was used;
* :func:`adequacy` — per fit: residual RMSE and lag-1 autocorrelation per residual group, and a
  plain statement when the residuals say the model misses structure in the data (then its
  intervals, which assume it does not, are too narrow).

Thresholds (documented choices, real-houses.md §3, §6, §7):

* a *cycle* is an off→on transition of the heat output across :data:`~impctl.imp.features.Q_ON_W`;
* an *interruption* on a held night is a run of no space heat longer than :data:`STOP_MIN_MIN`
  minutes and than 1.5× the night's median off phase (a DHW recharge takes 20–60 min, longer
  than the heat pump's own cycling), or any negative heat (a defrost draws heat from the water);
* the *emitter discharge time* is how long after switch-off T_air stays off the night's later
  exponential cooling (fitted to the second half of the night, back-extrapolated) by more than
  max(0.1 K, 3·reading noise): the hours the emitter and the air/furniture still discharge;
* *inadequate*: in a residual group (constrained-night T_air, held-night power), the means of
  the residuals over hour-long blocks are larger than white residuals give (a χ² test at
  :data:`WHITENESS_ALPHA`: Annex 58's whiteness, read where a missing dynamic shows — the
  readings' rounding and the heat pump's cycling are faster than an hour) **and** larger than
  a tolerance: :data:`T_AIR_TOLERANCE_K` on T_air, :data:`POWER_TOLERANCE` of the mean held
  power. Measured (``bench/fit.py --dump``, decision record 0023): no false alarm on 40 ideal
  5R1C houses; on 200 realistic ones it flags 20 %: 36 % of the quarter with the worst HLC
  error against 14 % of the rest; none of the four Annex 58 twin-house fits.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...imp.features import Q_ON_W
from ...imp.night import NightSamples

STOP_MIN_MIN = 20.0
#: Level of the hour-scale whiteness test of the residuals.
WHITENESS_ALPHA = 0.01
#: Hour-scale T_air misfit [K] (RMS of the hour means of the residuals) below which structure
#: is not called a model error: half the 0.1 K most room sensors report in, far below their
#: accuracy (±0.2–0.3 K).
T_AIR_TOLERANCE_K = 0.05
#: Hour-scale held-power misfit, as a share of the held nights' mean power, below which it is
#: not called a model error: a class-3 heat meter's ±5 %.
POWER_TOLERANCE = 0.05
#: Length [s] of the residual blocks whose means carry the low-frequency (whiteness) test.
BLOCK_S = 3600.0
#: Fewest compared samples in a block for its mean to count.
BLOCK_MIN_N = 3


def t_air_resolution_k(t_air_c: np.ndarray) -> float | None:
    """Smallest step between successive distinct T_air readings [K] (the sensor's or the
    logger's quantum when readings are rounded), None if T_air never changes."""
    d = np.abs(np.diff(np.asarray(t_air_c, float)))
    d = d[d > 1e-6]
    return float(np.round(d.min(), 4)) if len(d) else None


def cycles_per_h(time_s: np.ndarray, q_w: np.ndarray, threshold_w: float = Q_ON_W) -> float:
    """Off→on transitions of the heat output per hour."""
    t = np.asarray(time_s, float)
    on = np.asarray(q_w, float) > threshold_w
    hours = (t[-1] - t[0]) / 3600.0 if len(t) > 1 else 0.0
    starts = int(np.sum(on[1:] & ~on[:-1]))
    return float(starts / hours) if hours > 0 else float("nan")


def interruptions(time_s: np.ndarray, q_w: np.ndarray, threshold_w: float = Q_ON_W,
                  min_minutes: float = STOP_MIN_MIN) -> list[dict]:
    """Runs of negative heat ("defrost") and runs of no space heat longer than both
    ``min_minutes`` and 1.5× the night's median off phase ("dhw_or_stop": longer than the heat
    pump's own cycling) on a held night: [{"kind", "start_h", "minutes"}]."""
    t = np.asarray(time_s, float)
    q = np.asarray(q_w, float)

    def runs(flag):
        edges = np.flatnonzero(np.diff(np.r_[0, flag.astype(int), 0]))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            yield a, b, (t[b] if b < len(t) else t[-1]) - t[a]

    out = [{"kind": "defrost", "start_h": float(t[a] / 3600.0), "minutes": float(d / 60.0)}
           for a, b, d in runs(q < -threshold_w)]
    off = list(runs(q <= threshold_w))
    # the heat pump's own off phases: only a night that cycles (≥ 3 off runs) has them
    typical = float(np.median([d for _, _, d in off])) if len(off) >= 3 else 0.0
    limit = max(60.0 * min_minutes, 1.5 * typical)
    out += [{"kind": "dhw_or_stop", "start_h": float(t[a] / 3600.0), "minutes": float(d / 60.0)}
            for a, b, d in off if d > limit and not (q[a:b] < -threshold_w).all()]
    return sorted(out, key=lambda x: x["start_h"])


def reading_noise(y: np.ndarray) -> float:
    """White-noise SD of readings ``y`` from their second differences (SD σ·√6 for white
    noise of SD σ; a slowly varying signal drops out); 0 with fewer than 4 readings."""
    y = np.asarray(y, float)
    return float(np.std(np.diff(y, 2)) / np.sqrt(6.0)) if len(y) > 3 else 0.0


def emitter_discharge_h(time_s: np.ndarray, t_air_c: np.ndarray, t_out_c: np.ndarray
                        ) -> float | None:
    """Hours after switch-off (time 0) during which T_air departs from the night's later
    exponential cooling (module docstring); None when the night is too short or not cooling."""
    t = np.asarray(time_s, float)
    ta = np.asarray(t_air_c, float)
    te = float(np.mean(t_out_c))
    late = t >= 0.5 * t[-1]
    dt = ta - te
    if late.sum() < 4 or np.any(dt[late] <= 0.0):
        return None
    slope, icpt = np.polyfit(t[late], np.log(dt[late]), 1)
    if slope >= 0:
        return None
    curve = te + np.exp(icpt + slope * t)
    noise = reading_noise(ta[late])
    threshold = max(0.1, 3.0 * noise)
    off = np.abs(ta - curve) > threshold
    early = t < 0.5 * t[-1]
    idx = np.flatnonzero(off & early)
    return float(t[idx[-1] + 1] / 3600.0) if len(idx) else 0.0


def night_quality(night: NightSamples, threshold_w: float = Q_ON_W) -> dict:
    """What one measured night holds (module docstring); JSON-ready."""
    t = np.asarray(night.time_s, float)
    q = np.asarray(night.q_hc_w, float)
    ok = np.isfinite(t) & np.isfinite(q) & np.isfinite(night.t_air_c) & np.isfinite(
        night.t_out_c)
    t, q = t[ok], q[ok]
    ta = np.asarray(night.t_air_c, float)[ok]
    te = np.asarray(night.t_out_c, float)[ok]
    out = {"night_id": night.night_id, "kind": night.kind, "rows": int(ok.sum()),
           "hours": float((t[-1] - t[0]) / 3600.0) if len(t) > 1 else 0.0,
           "t_air_resolution_k": t_air_resolution_k(ta) if len(ta) > 1 else None,
           "cycles_per_h": None, "interruptions": [], "emitter_discharge_h": None,
           "night_gain_w": None}
    if len(t) < 3:
        return out
    if night.kind == "normal":
        out["cycles_per_h"] = cycles_per_h(t, q, threshold_w)
        out["interruptions"] = interruptions(t, q, threshold_w)
    else:
        # from switch-off (time 0) until heating resumes
        on = q > threshold_w
        after = t > 0
        end = np.flatnonzero(on & after)
        stop = end[0] if len(end) else len(t)
        cooling = after.copy()
        cooling[stop:] = False
        if cooling.sum() >= 8:
            out["emitter_discharge_h"] = emitter_discharge_h(t[cooling], ta[cooling],
                                                             te[cooling])
    return out


def used_nights_quality(nights: Sequence[NightSamples], used: Sequence[NightSamples],
                        skipped: Sequence[tuple[str, str]], threshold_w: float,
                        nuisance: dict | None) -> list[dict]:
    """:func:`night_quality` of each given night, with whether the fit used it (``used``: the
    nights as fitted), its usable hours, why not (``skipped``) and the fitted night gain [W]
    (from ``nuisance``; not when only assumed); JSON-ready."""
    used_by_id = {n.night_id: n for n in used}
    why = dict(skipped)
    out = []
    for night in nights:
        q = night_quality(night, threshold_w)
        kept = used_by_id.get(night.night_id)
        q["used"] = kept is not None
        q["usable_h"] = (float(kept.time_s[-1] - kept.time_s[0]) / 3600.0
                         if kept is not None else 0.0)
        q["reason"] = why.get(night.night_id)
        gain = (nuisance or {}).get("night_gain_w")
        # an assumed gain is not an estimate of this night's (fit.night_gain says it)
        if gain is not None and kept is not None and not gain.get("assumed"):
            q["night_gain_w"] = gain["value"]   # one value per campaign
        out.append(q)
    return out


def adequacy(sigma_fit: dict[str, float], sigma_data: dict[str, float],
             autocorrelation: dict[str, float], blocks: dict[str, dict] | None = None,
             t_air_resolution: float | None = None, mean_power_w: float | None = None) -> dict:
    """Residual statistics per group and the verdict (module docstring: *inadequate*).

    ``sigma_fit``/``sigma_data`` use the keys of :func:`~impctl.fit.nights.data.noise_levels`;
    ``autocorrelation`` and ``blocks`` (:func:`residual_blocks`) those of :mod:`.uncertainty`
    (constrained, normal_t_air, normal_power); ``t_air_resolution`` [K] the readings' quantum;
    ``mean_power_w`` [W] the held nights' mean heat power (the power tolerance's scale).
    """
    from scipy.special import chdtrc

    keys = {"constrained": "constrained_t_air_k", "normal_power": "normal_power_w"}
    groups, problems = {}, []
    for group, key in keys.items():
        if group not in autocorrelation:
            continue
        unit = "K" if key.endswith("_k") else "W"
        # lag-1 ρ and RMSE over the second-difference noise: what the model-error groups of
        # the intervals read (:mod:`impctl.fit.intervals.model_error`), kept as they were
        g = groups[group] = {
            "rmse": sigma_fit[key], "unit": unit, "noise_from_data": sigma_data[key],
            "rmse_over_noise": sigma_fit[key] / max(sigma_data.get(key, 0.0), 1e-12),
            "lag1_autocorrelation": float(autocorrelation[group])}
        b = (blocks or {}).get(group)
        if not b or b["n"] <= 0 or b["blocks"] <= 0 or b["ss"] <= 0:
            continue
        s2 = b["ss"] / b["n"]
        # the readings' own noise: second differences, and never below what rounding to the
        # sensor's quantum q leaves (q/√12), which slow changes hide from them
        noise = sigma_data[key]
        if unit == "K" and t_air_resolution:
            noise = max(noise, t_air_resolution / np.sqrt(12.0))
        ratio = b["lf"] / (b["blocks"] * s2)
        hour = float(np.sqrt(b["lf"] / b["n_blocked"]))   # RMS of the hour means [unit]
        tol = (T_AIR_TOLERANCE_K if unit == "K"
               else POWER_TOLERANCE * mean_power_w if mean_power_w else None)
        p_white = float(chdtrc(b["blocks"], b["lf"] / s2))
        g.update(blocks=b["blocks"], low_frequency_ratio=ratio, whiteness_p=p_white,
                 hour_scale_residual=hour, tolerance=tol, reading_noise=noise,
                 rmse_over_reading_noise=float(np.sqrt(s2)) / noise)
        if p_white < WHITENESS_ALPHA and ratio > 1.0 and tol is not None and hour > tol:
            what = ("constrained-night T_air" if unit == "K" else "held-night heat power")
            size = f"{hour:.2f} K" if unit == "K" else f"{hour:.0f} W"
            limit = (f"{tol:.2f} K" if unit == "K"
                     else f"{tol:.0f} W, {100 * POWER_TOLERANCE:.0f} % of the mean")
            problems.append(
                f"{what}: its residuals stay on one side for hours ({size} at the hour scale, "
                f"{ratio:.1f}× white noise, p = {p_white:.1g}; tolerance {limit})")
    adequate = not problems
    statement = (
        "no misfit beyond the readings' noise and the sensors' accuracy at the hour scale "
        "(the residuals cannot show an error every night shares alike)"
        if adequate else
        "the model misses structure in these nights — " + "; ".join(problems)
        + ". The values carry a model error the intervals may not cover; treat them as "
        "approximate.")
    return {"adequate": adequate, "groups": groups, "statement": statement}


def residual_blocks(raw: np.ndarray, mask: np.ndarray, grid_s: np.ndarray,
                    block_s: float = BLOCK_S) -> dict:
    """Residual sums of rows ``raw`` (rows, K) on their compared nodes ``mask`` at times
    ``grid_s`` [s]: ``n`` and ``ss`` (Σ r²) of all nodes, and over consecutive blocks of
    ``block_s`` seconds per row (at least :data:`BLOCK_MIN_N` nodes each) ``blocks`` (how many),
    ``n_blocked`` (their nodes) and ``lf`` (Σ n_b·m_b², m_b a block's mean residual). For white
    residuals of variance s², ``lf`` ≈ ``blocks``·s² (each n_b·m_b²/s² ~ χ²(1)); residuals that
    stay on one side for an hour — structure the model misses, not reading noise — make it
    larger."""
    n = ss = lf = n_blocked = 0.0
    blocks = 0
    for r, m, t in zip(raw, mask, grid_s, strict=True):
        r, t = np.asarray(r, float)[m], np.asarray(t, float)[m]
        if len(r) == 0:
            continue
        n += len(r)
        ss += float(np.sum(r * r))
        idx = np.floor((t - t[0]) / block_s).astype(int)
        count = np.bincount(idx)
        total = np.bincount(idx, weights=r)
        ok = count >= BLOCK_MIN_N
        blocks += int(ok.sum())
        n_blocked += float(count[ok].sum())
        lf += float(np.sum(total[ok] ** 2 / count[ok]))
    return {"n": n, "ss": ss, "blocks": blocks, "lf": lf, "n_blocked": n_blocked}


def power_usable(night: NightSamples, threshold_w: float = Q_ON_W) -> np.ndarray:
    """Per sample of a held night: False inside a DHW recharge or a stop of the space heating
    and during the recovery after it (as long again as the interruption, the heat debt being
    repaid), where the measured power is not the house's space-heating demand. True everywhere
    on a constrained night.

    A defrost (negative heat) stays compared, and so does its recovery: the heat it draws from
    the water is heat the heat pump puts back afterwards, so over whole cycles a signed reading
    is the house's demand. Leaving the negative readings out keeps the repayment, which outlasts
    any window and runs into the next defrost: on 200 realistic houses with a signed reading the
    HLC's median error was 15.7 % with the defrosts left out (+6.1 % signed), 10.8 % with them
    compared (decision record 0025)."""
    t = np.asarray(night.time_s, float)
    ok = np.ones(len(t), bool)
    if night.kind != "normal" or len(t) < 3:
        return ok
    for stop in interruptions(t, night.q_hc_w, threshold_w):
        if stop["kind"] == "defrost":
            continue
        a = stop["start_h"] * 3600.0
        ok &= ~((t >= a) & (t < a + 2 * 60.0 * stop["minutes"]))
    return ok
