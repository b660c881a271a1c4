"""Expected information of the next IMP night: how much each possible night is predicted to
shrink the 95 % intervals of HLC and τ (numpy and :mod:`impctl.model`; no torch).

Criterion (documented choice; README "Adaptive campaign"):

* **Parameters.** θ = (log s_U, log s_C): a common scale of the envelope U-values (it moves
  HLC) and of the heat capacity per floor area (it moves C_m), around the fitted house, plus
  one nuisance per night — its initial mass temperature θ_m,0, which the fit estimates per
  night and marginalises (Schur complement), exactly as the fit's Laplace intervals do.
* **What a night shows.** A constrained night (heating off after a pre-heat to T_set + ΔT)
  shows T_air from the end of the emission lag until it fell by the band 2ΔT or the window
  ends (counted from the end of the lag: the 5R1C air node drops at once at switch-off, a
  real room does not); a normal night (T_set held) shows the heat power. Both are simulated
  with the fitted 5R1C (Annex C) at the nights' sample step: past nights on their measured
  T_out and T_air (the fit JSON's ``predictions``, from the fitted θ_m,0), the candidate on
  a constant forecast T_out, after the house settled at the day setpoint.
* **Information.** Finite-difference sensitivities J (one-sided, 1 %, 0.05 K) per sample,
  divided by the fit's residual σ of that group, inflated by (1 + ρ)/(1 − ρ) for the
  residuals' lag-1 autocorrelation ρ (an effective-sample-size correction, as in
  :mod:`impctl.fit.intervals.uncertainty`): F = Σ Jᵀ J / σ_eff². F_past sums the fitted nights.
* **Prediction.** For q ∈ {HLC, τ} with log-gradient g_q(θ), the ratio
  r_q = g_qᵀ (F_past + F_night)⁻¹ g_q / g_qᵀ F_past⁻¹ g_q scales the fit's own statistical
  variance of log q (its reported interval with the sensor-offset allowance taken out in
  quadrature, and so the meter, night-gain and structural shares). Scaling by the fit's
  reported variance rather than using F directly carries
  over whatever widened the fit's interval beyond this simple model — the night-clustered
  sandwich, the other five parameters, the nuisance terms — assuming the next night is like
  the past ones. The sensor-offset allowance (a type-B share √(σ_in² + σ_out²)/mean ΔT that
  no number of nights removes) is added back in quadrature with the mean ΔT including the
  new night, the night-gain share likewise, the meter and structural shares unchanged. A
  sandwich interval also narrows by Student-t's t(G)/t(G − 1) for G fitted nights.
  Predicted relative half-width = sinh(1.96·sd), the same measure as
  :attr:`impctl.campaign.records.FitSummary.hlc_rel`.

A candidate is scored by the policy (:func:`impctl.campaign.policy.decide`,
:data:`impctl.campaign.policy.CRITERION`): with "balanced" the joint shrink Σ log(rel_pred /
rel) over HLC and τ, counting a quantity only while it is wider than its target. Since h18d the
default ("plan") runs the fixed plan's nights in order and uses the predictions only for the
stop rules ("more nights would not help", "precision limited").

* **Outlook.** The same prediction after ``ahead`` more nights (the most informative normal
  and constrained candidates, by det(F_past + F_night), alternating, normal first), and the
  *floor* then: the type-B shares alone (:func:`impctl.campaign.records.type_b_shares`) at
  the mean ΔT those nights bring — what no number of nights removes. The policy stops on it
  ("precision limited by …", naming the largest share) when the floor alone misses the
  target and dominates the predicted interval.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..imp.protocol import DEFAULT_BAND_K, DEFAULT_PREHEAT_H
from ..model import HouseParameters, simulate
from .records import CONSTRAINED, NORMAL, Candidate, Outlook, type_b_shares

Z95 = 1.959964
#: Relative step of the finite differences in θ, and the θ_m,0 step [K].
_REL_STEP = 0.01
_TM_STEP_K = 0.05
#: Days the candidate house settles at the day setpoint before its night, at an hourly step.
_SETTLE_DAYS = 10


@dataclass(frozen=True)
class Protocol:
    """How a night runs (the daemon's ``[night]``): window length and emission lag [h],
    pre-heat [h] to T_set + comfort band [K] on constrained nights, day setpoint [°C]."""

    window_h: float = 7.0
    emission_lag_h: float = 1.0
    preheat_h: float = DEFAULT_PREHEAT_H
    band_k: float = DEFAULT_BAND_K
    day_setpoint_c: float = 21.0


def house_of_fit(result: dict) -> HouseParameters:
    """The fitted house (seven parameters and the fixed air changes) of an ``impctl fit`` JSON."""
    params = dict(result["parameters"])
    fixed = result.get("fixed") or {}
    return HouseParameters(**params, ach_vent=float(fixed.get("ach_vent", 0.0)),
                           ach_infl=float(fixed.get("ach_infl", 0.01)))


def _variants(house: HouseParameters) -> HouseParameters:
    """Base, U-scaled and c_f-scaled copies of ``house`` (the θ finite differences), plus the
    base again for the θ_m,0 step: 4 houses."""
    s = 1.0 + _REL_STEP
    houses = [house,
              replace(house, u_walls=house.u_walls * s, u_windows=house.u_windows * s),
              replace(house, c_f=house.c_f * s),
              house]
    return HouseParameters.stack(houses)


def lumped_gradients(house: HouseParameters) -> dict[str, np.ndarray]:
    """d log q / dθ for q = HLC and τ, θ = (log s_U, log s_C); shape (2,) each."""
    net = _variants(house).network
    step = math.log1p(_REL_STEP)
    out = {}
    for name, value in (("hlc", net.hlc_w_per_k), ("tau", net.tau_h)):
        v = np.log(np.asarray(value, float))
        out[name] = np.array([v[1] - v[0], v[2] - v[0]]) / step
    return out


def _information(jac: np.ndarray) -> np.ndarray:
    """2×2 information of θ from a night's (n, 3) whitened Jacobian, θ_m,0 marginalised."""
    full = jac.T @ jac
    a, b, c = full[:2, :2], full[:2, 2], full[2, 2]
    return a - np.outer(b, b) / c if c > 1e-12 else a


def _jacobian(y: np.ndarray) -> np.ndarray:
    """(n, 4) simulated outputs of the 4 variants → (n, 3) sensitivities to θ and θ_m,0."""
    return np.stack([(y[:, 1] - y[:, 0]) / math.log1p(_REL_STEP),
                     (y[:, 2] - y[:, 0]) / math.log1p(_REL_STEP),
                     (y[:, 3] - y[:, 0]) / _TM_STEP_K], axis=1)


def _sigma_eff(result: dict) -> dict[str, float]:
    """Residual σ per observed group, inflated for lag-1 autocorrelation."""
    sigma = (result.get("fit") or {}).get("sigma") or {}
    groups = (result.get("adequacy") or {}).get("groups") or {}
    out = {}
    for kind, key, group, floor in ((CONSTRAINED, "constrained_t_air_k", "constrained", 0.01),
                                    (NORMAL, "normal_power_w", "normal_power", 1.0)):
        s = sigma.get(key)
        s = float(s) if isinstance(s, (int, float)) and math.isfinite(s) else 0.0
        rho = (groups.get(group) or {}).get("lag1_autocorrelation")
        rho = min(max(float(rho), 0.0), 0.95) if isinstance(rho, (int, float)) else 0.0
        out[kind] = max(s, floor) * math.sqrt((1 + rho) / (1 - rho))
    return out


def _regular(time_s: np.ndarray, values: np.ndarray, step_s: float) -> tuple[np.ndarray, ...]:
    grid = np.arange(time_s[0], time_s[-1] + 0.5 * step_s, step_s)
    return grid, np.interp(grid, time_s, values)


def past_information(result: dict, house: HouseParameters, step_s: float) -> np.ndarray:
    """F_past: the fitted nights' information about θ (2×2), from the JSON's ``predictions``."""
    variants = _variants(house)
    sigma = _sigma_eff(result)
    t_m0 = {p["night_id"]: p.get("t_m0_c") for p in result.get("per_night") or []}
    total = np.zeros((2, 2))
    for night in result.get("predictions") or []:
        kind = night.get("kind")
        t = np.asarray(night.get("time_s") or [], float)
        tm = t_m0.get(night.get("night_id"))
        if kind not in (CONSTRAINED, NORMAL) or len(t) < 3 or tm is None:
            continue
        _, t_out = _regular(t, np.asarray(night["t_out_c"], float), step_s)
        init = np.array([tm, tm, tm, tm + _TM_STEP_K])
        if kind == CONSTRAINED:
            sim = simulate(variants, t_out, step_s, t_m_init_c=init)
            y = sim.t_air_c
        else:
            _, held = _regular(t, np.asarray(night["t_air_measured_c"], float), step_s)
            sim = simulate(variants, t_out, step_s, setpoint_c=held, t_m_init_c=init)
            y = sim.phi_hc_w
        total += _information(_jacobian(y) / sigma[kind])
    return total


def _settled_mass_c(house: HouseParameters, t_out_c: float, setpoint_c: float) -> float:
    n = _SETTLE_DAYS * 24
    sim = simulate(house, np.full(n, t_out_c), 3600.0, setpoint_c=np.full(n, setpoint_c),
                   t_m_init_c=setpoint_c)
    return float(sim.t_m_c[-1])


def night_information(house: HouseParameters, kind: str, setpoint_c: float, t_out_c: float,
                      step_s: float, sigma_eff: float, protocol: Protocol = Protocol()
                      ) -> tuple[np.ndarray, float]:
    """F_night (2×2) of one candidate night on a constant outdoor temperature [°C], and the
    night's mean T_air − T_out [K] (for the sensor-offset allowance)."""
    variants = _variants(house)
    pre = int(round(protocol.preheat_h * 3600 / step_s)) if kind == CONSTRAINED else 0
    n_win = int(round(protocol.window_h * 3600 / step_s))
    t_m = _settled_mass_c(house, t_out_c, protocol.day_setpoint_c)
    if pre:
        sim = simulate(house, np.full(pre, t_out_c), step_s,
                       setpoint_c=np.full(pre, setpoint_c + protocol.band_k), t_m_init_c=t_m)
        t_m = float(sim.t_m_c[-1])
    init = np.array([t_m, t_m, t_m, t_m + _TM_STEP_K])
    t_out = np.full(n_win, t_out_c)
    if kind == CONSTRAINED:
        sim = simulate(variants, t_out, step_s, t_m_init_c=init)
        lag = int(round(protocol.emission_lag_h * 3600 / step_s))
        base = sim.t_air_c[:, 0]
        # The night ends at T_min = T_set − ΔT. The 5R1C air node is massless: T_air drops
        # 2–5 K the instant the heating stops, which a real room does not; so the cooling
        # allowed is the band 2ΔT counted from T_air at the end of the emission lag.
        below = np.flatnonzero(base[lag:] <= base[min(lag, n_win - 1)] - 2 * protocol.band_k)
        end = lag + int(below[0]) if len(below) else n_win
        y, delta = sim.t_air_c[lag:end], base[lag:end] - t_out_c
    else:
        sim = simulate(variants, t_out, step_s, setpoint_c=np.full(n_win, setpoint_c),
                       t_m_init_c=init)
        y, delta = sim.phi_hc_w, sim.t_air_c[:, 0] - t_out_c
    if len(y) < 2:
        return np.zeros((2, 2)), float(np.mean(delta)) if len(delta) else 0.0
    return _information(_jacobian(y) / sigma_eff), float(np.mean(delta))


def _stat_sd(result: dict, name: str, share: float) -> float:
    q = (result.get("lumped") or {}).get(name) or {}
    value, low, high = (q.get(k) for k in ("value", "low", "high"))
    if not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0
               for v in (value, low, high)):
        return math.inf
    sd = math.log(high / low) / (2 * Z95)
    return math.sqrt(max(sd * sd - share * share, 0.0))


