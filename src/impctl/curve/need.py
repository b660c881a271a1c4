"""The heating curve this house needs: the lowest flow temperature against the outdoor
temperature that holds the owner's setpoint, at the upper bound of the heat it needs.

**Heat need.** At outdoor θ_e the room at the setpoint θ_set needs
Q(θ_e) = HLC·(θ_set − θ_e) − G [W]. HLC comes from the fit (its value and 95 % interval); where
the file also holds :data:`SIGNATURE_NIGHTS` or more of the owner's own nights over at least
:data:`SIGNATURE_RANGE_K` of indoor–outdoor difference (nights the fit did not use), their
energy signature — each night's heat against its indoor–outdoor difference, a straight line —
gives a second HLC, and the two are combined by their precisions (log scale). G,
the heat the house gets besides the heating, is read from what the heating delivered on the
steady night blocks: G = HLC·(θ_air − θ_e) − Q for each block, averaged. The need is thereby
anchored on the heat measured at the nights' outdoor temperatures and extrapolated with the
HLC: at the nights' own temperatures the HLC hardly matters (a higher HLC comes with a higher
G), further out its interval widens the need. Without steady night blocks G is the fit's
night gain.

**Flow temperature.** The emitter (:mod:`.emitter`) must give Q at the room's setpoint: mean
water θ_set + (Q/K)^(1/n); the flow runs Q/(2ṁc) above it.

**Upper bound.** :data:`DRAWS` draws of HLC (log-normal from its interval), G (its mean over
the blocks under that HLC, spread as much as it varies from one night to the next: the room
must stay warm on the night the occupants, the appliances and the storage give least, not on
the average one), ln K and n (their posterior) give the flow needed at each outdoor
temperature; the curve's bound is their :data:`CONFIDENCE` quantile, and the stated margin is
added on top.

**The curve.** A heat pump runs a line through two points (Kronoterm: the flows at −15 and
+15 °C outdoor). The bound bows out on both sides of the nights' own temperatures (a steeper
heat loss raises the need when it is colder and lowers it when it is milder), and no line
follows a bow. Where it is colder than the nights — the heat loss extrapolated, where rooms
get cold — the line stays at or above the bound plus the margin, down to the winter's
:data:`COLD_QUANTILE` quantile (below it the line runs on: hours too rare to bound, where the
comfort watch raises the curve if a cold snap proves it short); where it is milder, at or
above the bound and the central need plus the margin. Within that, with points not below
:data:`FLOW_LIMITS_C`'s lower limit, it is the line lowest on average over the winter's
heating (its hours weighted by the heat they need): a linear programme in two unknowns. A
line with a point above the upper limit and above the running curve's own point there is
advice only: impctl does not write it (:func:`writable`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .emitter import EmitterFit

#: Outdoor temperatures of the curve's two points [°C] (Kronoterm loop-1 2309 and 2314).
POINTS_T_OUT_C = (-15.0, 15.0)
#: The outdoor grid the need is worked out on [°C].
GRID_T_OUT_C = np.arange(-15.0, 15.0 + 1e-9, 0.5)
#: Monte Carlo draws of the need.
DRAWS = 2000
#: One-sided confidence of the bound [-].
CONFIDENCE = 0.95
#: The flow temperatures a curve point may take [°C].
FLOW_LIMITS_C = (20.0, 55.0)
#: Quantile of the winter's hourly outdoor temperatures above which the bound holds [-].
COLD_QUANTILE = 0.01
#: SD of the HLC as a fraction when the fit gives no interval [-] (assumed).
HLC_SD_ASSUMED = 0.15
#: Fewest owner nights an energy signature is read from.
SIGNATURE_NIGHTS = 6
#: Narrowest range of indoor–outdoor difference [K] a signature is read over.
SIGNATURE_RANGE_K = 5.0
#: Floor of G's night-to-night SD [W] (the heat meter's noise over a night).
GAIN_SD_FLOOR_W = 30.0
#: G's night-to-night SD with a single night to read it from [W] (assumed: the fit's prior SD
#: of the night gain, :mod:`impctl.imp.gain`).
GAIN_SD_ONE_NIGHT_W = 87.0


class NeedUnknown(ValueError):
    """The inputs do not give the heat need (the message says what is missing)."""


def heat_w(hlc_w_per_k, gain_w, setpoint_c, t_out_c):
    """The heat a house of heat loss ``hlc_w_per_k`` [W/K] and other heat ``gain_w`` [W]
    needs to hold ``setpoint_c`` at ``t_out_c`` [°C]: HLC·(T_set − T_out) − G, at least 0 [W]
    (arrays broadcast: draws × hours)."""
    return np.maximum(hlc_w_per_k * (setpoint_c - t_out_c) - gain_w, 0.0)


@dataclass(frozen=True)
class HeatNeed:
    """What the heat need rests on.

    Attributes
    ----------
    hlc_w_per_k, hlc_low, hlc_high : the fit's HLC and its 95 % interval [W/K].
    hlc_source : "fit" or "nights" (an energy signature of the blocks).
    gain_w, gain_sd_w : G and how much it varies from night to night (the SD of one night's
        G about the mean, the mean's own uncertainty included) [W].
    gain_source : "measured" (the night blocks) or "fit" (the fit's night gain).
    anchor_t_out_c : mean outdoor temperature of the blocks G was read from [°C] (or None).
    blocks, nights : the night blocks and nights used.
    """

    hlc_w_per_k: float
    hlc_low: float
    hlc_high: float
    hlc_source: str
    gain_w: float
    gain_sd_w: float
    gain_source: str
    anchor_t_out_c: float | None
    blocks: int
    nights: int
    _x: np.ndarray  # θ_air − θ_e of the blocks [K]
    _q: np.ndarray  # their heat [W]

    @property
    def hlc_sd_log(self) -> float:
        """SD of ln HLC from the 95 % interval."""
        if self.hlc_low > 0 and self.hlc_high > self.hlc_low:
            return math.log(self.hlc_high / self.hlc_low) / (2 * 1.96)
        return HLC_SD_ASSUMED

    def q_w(self, setpoint_c: float, t_out_c: np.ndarray) -> np.ndarray:
        """Central heat need [W] at ``t_out_c`` (≥ 0)."""
        return heat_w(self.hlc_w_per_k, self.gain_w, setpoint_c, t_out_c)

    def draws(self, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
        """``n`` draws of (HLC [W/K], G [W]) (module docstring)."""
        hlc = self.hlc_w_per_k * np.exp(self.hlc_sd_log * rng.standard_normal(n))
        if self.gain_source == "measured":
            gain = hlc * float(np.mean(self._x)) - float(np.mean(self._q))
        else:
            gain = np.full(n, self.gain_w)
        return hlc, gain + self.gain_sd_w * rng.standard_normal(n)

    def to_dict(self) -> dict:
        """The JSON block ``heat_need``."""
        return {
            "hlc_w_per_k": {"value": self.hlc_w_per_k, "low": self.hlc_low,
                            "high": self.hlc_high, "source": self.hlc_source},
            "gain_w": {"value": self.gain_w, "sd": self.gain_sd_w, "source": self.gain_source},
            "anchor_t_out_c": self.anchor_t_out_c, "blocks": self.blocks, "nights": self.nights,
        }


def heat_need(blocks: pd.DataFrame, fit: dict | None) -> HeatNeed:
    """The heat need from the steady night blocks and the fit JSON ``fit`` (module docstring).

    Raises
    ------
    NeedUnknown
        Neither a fit nor enough blocks to read an HLC from.
    """
    night = blocks[blocks["night"].astype(bool)] if len(blocks) else blocks
    if len(night) == 0:
        night = blocks  # no night block: the day's blocks hold more gains (said in the notes)
    x = (night["t_air_c"] - night["t_out_c"]).to_numpy(dtype=float)
    q = night["q_w"].to_numpy(dtype=float)
    groups = night["evening"].to_numpy() if len(night) else np.array([])
    own = (night["kind"] == "owner").to_numpy() if len(night) else np.zeros(0, bool)
    signature = None
    if len(set(groups[own])) >= SIGNATURE_NIGHTS and np.ptp(x[own]) >= SIGNATURE_RANGE_K:
        signature = _signature(x[own], q[own], groups[own])
    if fit is not None:
        hlc = fit["lumped"]["hlc"]
        value = float(hlc["value"])
        low = float(hlc["low"]) if hlc.get("low") is not None else value * (1 - 2 * HLC_SD_ASSUMED)
        high = (float(hlc["high"]) if hlc.get("high") is not None
                else value * (1 + 2 * HLC_SD_ASSUMED))
        source = "fit"
        if signature is not None:
            value, low, high = _combine((value, low, high), signature)
            source = "fit and the owner's nights"
    elif signature is not None:
        value, low, high = signature
        source = "the owner's nights"
    elif len(night) >= 3 and np.ptp(x) >= 4.0:
        value, low, high = _signature(x, q, groups)
        source = "nights"
    else:
        raise NeedUnknown("no fit given (--fit FIT.json from impctl fit) and too few steady "
                          "night blocks over too narrow a range of outdoor temperatures to "
                          "read the house's heat loss from")
    if len(night):
        g_blocks = value * x - q
        per_night = pd.Series(g_blocks).groupby(groups).mean().to_numpy()
        m = len(per_night)
        sd = (float(np.std(per_night, ddof=1)) * math.sqrt(1.0 + 1.0 / m) if m > 1
              else GAIN_SD_ONE_NIGHT_W)
        return HeatNeed(value, low, high, source, float(np.mean(g_blocks)),
                        max(sd, GAIN_SD_FLOOR_W), "measured",
                        float(night["t_out_c"].mean()), int(len(night)),
                        int(len(set(groups))), x, q)
    gain = (fit or {}).get("fit", {}).get("night_gain", {})
    g, sd = gain.get("value_w"), gain.get("sd_w")
    if g is None:
        raise NeedUnknown("no steady night block with the heating on, and the fit gives no "
                          "night gain")
    return HeatNeed(value, low, high, source, float(g), float(sd or 0.0), "fit", None, 0, 0,
                    np.zeros(0), np.zeros(0))


def _combine(a: tuple[float, float, float],
             b: tuple[float, float, float]) -> tuple[float, float, float]:
    """Two (value, low, high) 95 % estimates combined by precision on the log scale."""
    def log_sd(v):
        return max(math.log(v[2] / v[1]) / (2 * 1.96), 1e-3) if v[1] > 0 else HLC_SD_ASSUMED
    wa, wb = 1 / log_sd(a) ** 2, 1 / log_sd(b) ** 2
    mean = (wa * math.log(a[0]) + wb * math.log(b[0])) / (wa + wb)
    sd = 1 / math.sqrt(wa + wb)
    return math.exp(mean), math.exp(mean - 1.96 * sd), math.exp(mean + 1.96 * sd)


def _signature(x: np.ndarray, q: np.ndarray, groups: np.ndarray) -> tuple[float, float, float]:
    """HLC [W/K] and its 95 % interval from Q = HLC·x − G over the blocks (night means)."""
    frame = pd.DataFrame({"x": x, "q": q, "g": groups}).groupby("g").mean()
    xx, qq = frame["x"].to_numpy(), frame["q"].to_numpy()
    if len(xx) < 3 or np.ptp(xx) < 2.0:
        xx, qq = x, q
    a = np.column_stack([xx, -np.ones(len(xx))])
    coef, *_ = np.linalg.lstsq(a, qq, rcond=None)
    resid = qq - a @ coef
    s2 = float(np.sum(resid**2) / max(len(qq) - 2, 1))
    cov = s2 * np.linalg.inv(a.T @ a)
    hlc, sd = float(coef[0]), math.sqrt(cov[0, 0])
    if hlc <= 0:
        raise NeedUnknown("the nights' heat does not grow as it gets colder outside: no heat "
                          "loss can be read from them; give --fit FIT.json")
    return hlc, max(hlc - 1.96 * sd, 0.1 * hlc), hlc + 1.96 * sd


@dataclass(frozen=True)
class NeedCurve:
    """The flow needed on :data:`GRID_T_OUT_C`: ``central`` (median of the draws) and
    ``upper`` (the :data:`CONFIDENCE` quantile) [°C], and the central heat need [W]."""

    t_out_c: np.ndarray
    central_c: np.ndarray
    upper_c: np.ndarray
    q_w: np.ndarray


def need_curve(need: HeatNeed, emitter: EmitterFit, setpoint_c: float,
               rng: np.random.Generator, draws: int = DRAWS) -> NeedCurve:
    """The flow needed at each outdoor temperature of the grid (module docstring)."""
    t = GRID_T_OUT_C
    hlc, gain = need.draws(rng, draws)
    ln_k, n = emitter.draws(rng, draws)
    q = np.maximum(hlc[:, None] * (setpoint_c - t[None, :]) - gain[:, None], 0.0)
    d = (q / np.exp(ln_k)[:, None]) ** (1.0 / n[:, None])
    flow = setpoint_c + d + q / (2.0 * emitter.flow_w_per_k)
    return NeedCurve(t, np.median(flow, axis=0), np.quantile(flow, CONFIDENCE, axis=0),
                     need.q_w(setpoint_c, t))


@dataclass(frozen=True)
class Line:
    """A heating curve: flow temperatures [°C] at the two points :data:`POINTS_T_OUT_C`."""

    flow_a_c: float
    flow_b_c: float

    def at(self, t_out_c: np.ndarray | float) -> np.ndarray:
        """Flow temperature at ``t_out_c`` [°C] (the line, extrapolated)."""
        a, b = POINTS_T_OUT_C
        s = (np.asarray(t_out_c, dtype=float) - a) / (b - a)
        return self.flow_a_c + (self.flow_b_c - self.flow_a_c) * s

    def to_dict(self) -> dict:
        """``{"t_out_c": [−15, 15], "flow_c": [a, b], "flow_at_0_c": …}``."""
        return {"t_out_c": list(POINTS_T_OUT_C),
                "flow_c": [round(self.flow_a_c, 1), round(self.flow_b_c, 1)],
                "flow_at_0_c": round(float(self.at(0.0)), 1)}


def required_flow_c(curve: NeedCurve, margin_k: float, setpoint_c: float, cold_c: float,
                    anchor_c: float) -> np.ndarray:
    """What the line must reach on the grid [°C] (module docstring, "The curve"); −inf below
    ``cold_c``, where nothing is required."""
    t = curve.t_out_c
    colder = curve.upper_c + margin_k
    milder = np.maximum(curve.upper_c, curve.central_c + margin_k)
    need = np.maximum(np.where(t <= anchor_c, colder, milder), setpoint_c + margin_k)
    return np.where(t >= min(cold_c, anchor_c), need, -np.inf)


def recommend(curve: NeedCurve, margin_k: float, weights: np.ndarray, setpoint_c: float,
              cold_c: float = -15.0, anchor_c: float = 0.0) -> Line:
    """The lowest line at or above :func:`required_flow_c` on the grid, weighted by
    ``weights`` (heat per grid temperature), points at least :data:`FLOW_LIMITS_C`'s lower
    limit (whether impctl may set it: :func:`writable`).

    A linear programme in two unknowns (the flows at the two points): its optimum is a vertex,
    a line through two of the constraints' points (the floor of a curve point is the point
    (±15 °C, floor)), so every such line is tried and the feasible one of least cost kept.
    """
    need = required_flow_c(curve, margin_k, setpoint_c, cold_c, anchor_c)
    a, b = POINTS_T_OUT_C
    lo = FLOW_LIMITS_C[0]
    held = np.isfinite(need)
    t_pts = np.concatenate([curve.t_out_c[held], [a, b]])
    f_pts = np.concatenate([need[held], [lo, lo]])
    i, j = np.triu_indices(len(t_pts), k=1)
    ok = np.abs(t_pts[j] - t_pts[i]) > 1e-9
    i, j = i[ok], j[ok]
    slope = (f_pts[j] - f_pts[i]) / (t_pts[j] - t_pts[i])
    fa = f_pts[i] + slope * (a - t_pts[i])
    fb = f_pts[i] + slope * (b - t_pts[i])
    s_held = (curve.t_out_c[held] - a) / (b - a)
    lines = fa[:, None] + (fb - fa)[:, None] * s_held[None, :]
    feasible = (np.all(lines >= need[held][None, :] - 1e-6, axis=1)
                & (fa >= lo - 1e-9) & (fb >= lo - 1e-9))
    s = (curve.t_out_c - a) / (b - a)
    w = np.asarray(weights, dtype=float) + 1e-6 * max(float(np.sum(weights)), 1.0)
    cost = fa * np.sum(w * (1 - s)) + fb * np.sum(w * s)
    best = int(np.argmin(np.where(feasible, cost, np.inf)))
    return Line(float(fa[best]), float(fb[best]))


def writable(line: Line, running: Line | None) -> bool:
    """Whether impctl may set ``line``'s points: each within :data:`FLOW_LIMITS_C`, or up to
    the running curve's own point where that is higher (a value the controller already runs;
    the daemon checks against the controller's own points 2309/2314)."""
    lo, hi = FLOW_LIMITS_C
    points = (line.flow_a_c, line.flow_b_c)
    own = ((running.flow_a_c, running.flow_b_c) if running is not None
           else (-math.inf, -math.inf))
    return all(lo <= p <= max(hi, o) for p, o in zip(points, own, strict=True))
