"""Data preparation and small helpers of the night fit (no torch).

* :func:`prepare_nights` — cut each night to its fit window (the emission lag, resumed heating),
  drop the short ones;
* :func:`compared_power` — which power samples are compared (:func:`settled` on held nights);
* :func:`search_bounds` — the search box: class ranges, physical bounds, ISO domains;
* :func:`noise_levels` — measurement noise per residual group, from the data alone;
* :func:`validation_table` — the paper's Tables II/V per night;
* :class:`Estimate` — a value with its 95 % interval and whether the data determine it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ...imp.features import Q_ON_W
from ...imp.night import NightSamples
from ...imp.plan import EMISSION_LAG_H
from ...imp.protocol import MIN_NIGHT_H
from ...model.house import H_MS, LAMBDA_AT, am_factor
from ..ode.names import CLASSIFIED, PARAM_NAMES, PHYSICAL_BOUNDS, eq63_margin
from .quality import power_usable


@dataclass(frozen=True)
class Estimate:
    """A lumped quantity with its 95 % interval; ``determined`` False = not from the data."""

    value: float
    low: float
    high: float
    determined: bool

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def prepare_nights(
    nights: Sequence[NightSamples],
    emission_lag_h: float = EMISSION_LAG_H,
    min_hours: float = MIN_NIGHT_H,
    resume_threshold_w: float = Q_ON_W,
) -> tuple[list[NightSamples], list[float], list[tuple[str, str]]]:
    """Cut each night to its fit window and drop the unusable ones.

    Constrained nights start ``emission_lag_h`` after switch-off (time 0): the 5R1C air node is
    massless and would drop at once, while real emitters keep heating (identifiability.md §11.2);
    they end before the first sample where the heat power exceeds ``resume_threshold_w`` again
    (heating resumed at T_min). Normal nights keep all samples. Non-finite samples are dropped.
    An auto-cut night on which the setpoint was not held (``not_held``) is skipped with its
    reason.

    Returns
    -------
    kept : the cut nights
    offsets_s : per kept night, the time [s] of its first sample (grid time 0)
    skipped : (night_id, reason) of the dropped nights
    """
    kept, offsets, skipped = [], [], []
    for night in nights:
        if night.not_held:   # an auto-cut night that is neither kind (impctl.imp.files.held)
            skipped.append((night.night_id, night.not_held))
            continue
        t = np.asarray(night.time_s, float)
        arrays = [np.asarray(a, float) for a in (night.t_air_c, night.t_out_c, night.q_hc_w)]
        ok = np.isfinite(t) & np.all([np.isfinite(a) for a in arrays], axis=0)
        if night.kind == "constrained":
            ok &= t >= emission_lag_h * 3600.0 - 1e-6
            on = ok & (arrays[2] > resume_threshold_w)
            if on.any():
                ok &= t < t[on.argmax()]
        if ok.sum() < 2 or t[ok][-1] - t[ok][0] < min_hours * 3600.0 - 1e-6:
            span = (t[ok][-1] - t[ok][0]) / 3600.0 if ok.sum() >= 2 else 0.0
            what = " after the emission lag" if night.kind == "constrained" else ""
            # rounded down: 2.97 h is "2.9 h, under the 3 h minimum", never "3.0 h, under"
            shown = math.floor(span * 10 + 1e-9) / 10
            skipped.append((night.night_id, f"{night.kind} night covers {shown:.1f} h{what}, "
                            f"under the {min_hours:g} h minimum"))
            continue
        kept.append(dataclasses.replace(
            night, time_s=t[ok], t_air_c=arrays[0][ok], t_out_c=arrays[1][ok],
            q_hc_w=arrays[2][ok]))
        offsets.append(float(t[ok][0]))
    return kept, offsets, skipped


def settled(night: NightSamples, settle_h: float, until_held: bool = False,
            margin_k: float = 0.2) -> np.ndarray:
    """Bool per sample of a held night: its power may be compared with the model.

    False for the first ``settle_h`` hours and, with ``until_held``, until T_air first comes
    within ``margin_k`` [K] of the level it is held at (the median T_air of the night's second
    half): before that the heat pump runs at capacity while the emitter, air and furniture
    charge, and a climbing room sensor lags.
    """
    t = np.asarray(night.time_s, float) - float(night.time_s[0])
    ok = t >= 3600.0 * settle_h
    if until_held and len(t) > 2:
        t_air = np.asarray(night.t_air_c, float)
        held = float(np.median(t_air[t >= 0.5 * t[-1]]))
        reached = t_air >= held - margin_k
        if reached.any():
            ok &= t >= t[int(reached.argmax())]
    return ok


def compared_power(nights: Sequence[NightSamples], threshold_w: float, settle_h: float,
                   until_held: bool = False) -> list[np.ndarray]:
    """Bool per sample of each night: its heat power is compared with the model (the rest of
    the night still drives it). ``threshold_w`` [W] as :func:`.quality.power_usable`;
    ``settle_h`` [h] and ``until_held`` as :func:`settled`, on held nights."""
    # A night with a DHW recharge is used: its T_air still drives the model, only the power
    # during the interruption and its recovery is not compared (a defrost's is: power_usable).
    power_ok = [power_usable(n, threshold_w) for n in nights]
    # The first hour after the setpoint step of a held night is emitter, air and furniture
    # charging and the sensor's lag (README "Accuracy", error budget): that power drives
    # nothing the 5R1C has, so it is not compared (T_air still drives the model).
    return [ok & settled(n, settle_h, until_held)
            if n.kind == "normal" else ok for n, ok in zip(nights, power_ok, strict=True)]


def search_bounds(ranges: dict[str, tuple[float, float]] | None,
                  physical: dict[str, tuple[float, float]] | None = None
                  ) -> dict[str, tuple[float, float]]:
    """Search box: the classified ranges (floor_area, c_f, u_walls — or whatever the
    classifiers were trained for), physical bounds elsewhere.

    The upper walls_area and windows_area bounds are lowered if needed so that eq. 63
    (H_tr,op < H_tr,ms) and the ISO C.3 gain-split domain hold in the whole box.
    """
    box = dict(PHYSICAL_BOUNDS if physical is None else physical)
    for name, rng in (ranges or {}).items():
        if name not in PARAM_NAMES:
            raise ValueError(f"ranges: unknown parameter {name!r} (expected one of "
                             f"{PARAM_NAMES}; usually {CLASSIFIED})")
        lo, hi = (float(v) for v in rng)
        if not 0 < lo < hi:
            raise ValueError(f"ranges[{name!r}] = {rng!r} is not an increasing positive range")
        box[name] = (lo, hi)
    margin = eq63_margin(box)
    if margin <= 0:
        lo, hi = box["walls_area"]
        cap = 0.9 * (hi * box["u_walls"][1] + margin) / box["u_walls"][1]
        box["walls_area"] = (min(lo, 0.5 * cap), cap)
    # ISO C.3 needs A_t ≥ A_m + H_tr,w/9.1, else the fitted house is refused downstream.
    a_t_free = (LAMBDA_AT - float(am_factor(box["c_f"][1]))) * box["floor_area"][0]
    cap = 0.95 * H_MS * a_t_free / box["u_windows"][1]
    if box["windows_area"][1] > cap:
        lo = box["windows_area"][0]
        box["windows_area"] = (min(lo, 0.5 * cap), cap)
    return box


def noise_levels(nights: Sequence[NightSamples]) -> dict[str, float]:
    """Measurement noise per residual group, from the data alone (before any fit).

    Second differences remove a slowly varying signal; for white noise of standard deviation σ
    they have standard deviation σ·√6. Pooled over the nights of each kind: constrained T_air
    [K] (quantisation, floored at 0.01 K), normal T_air [K] and normal heat power [W] (floored
    at 1 W). They weight the groups against each other in the fit.
    """
    def pooled(series, floor):
        d2 = [np.diff(np.asarray(x, float), 2) for x in series if len(x) >= 3]
        if not d2:
            return floor
        return max(floor, float(np.sqrt(np.mean(np.concatenate(d2) ** 2) / 6.0)))

    cons = [n for n in nights if n.kind == "constrained"]
    normal = [n for n in nights if n.kind == "normal"]
    return {"constrained_t_air_k": pooled([n.t_air_c for n in cons], 0.01),
            "normal_t_air_k": pooled([n.t_air_c for n in normal], 0.01),
            "normal_power_w": pooled([n.q_hc_w for n in normal], 1.0)}


def lag1_autocorrelation(raw: np.ndarray, mask: np.ndarray) -> float | None:
    """Pooled lag-1 autocorrelation of residuals ``raw`` (rows, K) on consecutive masked
    nodes, clipped to [0, 0.95]; None with fewer than 5 pairs."""
    both = mask[:, 1:] & mask[:, :-1]
    if int(both.sum()) < 5:
        return None
    a, b = raw[:, 1:][both], raw[:, :-1][both]
    rho = float((a * b).sum() / max(np.sqrt((a * a).sum() * (b * b).sum()), 1e-300))
    return float(np.clip(rho, 0.0, 0.95))


def validation_table(night_ids: Sequence[str], kinds: Sequence[str], grid_s: np.ndarray,
                     mask: np.ndarray, t_air_c: np.ndarray, q_w: np.ndarray,
                     t_air_model_c: np.ndarray, q_model_w: np.ndarray) -> dict:
    """Per-night and mean ΔQ_total [kWh], ΔQ_power [kW], ε [%] and T_air RMSE [K].

    Arrays are (nights, K); ``grid_s`` is (K,) or per night (nights, K).
    ΔQ_total = |E_model − E_measured| over the night (energy = power on each sample interval ×
    its length), ΔQ_power = ΔQ_total / night length = |mean P_model − mean P_measured|,
    ε = ΔQ_total / E_measured: the paper's Tables II and V, per night instead of per month.
    T_air RMSE on the constrained nights.
    """
    normal, constrained = [], []
    for i, nid in enumerate(night_ids):
        m = mask[i]
        if kinds[i] == "normal":
            span = np.diff((grid_s if grid_s.ndim == 1 else grid_s[i])[m])
            hours = float(span.sum()) / 3600.0
            e_meas = float((q_w[i][m][:-1] * span).sum()) / 3.6e6
            e_mod = float((q_model_w[i][m][:-1] * span).sum()) / 3.6e6
            normal.append({"night_id": nid, "q_measured_kwh": e_meas, "q_model_kwh": e_mod,
                           "dq_total_kwh": abs(e_mod - e_meas),
                           "dq_power_kw": abs(e_mod - e_meas) / hours,
                           "eps_pct": 100.0 * abs(e_mod - e_meas) / e_meas if e_meas > 0
                           else float("nan")})
        else:
            err = t_air_model_c[i][m] - t_air_c[i][m]
            constrained.append({"night_id": nid, "rmse_k": float(np.sqrt(np.mean(err ** 2)))})
    summary = {}
    if normal:
        for key in ("dq_total_kwh", "dq_power_kw", "eps_pct"):
            summary[key] = float(np.mean([r[key] for r in normal]))
    if constrained:
        summary["rmse_k"] = float(np.mean([r["rmse_k"] for r in constrained]))
    return {"normal": normal, "constrained": constrained, "mean": summary,
            "note": "in-sample: each night's initial mass temperature is fitted on that night"}