def _offsets(result: dict) -> tuple[float, float, int]:
    """(√(σ_in² + σ_out²) [K], the fit's mean ΔT [K], its samples) of the offset allowance."""
    allowance = (result.get("fit") or {}).get("offset_allowance") or {}
    offsets = allowance.get("sensor_offsets_k") or [0.0, 0.0]
    mean_dt = allowance.get("mean_delta_t_k")
    samples = sum(len(p.get("time_s") or []) for p in result.get("predictions") or [])
    if not isinstance(mean_dt, (int, float)) or not math.isfinite(mean_dt):
        return 0.0, 0.0, 0
    return float(math.hypot(*offsets)), float(mean_dt), samples


class _Predictor:
    """The predicted relative half-widths of HLC and τ after any set of added nights."""

    def __init__(self, result: dict, protocol: Protocol, step_s: float):
        self.house = house_of_fit(result)
        self.sigma = _sigma_eff(result)
        self.protocol, self.step_s = protocol, step_s
        f_past = past_information(result, self.house, step_s)
        self.grads = lumped_gradients(self.house)
        self.offset_k, self.mean_dt, self.n_past = _offsets(result)
        share_now = self.offset_k / self.mean_dt if self.mean_dt > 1.0 else 0.0
        # (night-gain share, the shares no night changes) per quantity: records.type_b_shares
        self.fixed = {name: shares[1:] for name, shares in type_b_shares(result).items()}
        self.stat = {name: _stat_sd(result, name, math.hypot(share_now, *self.fixed[name]))
                     for name in self.grads}
        self.ridge = 1e-9 * max(float(np.trace(f_past)), 1e-12) * np.eye(2)
        self.f_past = f_past
        g = self.grads
        past_cov = np.linalg.pinv(f_past + self.ridge)
        self.before = {name: float(g[name] @ past_cov @ g[name]) for name in g}
        self.sandwich = {name for name, src in
                         ((result.get("fit") or {}).get("interval_source") or {}).items()
                         if src == "sandwich"}
        self.n_nights = len(result.get("predictions") or [])
        self.n_new = int(round(protocol.window_h * 3600 / step_s))

    def night(self, kind: str, setpoint_c: float, t_out_c: float) -> tuple[np.ndarray, float]:
        return night_information(self.house, kind, setpoint_c, t_out_c, self.step_s,
                                 self.sigma[kind], self.protocol)

    def _t_ratio(self, added: int) -> float:
        # A sandwich interval from G nights takes Student-t's quantile with G − 1 degrees of
        # freedom (impctl.fit.intervals.uncertainty): more nights also narrow it by
        # t(G + k − 1)/t(G − 1).
        if self.n_nights < 2 or added < 1:
            return 1.0
        from scipy.special import stdtrit
        return float(stdtrit(self.n_nights + added - 1, 0.975)
                     / stdtrit(self.n_nights - 1, 0.975))

    def after(self, nights: Sequence[tuple[np.ndarray, float]]
              ) -> tuple[dict[str, float], dict[str, float]]:
        """({q: predicted relative half-width}, {q: the floor then}) after ``nights``
        [(F_night, mean ΔT [K])] are added, q ∈ {hlc, tau}."""
        dt_sum = self.mean_dt * self.n_past + sum(d * self.n_new for _, d in nights)
        n_all = self.n_past + self.n_new * len(nights)
        dt_all = dt_sum / n_all if n_all else 0.0
        share = self.offset_k / dt_all if dt_all > 1.0 else 0.0
        scale = self.mean_dt / dt_all if dt_all > 1.0 and self.mean_dt > 1.0 else 1.0
        cov = np.linalg.pinv(self.f_past + sum(f for f, _ in nights) + self.ridge)
        t_ratio = self._t_ratio(len(nights))
        pred, floor = {}, {}
        for name, g in self.grads.items():
            before = self.before[name]
            ratio = float(g @ cov @ g) / before if before > 0 else 1.0
            if name in self.sandwich:
                ratio *= t_ratio ** 2
            gain, fixed_sd = self.fixed[name]
            floor_var = share ** 2 + (gain * scale) ** 2 + fixed_sd ** 2
            sd = math.sqrt(self.stat[name] ** 2 * min(max(ratio, 0.0), 1.0) + floor_var)
            pred[name] = math.sinh(Z95 * sd) if math.isfinite(sd) else math.inf
            floor[name] = math.sinh(Z95 * math.sqrt(floor_var))
        return pred, floor


