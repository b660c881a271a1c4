"""The night as a continuous–discrete stochastic state-space model (CTSM-R style), torch float64.

States x = (T_i, T_m, T_e) [°C]: the air node with the air and furniture capacity C_i, the
thermal mass C_m,state, and the emitter C_e, charged by the metered heat Q_HC and releasing it to
the air through G_e = C_e/τ_e::

    C_i dT_i = [H_a (T_o − T_i) + H_im (T_m − T_i) + G_e (T_e − T_i) + β Φ_0] dt + σ_i C_i dw_i
    C_m dT_m = [H_im (T_i − T_m) + H_b (T_o − T_m) + (1 − β) Φ_0] dt          + σ_m C_m dw_m
    C_e dT_e = [Q_HC − G_e (T_e − T_i)] dt                                     + σ_e C_e dw_e
    y_k = T_i(t_k) + ε_k,   ε_k ~ N(0, σ_y² + δ²/12)

with δ the room sensor's resolution (read from the data) and σ_y one per kind of night (a
held room sensor reads a steadier value than a free-cooling one).

The heat that reaches the emitter over the interval [t_k, t_k+1) is a latent, piecewise-constant
state Q_k (a random walk, Q_k+1 = Q_k + η_k, η_k ~ N(0, σ_q²Δt)), and the metered power is a
second measurement of it, q_k = Q_k + ε_k with SD r_q·|q_k| + :data:`Q_FLOOR_W` (per-sample
meter error). On a held night the controller sets the heat that keeps T_air at its setpoint, so
a noisy metered power as a plain input would be errors in the variables (identifiability.md
§11.3); as a measurement of a latent input the filter weighs it against what T_air says.

Inputs u = (T_o, Q_HC, 1) of the continuous part (Q_HC is the latent Q_k); Φ_0 [W] is a
constant heat input (unmetered night gain, and the
intercept an indoor/outdoor sensor offset makes: HLC·offset), split between air and mass as the
losses are (β the share of the HLC that bypasses the mass).

The three conductances are the 5R1C's after eliminating its massless surface node (star–mesh:
H_a = H_ve + H_is·H_w/S, H_im = H_is·H_ms/S, H_b = H_em + H_ms·H_w/S, S = H_is + H_w + H_ms),
so every 5R1C house is one parameter set of this model (C_i = C_e = 0). The reported quantities
keep the 5R1C's definitions (:func:`lumped`): HLC = H_a + (H_im ∥ H_b) (steady state),
C_m = C_i + C_m,state + C_e (the whole capacity, as the plant and the classes count it) and
τ = C_m / (H_b + H_im ∥ H_a), i.e. C_m/(H_tr,em + H_tr,3) of the 5R1C.

Unconstrained parameters (one row per household, :data:`NAMES`): ln HLC; ln C_m; β by a sigmoid;
κ = ln(H_im/P − 1) with P = (1 − β)·HLC the mass path (so H_im = P(1 + e^κ), H_b = P(1 + e^−κ));
the air and emitter shares of C_m and τ_e on log-boxes; Φ_0/100 W; the log diffusions σ_i, σ_m,
σ_e [K/√h], the log measurement SD σ_y [K], ln σ_q [W/√h] and ln r_q.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

DTYPE = torch.float64

NAMES = ("ln_hlc", "ln_c_m", "beta", "kappa", "share_i", "share_e", "tau_e", "phi0",
         "ln_sig_i", "ln_sig_m", "ln_sig_e", "ln_sig_y", "ln_sig_q", "ln_r_q", "ln_sig_y_held")
IDX = {n: i for i, n in enumerate(NAMES)}
N_PARAMS = len(NAMES)
N_STATES = 3

#: Log-boxes (lo, hi) of the capacity shares [-] and of τ_e [h]: exp(ln lo + (ln hi − ln lo)·s(u)).
#: Air + furniture ≈ 3–34 kJ/(m²K) of floor against C_m of 80–370 kJ/(m²K) (real-houses.md §1);
#: radiators (36 kJ/K per kW) to a screed of 130–250 kJ/(m²K) on 30–100 % of the floor (§2).
SHARE_I_BOX = (1e-4, 0.3)
SHARE_E_BOX = (1e-4, 0.5)
TAU_E_BOX_H = (1.0 / 60.0, 12.0)
BETA_BOX = (1e-3, 0.95)
PHI0_SCALE_W = 100.0
#: Log-box of the relative per-sample meter noise r_q [-]: a meter is never pure noise (without
#: the box the fit can call the meter noise, lose the HLC's scale and collapse it; measured on
#: the realistic plant, 3 of 10 houses). Class 2–3 meters, low-flow errors (real-houses.md §5).
R_Q_BOX = (0.002, 0.15)
#: Floor of a metered power sample's SD [W] (energy-counter quantisation, a standby reading).
Q_FLOOR_W = 20.0


def _logbox(u: torch.Tensor, box: tuple[float, float]) -> torch.Tensor:
    lo, hi = torch.log(torch.tensor(box, dtype=DTYPE))
    return torch.exp(lo + (hi - lo) * torch.sigmoid(u))


def _logbox_inv(x: float, box: tuple[float, float]) -> float:
    import math

    lo, hi = math.log(box[0]), math.log(box[1])
    f = min(max((math.log(x) - lo) / (hi - lo), 1e-6), 1 - 1e-6)
    return math.log(f / (1 - f))


@dataclass
class Physical:
    """Physical values of parameter rows (each a tensor of the rows' batch shape)."""

    hlc: torch.Tensor      # W/K
    c_m: torch.Tensor      # J/K, whole capacity
    beta: torch.Tensor
    h_a: torch.Tensor      # W/K
    h_im: torch.Tensor
    h_b: torch.Tensor
    c_i: torch.Tensor      # J/K
    c_mass: torch.Tensor
    c_e: torch.Tensor
    g_e: torch.Tensor      # W/K
    tau_e_s: torch.Tensor
    phi0_w: torch.Tensor
    sig_s: torch.Tensor    # (…, 3) diffusion [K/√s]
    sig_y: torch.Tensor    # K
    sig_q: torch.Tensor    # random walk of the heat input [W/√s]
    r_q: torch.Tensor      # relative SD of a metered power sample [-]
    sig_y_held: torch.Tensor  # K, T_air's SD beyond quantisation on held nights


def physical(u: torch.Tensor) -> Physical:
    """Physical values of unconstrained rows u (…, :data:`N_PARAMS`)."""
    hlc = torch.exp(u[..., IDX["ln_hlc"]])
    c_m = torch.exp(u[..., IDX["ln_c_m"]])
    b_lo, b_hi = BETA_BOX
    beta = b_lo + (b_hi - b_lo) * torch.sigmoid(u[..., IDX["beta"]])
    p = (1.0 - beta) * hlc
    kappa = u[..., IDX["kappa"]]
    h_im = p * (1.0 + torch.exp(kappa))
    h_b = p * (1.0 + torch.exp(-kappa))
    s_i = _logbox(u[..., IDX["share_i"]], SHARE_I_BOX)
    s_e = _logbox(u[..., IDX["share_e"]], SHARE_E_BOX)
    c_i, c_e = s_i * c_m, s_e * c_m
    tau_e_s = 3600.0 * _logbox(u[..., IDX["tau_e"]], TAU_E_BOX_H)
    sig = torch.exp(u[..., IDX["ln_sig_i"]:IDX["ln_sig_e"] + 1]) / 60.0   # K/√h → K/√s
    return Physical(hlc=hlc, c_m=c_m, beta=beta, h_a=beta * hlc, h_im=h_im, h_b=h_b, c_i=c_i,
                    c_mass=c_m - c_i - c_e, c_e=c_e, g_e=c_e / tau_e_s, tau_e_s=tau_e_s,
                    phi0_w=PHI0_SCALE_W * u[..., IDX["phi0"]], sig_s=sig,
                    sig_y=torch.exp(u[..., IDX["ln_sig_y"]]),
                    sig_q=torch.exp(u[..., IDX["ln_sig_q"]]) / 60.0,
                    r_q=_logbox(u[..., IDX["ln_r_q"]], R_Q_BOX),
                    sig_y_held=torch.exp(u[..., IDX["ln_sig_y_held"]]))


def lumped(u: torch.Tensor) -> torch.Tensor:
    """(HLC [W/K], C_m [J/K], τ [h]) of rows u (…, P) → (…, 3), the 5R1C's definitions."""
    x = physical(u)
    tau_h = x.c_m / (x.h_b + x.h_im * x.h_a / (x.h_im + x.h_a)) / 3600.0
    return torch.stack([x.hlc, x.c_m, tau_h], dim=-1)


def matrices(u: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Continuous-time A (…, 3, 3), B (…, 3, 3) for inputs (T_o, Q_HC, 1), and the diffusion
    G (…, 3, 3) (diagonal, K/√s), of rows u (…, P). Time in seconds."""
    x = physical(u)
    z = torch.zeros_like(x.hlc)
    ci, cm, ce = x.c_i, x.c_mass, x.c_e
    a = torch.stack([
        torch.stack([-(x.h_a + x.h_im + x.g_e) / ci, x.h_im / ci, x.g_e / ci], -1),
        torch.stack([x.h_im / cm, -(x.h_im + x.h_b) / cm, z], -1),
        torch.stack([x.g_e / ce, z, -x.g_e / ce], -1)], -2)
    b = torch.stack([
        torch.stack([x.h_a / ci, z, x.beta * x.phi0_w / ci], -1),
        torch.stack([x.h_b / cm, z, (1.0 - x.beta) * x.phi0_w / cm], -1),
        torch.stack([z, 1.0 / ce, z], -1)], -2)
    g = torch.diag_embed(x.sig_s)
    return a, b, g


def from_5r1c(h_ve: float, h_is: float, h_w: float, h_ms: float, h_em: float) -> tuple[
        float, float, float]:
    """(H_a, H_im, H_b) [W/K] of a 5R1C network: its surface node eliminated (star–mesh)."""
    s = h_is + h_w + h_ms
    return h_ve + h_is * h_w / s, h_is * h_ms / s, h_em + h_ms * h_w / s


def unconstrained(hlc: float, c_m: float, h_a: float, h_im: float, *, share_i: float = 1e-3,
                  share_e: float = 1e-3, tau_e_h: float = 0.25, phi0_w: float = 0.0,
                  sig_k_per_sqrt_h: tuple[float, float, float] = (0.05, 0.02, 0.2),
                  sig_y_k: float = 0.05, sig_q_w_per_sqrt_h: float = 2000.0,
                  r_q: float = 0.05) -> torch.Tensor:
    """One unconstrained row from physical values (the inverse of :func:`physical`)."""
    import math

    beta = h_a / hlc
    b_lo, b_hi = BETA_BOX
    fb = min(max((beta - b_lo) / (b_hi - b_lo), 1e-6), 1 - 1e-6)
    p = (1.0 - beta) * hlc
    row = [math.log(hlc), math.log(c_m), math.log(fb / (1 - fb)),
           math.log(max(h_im / p - 1.0, 1e-9)), _logbox_inv(share_i, SHARE_I_BOX),
           _logbox_inv(share_e, SHARE_E_BOX), _logbox_inv(tau_e_h, TAU_E_BOX_H),
           phi0_w / PHI0_SCALE_W, *(math.log(s) for s in sig_k_per_sqrt_h), math.log(sig_y_k),
           math.log(sig_q_w_per_sqrt_h), _logbox_inv(r_q, R_Q_BOX), math.log(sig_y_k)]
    return torch.tensor(row, dtype=DTYPE)
