"""The negative log posterior of the state-space night model: Kalman likelihood + priors.

Priors (what is known before the nights, said in the fit's ``prior_``):

* **class prior** (the range forests' classes): the virtual population the classifiers are
  trained on (:data:`~impctl.fit.prior.PRIOR_SEED`, the bench's held-out houses use another
  seed), restricted to the households whose floor_area, c_f, u_walls lie in the class box, or
  weighted by the classes' probabilities, gives a joint Gaussian on (ln C_m, β, κ) — the
  capacity and how the losses split between the air and the mass path, which the nights pin
  down least. HLC and τ get no population prior: the nights measure them.
* **physical priors** (real-houses.md §1, §2, §4): wide log-normals on the air/furniture and
  emitter shares of C_m and on the emitter's time constant; the noise levels get very wide
  log-normal priors that only keep them off zero; the night-gain term Φ_0 is declared (pinned),
  or estimated under N(gain, gain_sd² + (HLC·offset_sd)²) — a sensor offset makes an intercept
  HLC·offset that Φ_0 absorbs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch

from ..ode.parameters import CLASSIFIED
from ..prior import PRIOR_HOUSEHOLDS, PRIOR_SEED
from .data import Batch
from .kalman import discretise, filter_nll
from .model import BETA_BOX, DTYPE, IDX, N_PARAMS, Q_FLOOR_W, matrices, physical

#: Physical priors on the unconstrained nuisance terms: (centre, SD) of ln value.
LN_PRIORS = {
    "share_i": (math.log(0.05), 1.0),
    "share_e": (math.log(0.03), 1.5),
    "tau_e": (math.log(0.75), 1.5),          # h
    "ln_sig_i": (math.log(0.1), 2.5),        # K/√h
    "ln_sig_m": (math.log(0.02), 2.5),
    "ln_sig_e": (math.log(0.3), 2.5),
    "ln_sig_y": (math.log(0.05), 2.5),       # K
    "ln_sig_y_held": (math.log(0.05), 2.5),
    "ln_sig_q": (math.log(2000.0), 2.5),     # W/√h
    "ln_r_q": (math.log(0.03), 1.0),         # class 2–3 meters, per-sample noise 0–10 %
}

#: Initial state: the mass about the first reading (SD, K); the emitter above it (mean, SD, K);
#: the heat input about the first hour's mean power (SD: a share of it plus a floor, W).
T_M0_SD_K = 3.0
T_E0_MEAN_K, T_E0_SD_K = 5.0, 15.0
P_E0_SHARE, P_E0_FLOOR_W = 0.5, 200.0


@lru_cache(maxsize=4)
def population_coordinates(ach_vent: float, ach_infl: float, n: int = PRIOR_HOUSEHOLDS,
                           seed: int = PRIOR_SEED) -> tuple[np.ndarray, np.ndarray]:
    """(classified parameters (N, 3), (ln C_m, β's unconstrained value, κ) (N, 3)) of the
    prior population, in this model's coordinates."""
    from ...model.house import conductances
    from ...population.households import sample_population
    from .model import from_5r1c

    t = sample_population(n, seed)
    net = conductances(*(t[c].to_numpy(float) for c in (
        "floor_area", "wall_height", "walls_area", "windows_area", "c_f", "u_walls",
        "u_windows")), ach_vent, ach_infl)
    h_a, h_im, h_b = from_5r1c(net.h_ve, net.h_tr_is, net.h_tr_w, net.h_tr_ms, net.h_tr_em)
    hlc = h_a + h_im * h_b / (h_im + h_b)
    beta = h_a / hlc
    lo, hi = BETA_BOX
    f = np.clip((beta - lo) / (hi - lo), 1e-6, 1 - 1e-6)
    p = (1 - beta) * hlc
    z = np.stack([np.log(net.c_m_j_per_k), np.log(f / (1 - f)), np.log(h_im / p - 1.0)], 1)
    return t[list(CLASSIFIED)].to_numpy(float), z


def class_prior(ranges: dict | None, probabilities: dict | None, ach_vent: float,
                ach_infl: float) -> tuple[np.ndarray, np.ndarray]:
    """(mean (3,), covariance (3, 3)) of (ln C_m, β, κ) over the prior population inside the
    class ``ranges`` (or mixed by the classes' ``probabilities`` {name: {"lo-hi": p}})."""
    x, z = population_coordinates(float(ach_vent), float(ach_infl))
    w = np.ones(len(x))
    if probabilities:
        for name, rows in probabilities.items():
            col = x[:, list(CLASSIFIED).index(name)]
            pw = np.zeros(len(x))
            for label, p in rows.items():
                lo, hi = (float(v) for v in label.split("-"))
                pw[(col >= lo) & (col < hi)] = p
            w = w * pw
    elif ranges:
        for name, (lo, hi) in ranges.items():
            if name in CLASSIFIED:
                col = x[:, list(CLASSIFIED).index(name)]
                w = w * ((col >= lo) & (col <= hi))
    if w.sum() <= 0:
        w = np.ones(len(x))
    w = w / w.sum()
    mean = w @ z
    d = z - mean
    cov = (d * w[:, None]).T @ d + 1e-6 * np.eye(3)
    return mean, cov


@dataclass
class Priors:
    """Per household: the class prior (mean, precision) on (ln C_m, β, κ) and the night gain."""

    mean: torch.Tensor        # (H, 3)
    precision: torch.Tensor   # (H, 3, 3)
    gain_w: torch.Tensor      # (H,) declared value or prior centre [W]
    gain_sd_w: torch.Tensor   # (H,) SD of a declared gain, or of the gain prior [W]
    offset_sd_k: torch.Tensor  # (H,) sensor-offset SD behind the Φ_0 prior [K] (0: declared)
    pinned: torch.Tensor      # (H,) bool: Φ_0 fixed at gain_w (declared with SD 0)


_CLASS_COLS = [IDX["ln_c_m"], IDX["beta"], IDX["kappa"]]


def neg_log_prior(u: torch.Tensor, pri: Priors) -> torch.Tensor:
    """−ln p(u) per household (H,), up to constants."""
    d = u[:, _CLASS_COLS] - pri.mean
    out = 0.5 * torch.einsum("hi,hij,hj->h", d, pri.precision, d)
    x = physical(u)
    for name, (mu, sd) in LN_PRIORS.items():
        if name in ("share_i", "share_e", "tau_e", "ln_r_q"):
            v = {"share_i": x.c_i / x.c_m, "share_e": x.c_e / x.c_m,
                 "tau_e": x.tau_e_s / 3600.0, "ln_r_q": x.r_q}[name]
            out = out + 0.5 * ((torch.log(v) - mu) / sd) ** 2
        else:
            out = out + 0.5 * ((u[:, IDX[name]] - mu) / sd) ** 2
    sd_w = torch.sqrt(pri.gain_sd_w ** 2 + (pri.offset_sd_k * x.hlc) ** 2 + 1e-6)
    gain_term = 0.5 * ((x.phi0_w - pri.gain_w) / sd_w) ** 2 + torch.log(sd_w)
    return out + torch.where(pri.pinned, torch.zeros_like(gain_term), gain_term)


def initial_state(u: torch.Tensor, b: Batch) -> tuple[torch.Tensor, torch.Tensor]:
    """(x0 (H, N, 4), P0 (H, N, 4, 4)), the same for every parameter value (a prior that moved
    with the parameters would let them buy a better start): T_i at its first reading, T_m and
    the emitter about it (SDs :data:`T_M0_SD_K`, :data:`T_E0_SD_K`), the heat input at the first
    hour's mean metered power."""
    x0 = torch.stack([b.y0, b.y0, b.y0 + T_E0_MEAN_K, b.q0], -1).expand(
        len(u), *b.y0.shape[1:], 4)
    sd = torch.stack([torch.full_like(b.y0, 0.3), torch.full_like(b.y0, T_M0_SD_K),
                      torch.full_like(b.y0, T_E0_SD_K), P_E0_SHARE * b.q0 + P_E0_FLOOR_W], -1)
    return x0, torch.diag_embed(sd ** 2)


def augmented(u: torch.Tensor, b: Batch) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The exact discrete transition of (T_i, T_m, T_e, Q) over the household's step:
    (Φ (H, 4, 4), Γu (H, N, T, 4), Q_d (H, 4, 4)); Q is held over each interval and then
    takes its random-walk step."""
    a, bb, g = matrices(u)
    phi3, gam, qd3 = discretise(a, bb, g, b.dt_s)
    h = len(u)
    phi = torch.zeros(h, 4, 4, dtype=DTYPE)
    phi[:, :3, :3] = phi3
    phi[:, :3, 3] = gam[:, :, 1]
    phi[:, 3, 3] = 1.0
    qd = torch.zeros(h, 4, 4, dtype=DTYPE)
    qd[:, :3, :3] = qd3
    qd[:, 3, 3] = physical(u).sig_q ** 2 * b.dt_s
    gam_u = torch.einsum("hij,hntj->hnti", gam[:, :, [0, 2]], b.u)
    gam_u = torch.cat([gam_u, torch.zeros_like(gam_u[..., :1])], -1)
    return phi, gam_u, qd


def neg_log_likelihood(u: torch.Tensor, b: Batch, innovations: bool = False):
    """Σ over each household's nights of the Kalman NLL (H,); with ``innovations`` also the
    standardised innovations (H, N, T, 2) of T_air and of the metered power."""
    phi, gam_u, qd = augmented(u, b)
    x = physical(u)
    sig_y2 = torch.where(b.constrained, (x.sig_y ** 2)[:, None], (x.sig_y_held ** 2)[:, None])
    r = torch.stack([(sig_y2 + b.quantum_k[:, None] ** 2 / 12.0)[..., None].expand(
                        b.y.shape[:-1]),
                     (x.r_q[:, None, None] * b.y[..., 1].abs() + Q_FLOOR_W) ** 2], -1)
    x0, p0 = initial_state(u, b)
    nll, z = filter_nll(phi[:, None], gam_u, qd[:, None], x0, p0, b.y, r, b.observed,
                        (0, 3))
    total = (nll * b.night_mask).sum(1)
    return (total, z) if innovations else total


def neg_log_posterior(u: torch.Tensor, b: Batch, pri: Priors) -> torch.Tensor:
    return neg_log_likelihood(u, b) + neg_log_prior(u, pri)


def free_mask(pri: Priors) -> torch.Tensor:
    """(H, P) bool: the parameters the optimiser moves (Φ_0 pinned when declared with SD 0)."""
    m = torch.ones(len(pri.gain_w), N_PARAMS, dtype=torch.bool)
    m[:, IDX["phi0"]] = ~pri.pinned
    m[:, IDX["ln_sig_m"]] = False
    return m


def as_priors(rows: list[tuple[np.ndarray, np.ndarray, float, float, float]]) -> Priors:
    """Priors of several households from (mean, cov, gain_w, gain_sd_w, offset_sd_k) rows;
    a gain with both SDs 0 is pinned."""
    mean = torch.as_tensor(np.array([r[0] for r in rows]), dtype=DTYPE)
    prec = torch.linalg.inv(torch.as_tensor(np.array([r[1] for r in rows]), dtype=DTYPE))
    col = lambda i: torch.as_tensor([float(r[i]) for r in rows], dtype=DTYPE)  # noqa: E731
    return Priors(mean, prec, col(2), col(3), col(4), (col(3) <= 0) & (col(4) <= 0))