def predict(result: dict, forecast_t_out_c: float, *, constrained_setpoint_c: float,
            normal_setpoints_c: Sequence[float], step_s: float,
            protocol: Protocol = Protocol(), ahead: int = 2
            ) -> tuple[list[Candidate], Outlook]:
    """Predicted relative 95 % half-widths of HLC and τ after each candidate night, and the
    outlook after ``ahead`` more nights.

    Parameters
    ----------
    result : the JSON of ``impctl fit`` (schema ``impctl-fit/1``)
    forecast_t_out_c : the next nights' mean outdoor temperature [°C]
    constrained_setpoint_c, normal_setpoints_c : the candidates' T_set [°C]
    step_s : the nights' sample step [s]
    protocol : window, lag, pre-heat, band and day setpoint of a night
    ahead : nights of the outlook: the most informative normal and constrained nights
        (largest det(F_past + F_night)) alternating, normal first (never two constrained in a
        row, whatever the last night was)

    Returns
    -------
    candidates : the constrained night first, then the normal nights in setpoint order
    outlook : predicted half-widths after ``ahead`` nights and the floor (type-B shares) then
    """
    if ahead < 1:
        raise ValueError(f"ahead must be >= 1, got {ahead!r}")
    pred = _Predictor(result, protocol, step_s)
    plans = [(CONSTRAINED, float(constrained_setpoint_c))]
    plans += [(NORMAL, float(sp)) for sp in normal_setpoints_c]
    infos = [pred.night(kind, sp, forecast_t_out_c) for kind, sp in plans]
    out = []
    for (kind, sp), info in zip(plans, infos, strict=True):
        after, _ = pred.after([info])
        out.append(Candidate(kind, sp, after["hlc"], after["tau"]))

    def most_informative(kind: str) -> tuple[np.ndarray, float]:
        of_kind = [info for (k, _), info in zip(plans, infos, strict=True) if k == kind]
        return max(of_kind, key=lambda info: float(np.linalg.det(pred.f_past + info[0])))

    best = {NORMAL: most_informative(NORMAL), CONSTRAINED: infos[0]}
    sequence = [best[NORMAL if i % 2 == 0 else CONSTRAINED] for i in range(ahead)]
    after, floor = pred.after(sequence)
    return out, Outlook(ahead, after["hlc"], after["tau"], floor["hlc"], floor["tau"])


def predict_candidates(result: dict, forecast_t_out_c: float, *, constrained_setpoint_c: float,
                       normal_setpoints_c: Sequence[float], step_s: float,
                       protocol: Protocol = Protocol()) -> list[Candidate]:
    """The candidates of :func:`predict` (the outlook left out)."""
    return predict(result, forecast_t_out_c, constrained_setpoint_c=constrained_setpoint_c,
                   normal_setpoints_c=normal_setpoints_c, step_s=step_s, protocol=protocol,
                   ahead=1)[0]
