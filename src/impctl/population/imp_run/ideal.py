"""The IMP run on virtual households: one vectorised 5R1C simulation for all their nights.

Every (household, weather day, night plan) is one column of the model's (n_steps, n_houses)
arrays, so all nights of all households advance together, one Python loop over time steps only
(inside :func:`impctl.model.simulate`). Per night:

1. **Spin-up** (``spinup_days``, hourly): the days before the night held at the household's
   normal setpoint (drawn per household from ``day_setpoint_c``), from the steady state at the
   first hour's T_out, so the mass enters the night in a realistic state — including the
   charging after the evening's setpoint step that makes normal nights non-stationary
   (identifiability.md §11.1). No internal or solar gains (the paper's night-time assumption,
   kept all day for simplicity).
2. **Pre-heat** (``preheat_h`` at ``step_s``): held at T_max (constrained) or T_set (normal).
3. **Window** (local 22:00–05:00 in absolute time, at ``step_s``): a normal night holds T_set; a
   constrained night switches the heat pump off — its emitters still give heat falling linearly
   from the last pre-heat power to zero over ``emitter_lag_h`` (the paper's approximation, made
   exact here) — and cools to the window's end. With ``stop_at_t_min`` it ends instead at the
   first step after the lag where T_air would fall below T_min (the heating resumes there).

Why constrained nights cool for the whole window by default: the 5R1C air node is massless, so
T_air drops by about Φ_HC/(H_tr,is ⊕ (H_tr,w + H_tr,ms)) when the heating stops: over the lag
hour 5.4 K in the median (10–90 %: 3.7–7.3 K) for a 500-household sample. With ΔT = 1.5 K that
drop alone passes T_min in 97 % of the simulated constrained nights, so a T_min stop would end
them right after the lag — an artefact that real houses, whose emitters, air and furniture smooth
the drop, do not show (identifiability.md §11.2). The classifiers use only the constrained nights'
decay rate, which does not depend on the drop or on where a night ends
(:mod:`impctl.classifiers.campaign`).

Observed samples: T_air with optional Gaussian noise, then quantised to ``quantum_k`` (the heat
pump reports 0.1 °C); T_out quantised the same way; Q_HC = the heat pump's output (zero while it is
off, even while the emitters still give heat) with optional relative Gaussian noise. Samples are
stamped at the start of each step and hold the step's values.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import ceil

import numpy as np
import pandas as pd

from ...errors import InputError
from ...imp import NightSamples, features_from_arrays
from ...model import HouseParameters, simulate
from ...model.continuous import mass_derivative
from .setup import ImpSimConfig, _epoch_s, default_weather, usable_nights


def _steady_mass_c(houses: HouseParameters, t_e: np.ndarray, t_air: np.ndarray) -> np.ndarray:
    """θ_m [°C] of the steady state holding ``t_air`` at outdoor ``t_e`` (no gains)."""
    net = houses.network
    phi = houses.hlc_w_per_k * (t_air - t_e)
    # dθ_m/dt at θ_m = θ_e is the Φ_HC share reaching the mass; it balances h_sum·(θ_m − θ_e).
    drive = mass_derivative(t_e, t_e, phi, net) * net.c_m_j_per_k
    return t_e + drive / (net.h_tr_em + net.h_tr_3)


def _repeat(houses: HouseParameters, k: int) -> HouseParameters:
    n = houses.n_houses or 1
    return HouseParameters(**{name: np.repeat(np.broadcast_to(np.asarray(v, float), (n,)), k)
                              for name, v in houses.as_dict().items()})


@dataclass
class ImpResult:
    """Nights of a virtual IMP run.

    Attributes
    ----------
    nights : DataFrame
        One row per night: ``household`` (index into the houses), ``day`` (0…days−1), ``date``,
        ``kind``, ``replay`` (0, 1, … for a plan run more than once a day), ``setpoint_c`` [°C],
        ``start`` (tz-aware), ``duration_h`` [h], then the night
        features (:data:`impctl.imp.NIGHT_FEATURE_NAMES`).
    time_s : ndarray (n_samples,) or None
        Sample times since the window start [s], shared by all nights.
    t_air_c, t_out_c, q_hc_w : ndarray (n_samples, n_nights) or None
        Observed samples (quantised, noisy) [°C, °C, W]; column i is row i of ``nights``.
    valid : bool ndarray (n_samples, n_nights) or None
        Which entries belong to the night (window length, constrained cut at T_min).
    """

    nights: pd.DataFrame
    time_s: np.ndarray | None = None
    t_air_c: np.ndarray | None = None
    t_out_c: np.ndarray | None = None
    q_hc_w: np.ndarray | None = None
    valid: np.ndarray | None = None

    def night(self, i: int) -> NightSamples:
        """Night ``i`` (row of ``nights``) as NightSamples; needs ``keep_samples=True``."""
        if self.valid is None:
            raise ValueError("samples were not kept (simulate_imp(..., keep_samples=True))")
        row = self.nights.iloc[i]
        m = self.valid[:, i]
        replay = f"-r{row['replay']}" if row.get("replay", 0) else ""
        return NightSamples(
            night_id=f"h{row['household']}-{row['date']}-{row['kind']}-{row['setpoint_c']:g}"
                     f"{replay}",
            kind=row["kind"], start=row["start"], time_s=self.time_s[m],
            t_air_c=self.t_air_c[m, i], t_out_c=self.t_out_c[m, i], q_hc_w=self.q_hc_w[m, i],
            setpoint_c=float(row["setpoint_c"]),
        )

    def nights_of(self, household: int) -> list[NightSamples]:
        """All nights of one household as NightSamples.

        Nights of one date at different plans are counterfactual replays of the same evening
        (their times overlap); :meth:`campaign` picks a realistic set.
        """
        rows = np.flatnonzero(self.nights["household"].to_numpy() == household)
        return [self.night(int(i)) for i in rows]

    def campaign(self, household: int, n_constrained: int = 2, n_normal: int = 6,
                 seed: int = 0) -> list[NightSamples]:
        """A realistic campaign of one household: that many nights, each on a different date.

        Plans (setpoints) are drawn at random among the household's nights; the result is in
        time order. Raises ValueError when the household has fewer dates than nights asked.
        """
        rng = np.random.default_rng(seed)
        mine = (self.nights["household"] == household).to_numpy()
        date = self.nights["date"].to_numpy()
        kind = self.nights["kind"].to_numpy()
        dates = np.unique(date[mine])
        if n_constrained + n_normal > len(dates):
            raise ValueError(f"household {household} has {len(dates)} dates, "
                             f"{n_constrained + n_normal} nights asked")
        chosen = rng.permutation(dates)[: n_constrained + n_normal]
        kinds = ["constrained"] * n_constrained + ["normal"] * n_normal
        rows = [int(rng.choice(np.flatnonzero(mine & (date == d) & (kind == k))))
                for d, k in zip(chosen, kinds, strict=True)]
        return sorted((self.night(i) for i in rows), key=lambda n: n.start)


def simulate_imp(
    houses: HouseParameters,
    weather: pd.Series | None = None,
    config: ImpSimConfig | None = None,
    seed: int | np.random.SeedSequence | np.random.Generator = 0,
    *,
    keep_samples: bool = True,
) -> ImpResult:
    """Run the IMP on many households at once (module docstring).

    Parameters
    ----------
    houses : HouseParameters
        Array-valued (or one house).
    weather : Series, optional
        Outdoor temperature [°C] with a tz-aware index (:func:`impctl.weather.read_weather`);
        default :func:`default_weather` with the integer ``seed`` (else 0).
    config : ImpSimConfig, optional
    seed : int, SeedSequence or Generator
        Chooses each household's weather days and the measurement noise.
    keep_samples : bool
        Keep the sample arrays (for :meth:`ImpResult.night`); the dataset needs only features.

    Returns
    -------
    ImpResult

    Raises
    ------
    InputError
        The weather holds fewer usable nights than ``config.days``.
    """
    cfg = config or ImpSimConfig()
    if weather is None:
        weather = default_weather(seed if isinstance(seed, int) else 0, cfg.tz)
    rng = np.random.default_rng(seed)
    if houses.n_houses is None:
        houses = _repeat(houses, 1)
    n, days = houses.n_houses, cfg.days
    cand = usable_nights(weather, cfg)
    if len(cand) < days:
        raise InputError(f"the weather holds {len(cand)} usable nights (window inside the data "
                         f"with {cfg.spinup_days:g} days before, mean T_out < "
                         f"{cfg.max_t_out_c:g} °C); {days} are needed", place="weather")
    w_t = _epoch_s(pd.DatetimeIndex(weather.index))
    w_v = weather.to_numpy(dtype=float)
    plans = cfg.plans()
    n_p = len(plans)
    zeros = np.zeros  # gains are off: (n_steps,) inputs are shared by all columns, not copied

    pick = np.argsort(rng.random((n, len(cand))), axis=1)[:, :days]          # (n, days)
    start_s = cand["start_s"].to_numpy()[pick].reshape(-1)                    # (n·days,)
    duration_s = cand["duration_s"].to_numpy()[pick].reshape(-1)
    preheat_s = cfg.preheat_h * 3600.0
    day_sp = np.repeat(rng.uniform(*cfg.day_setpoint_c, n), days)

    # 1. spin-up, one column per (household, day)
    n_su = int(round(cfg.spinup_days * 86400.0 / cfg.spinup_step_s))
    t_su = start_s - preheat_s - n_su * cfg.spinup_step_s
    te = np.interp(t_su[None, :] + (np.arange(n_su)[:, None] + 0.5) * cfg.spinup_step_s, w_t, w_v)
    su_houses = _repeat(houses, days)
    t_m = simulate(su_houses, te, cfg.spinup_step_s, setpoint_c=np.broadcast_to(day_sp, te.shape),
                   internal_gains_w=zeros(n_su), solar_gains_w=zeros(n_su),
                   t_m_init_c=_steady_mass_c(su_houses, te[0], day_sp)).t_m_c[-1]
    t_m = np.repeat(t_m, n_p)                                                 # (n·days·n_p,)

    # 2. pre-heat, one column per (household, day, plan)
    houses_n = _repeat(houses, days * n_p)
    n_ph = int(round(preheat_s / cfg.step_s))
    te = np.interp((start_s - preheat_s)[None, :] + (np.arange(n_ph)[:, None] + 0.5) * cfg.step_s,
                   w_t, w_v)
    te = np.repeat(te, n_p, axis=1)
    shift = cfg.setpoint_shift_k(plans, n * days * n_p, rng)
    sp_pre = np.tile([p.preheat_setpoint_c for p in plans], n * days) + shift
    pre = simulate(houses_n, te, cfg.step_s, setpoint_c=np.broadcast_to(sp_pre, te.shape),
                   internal_gains_w=zeros(n_ph), solar_gains_w=zeros(n_ph), t_m_init_c=t_m)

    # 3. the window
    n_w = int(ceil(cand["duration_s"].max() / cfg.step_s))
    time_s = np.arange(n_w) * cfg.step_s
    te = np.repeat(np.interp(start_s[None, :] + time_s[:, None] + 0.5 * cfg.step_s, w_t, w_v),
                   n_p, axis=1)
    cons = np.tile([p.kind == "constrained" for p in plans], n * days)
    lag_s = cfg.emitter_lag_h * 3600.0
    # Step means of an emitter output falling linearly from the last pre-heat power to 0.
    share = np.clip(1.0 - (time_s + 0.5 * cfg.step_s) / max(lag_s, 1e-9), 0.0, 1.0)
    in_lag = time_s < lag_s
    forced = np.where(in_lag[:, None] & cons[None, :],
                      share[:, None] * pre.phi_hc_w[-1][None, :], np.nan)
    sp_win = np.tile([p.window_setpoint_c for p in plans], n * days) + shift
    win = simulate(houses_n, te, cfg.step_s, setpoint_c=np.broadcast_to(sp_win, te.shape),
                   phi_hc_w=forced, internal_gains_w=zeros(n_w), solar_gains_w=zeros(n_w),
                   t_m_init_c=pre.t_m_c[-1])
    q_true = np.where(np.isnan(forced), win.phi_hc_w, 0.0)
    valid = time_s[:, None] < np.repeat(duration_s, n_p)[None, :]
    resumed = np.cumsum(~in_lag[:, None] & (q_true > 0.0), axis=0) > 0
    valid &= ~(resumed & cons[None, :])

    t_air = win.t_air_c + (rng.normal(0.0, cfg.noise_t_air_k, win.t_air_c.shape)
                           if cfg.noise_t_air_k > 0 else 0.0)
    q_obs = q_true * (1.0 + rng.normal(0.0, cfg.noise_q_rel, q_true.shape)) \
        if cfg.noise_q_rel > 0 else q_true
    q_obs = np.maximum(q_obs, 0.0)
    if cfg.quantum_k > 0:
        t_air = np.round(t_air / cfg.quantum_k) * cfg.quantum_k
        te = np.round(te / cfg.quantum_k) * cfg.quantum_k
    sp_night = np.tile([p.setpoint_c for p in plans], n * days) + shift
    feats = features_from_arrays(time_s, t_air, te, q_obs, constrained=cons, setpoint_c=sp_night,
                                 valid=valid, emission_lag_h=cfg.emitter_lag_h)

    return night_result(pick, cand, plans, n, days, sp_night, duration_s, feats,
                        (time_s, t_air, te, q_obs, valid) if keep_samples else None)


def night_result(pick: np.ndarray, cand: pd.DataFrame, plans, n: int, days: int,
                 sp_night: np.ndarray, duration_s: np.ndarray, feats: dict,
                 samples: tuple | None) -> ImpResult:
    """One table row per household, day and planned night (the features next to where and
    when each night ran: ``setpoint_c`` [°C], ``duration_h`` [h]); ``samples`` = (time_s,
    t_air, t_out, q_obs, valid) to keep the series, or None. Shared by both plants."""
    n_p = len(plans)
    night_rows = pick.reshape(-1).repeat(n_p)
    table = pd.DataFrame({
        "household": np.repeat(np.arange(n), days * n_p),
        "day": np.tile(np.repeat(np.arange(days), n_p), n),
        "date": cand["date"].to_numpy()[night_rows],
        "kind": np.tile([p.kind for p in plans], n * days),
        # 0, 1, … for repeated plans of one day (constrained_per_day), so night ids stay unique
        "replay": np.tile([sum(q == p for q in plans[:j]) for j, p in enumerate(plans)], n * days),
        "setpoint_c": sp_night,
        "start": pd.DatetimeIndex(cand["start"])[night_rows],
        "duration_h": np.repeat(duration_s, n_p) / 3600.0,
        **feats,
    })
    return ImpResult(table) if samples is None else ImpResult(table, *samples)
