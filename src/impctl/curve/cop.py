"""How efficiently the heat pump turns electricity into heat, against its flow temperature.

COP = η · T_flow / (T_flow − T_out + δ) (temperatures in kelvin): a fraction η of the Carnot
COP between the flow and the outdoor air, δ = :data:`LIFT_OFFSET_K` standing for the heat
exchangers' temperature differences. Lowering the flow by 1 K raises it by about 2–3 %.

Where the nights carry the heat pump's electrical power (``p_el_w``) and its heat (``q_hc``),
η is fitted to them: each steady block's COP is its heat over its electricity, its T_flow the
flow while the heat pump delivers heat; η is their mean and its uncertainty their spread over
the nights. Without ``p_el_w`` η is :data:`ETA_ASSUMED` — an assumption, labelled as one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

#: δ [K] (assumed: a few kelvin in each heat exchanger).
LIFT_OFFSET_K = 5.0
#: η and its SD when the nights carry no electrical power [-] (assumed: air-to-water heat
#: pumps reach 0.35–0.55 of Carnot in the field).
ETA_ASSUMED = (0.45, 0.08)
#: Fewest blocks η is fitted from.
MIN_BLOCKS = 3
#: Plausible range of a block's η [-] (outside: a reading problem, the block is left out).
ETA_PLAUSIBLE = (0.15, 0.8)
#: The COP range the model is clipped to [-].
COP_RANGE = (1.0, 8.0)


def carnot_cop(flow_c: np.ndarray, t_out_c: np.ndarray, eta: np.ndarray | float) -> np.ndarray:
    """COP at flow ``flow_c`` and outdoor ``t_out_c`` [°C] for Carnot fraction ``eta``."""
    hot = np.asarray(flow_c, dtype=float) + 273.15
    lift = np.maximum(hot - (np.asarray(t_out_c, dtype=float) + 273.15) + LIFT_OFFSET_K, 1.0)
    return np.clip(np.asarray(eta) * hot / lift, *COP_RANGE)


@dataclass(frozen=True)
class CopModel:
    """η (with its SD) and whether it was fitted to this heat pump or assumed."""

    eta: float
    eta_sd: float
    assumed: bool
    blocks: int

    def draws(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` draws of η, kept inside :data:`ETA_PLAUSIBLE`."""
        return np.clip(self.eta + self.eta_sd * rng.standard_normal(n), *ETA_PLAUSIBLE)

    def to_dict(self) -> dict:
        """The JSON block ``cop``."""
        return {"model": "carnot_fraction", "eta": round(self.eta, 3),
                "eta_sd": round(self.eta_sd, 3), "lift_offset_k": LIFT_OFFSET_K,
                "assumed": self.assumed, "blocks": self.blocks,
                "cop_at_35_and_0_c": round(float(carnot_cop(35.0, 0.0, self.eta)), 2)}


def fit_cop(blocks: pd.DataFrame) -> CopModel:
    """η from the steady blocks that carry electrical power (module docstring)."""
    p = blocks["p_el_w"].to_numpy(dtype=float)
    q = blocks["q_w"].to_numpy(dtype=float)
    flow = blocks["t_flow_run_c"].to_numpy(dtype=float)
    t_out = blocks["t_out_c"].to_numpy(dtype=float)
    ok = np.isfinite(p) & (p > 50.0) & np.isfinite(flow) & (q > 0)
    if ok.sum() < MIN_BLOCKS:
        return CopModel(*ETA_ASSUMED, assumed=True, blocks=0)
    eta = (q[ok] / p[ok]) / carnot_cop(flow[ok], t_out[ok], 1.0)
    groups = blocks["evening"].to_numpy()[ok]
    plausible = (eta >= ETA_PLAUSIBLE[0]) & (eta <= ETA_PLAUSIBLE[1])
    if plausible.sum() < MIN_BLOCKS:
        return CopModel(*ETA_ASSUMED, assumed=True, blocks=0)
    eta, groups = eta[plausible], groups[plausible]
    per_night = pd.Series(eta).groupby(groups).mean().to_numpy()
    sd = (float(np.std(per_night, ddof=1)) / math.sqrt(len(per_night)) if len(per_night) > 1
          else 0.05)
    return CopModel(float(np.mean(eta)), max(sd, 0.01), assumed=False,
                    blocks=int(plausible.sum()))
