"""How a household's nights are combined into one row for the classifiers.

A *campaign* is any set of a household's nights (all of them, or the few a real IMP campaign
measured). Its row aggregates the night features (:data:`impctl.imp.NIGHT_FEATURES`) per kind —
medians over the constrained nights, a regression over the normal nights — and combines the two
kinds into τ and C_m estimates, which no single night can give (temperature alone fixes τ, the heat
output fixes the scale). The forest then classifies that row: nights are combined *before*
classification, not by voting.

Constrained nights enter through their decay rate (≈ 1/τ), the decay rate of their first 2 h
after the cut and their mean T_out. The gateway ends a constrained night at T_min, so the
whole-night decay rate is censored where the night stops; the early decay rate reads the same
span on every night (on the gateway's nights: u_walls Brier −0.002 / −0.009 on two seeds,
c_f and floor area unchanged; bench/RESULTS.md "Issue 14: classes on stopped nights", branch
h14x). Their cooling time, temperature drop, cooling rate and indoor–outdoor difference at
the cut are left out. With T_max fixed by the plan, each of them (alone or with the decay
rate) reveals how far T_air fell during the emitter lag, and in the 5R1C that fall is the
massless air node's switch-off drop, which scales with 1/A_f and does not exist in real data
(identifiability.md §11.2). On a 2000-household development population (seed 1, not the
reported seed) keeping them raised the floor-area accuracy from 70 % to 84 % — information a
real house would not give. The cooling time was measured again on the realistic plant (h14x):
it adds nothing on the nights the gateway keeps (valid: ≥ 3 h after the lag), and helps c_f
only on nights that stop at T_min sampled every 10 min after the lag, which the gateway does
not record.

Missing kinds give NaN features; the forests handle NaN (scikit-learn ≥ 1.4), and they are
trained on campaigns of random sizes, including campaigns with only one kind of night.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Mapping

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..imp import NIGHT_FEATURE_NAMES
from ..population.imp_run.gateway import campaign_runs

#: (name, unit, meaning) of every campaign feature, in column order.
CAMPAIGN_FEATURES: tuple[tuple[str, str, str], ...] = (
    ("c_decay_rate_per_h", "1/h", "median decay_rate_per_h of the constrained nights"),
    ("c_t_out_mean_c", "°C", "median t_out_mean_c of the constrained nights"),
    ("c_decay_rate_early_per_h", "1/h", "median decay_rate_early_per_h of the constrained "
                                        "nights (their first 2 h after the cut)"),
    ("n_hlc_w_per_k", "W/K", "normal nights: least-squares slope through the origin of "
                             "q_hc_mean_w on (t_set_c − t_out_mean_c), the heat-loss coefficient"),
    ("n_q_slope_w_per_h", "W/h", "median q_slope_w_per_h of the normal nights"),
    ("n_t_out_mean_c", "°C", "median t_out_mean_c of the normal nights"),
    ("n_q_per_t_out_w_per_k", "W/K", "median q_per_t_out_w_per_k of the normal nights"),
    ("tau_h", "h", "1 / c_decay_rate_per_h, the time constant"),
    ("c_m_mj_per_k", "MJ/K", "tau_h · n_hlc_w_per_k · 3600 / 1e6, the τ·HLC estimate of C_m"),
)
CAMPAIGN_FEATURE_NAMES: tuple[str, ...] = tuple(f[0] for f in CAMPAIGN_FEATURES)

_MEDIAN_OF = {
    "c_decay_rate_per_h": "decay_rate_per_h",
    "c_decay_rate_early_per_h": "decay_rate_early_per_h",
    "n_q_slope_w_per_h": "q_slope_w_per_h",
    "n_q_per_t_out_w_per_k": "q_per_t_out_w_per_k",
}
_IX = {name: i for i, name in enumerate(NIGHT_FEATURE_NAMES)}


def aggregate_nights(values: NDArray, selected: NDArray) -> NDArray[np.float64]:
    """Campaign rows from night feature arrays.

    Parameters
    ----------
    values : array (n_rows, n_nights, n_night_features)
        Night features in :data:`impctl.imp.NIGHT_FEATURE_NAMES` order.
    selected : bool array (n_rows, n_nights)
        The nights of each campaign.

    Returns
    -------
    array (n_rows, n_campaign_features)
        Columns in :data:`CAMPAIGN_FEATURE_NAMES` order.
    """
    x = np.where(selected[..., None], values, np.nan)
    cons = x[..., _IX["is_constrained"]] == 1.0
    norm = x[..., _IX["is_constrained"]] == 0.0

    def of(name: str, kind: NDArray) -> NDArray:
        return np.where(kind, x[..., _IX[name]], np.nan)

    out: dict[str, NDArray] = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # empty campaigns → NaN, as wanted
        for name, src in _MEDIAN_OF.items():
            kind = cons if name.startswith("c_") else norm
            out[name] = np.nanmedian(of(src, kind), axis=1)
        out["c_t_out_mean_c"] = np.nanmedian(of("t_out_mean_c", cons), axis=1)
        out["n_t_out_mean_c"] = np.nanmedian(of("t_out_mean_c", norm), axis=1)
        q = of("q_hc_mean_w", norm)
        dtheta = of("t_set_c", norm) - of("t_out_mean_c", norm)
        ok = np.isfinite(q) & np.isfinite(dtheta)
        sxy = np.where(ok, q * dtheta, 0.0).sum(axis=1)
        sxx = np.where(ok, dtheta * dtheta, 0.0).sum(axis=1)
        out["n_hlc_w_per_k"] = np.where(sxx > 0, sxy / np.where(sxx > 0, sxx, 1.0), np.nan)
        k = out["c_decay_rate_per_h"]
        out["tau_h"] = np.where(k > 0, 1.0 / np.where(k > 0, k, 1.0), np.nan)
        out["c_m_mj_per_k"] = out["tau_h"] * out["n_hlc_w_per_k"] * 3600.0 / 1e6
    return np.stack([out[name] for name in CAMPAIGN_FEATURE_NAMES], axis=1)


def campaign_features(night_rows: Iterable[Mapping[str, float]] | pd.DataFrame
                      ) -> dict[str, float]:
    """The campaign row of one household from its nights' feature rows.

    Parameters
    ----------
    night_rows : DataFrame or iterable of dicts
        Rows of :func:`impctl.imp.night_features` (any extra columns are ignored).

    Returns
    -------
    dict
        Campaign feature name → value (units in :data:`CAMPAIGN_FEATURES`).
    """
    table = pd.DataFrame(list(night_rows) if not isinstance(night_rows, pd.DataFrame)
                         else night_rows)
    values = table.reindex(columns=list(NIGHT_FEATURE_NAMES)).to_numpy(dtype=float)[None]
    row = aggregate_nights(values, np.ones(values.shape[:2], bool))[0]
    return dict(zip(CAMPAIGN_FEATURE_NAMES, row.tolist(), strict=True))


def night_cube(nights: pd.DataFrame) -> tuple[NDArray, NDArray]:
    """Night features as (n_households, nights_per_household, n_features) and household ids.

    ``nights`` must hold the same number of nights for every household (as the virtual IMP
    gives), in a fixed order within each household.
    """
    ordered = nights.sort_values("household", kind="stable")
    ids, counts = np.unique(ordered["household"].to_numpy(), return_counts=True)
    if not (counts == counts[0]).all():
        raise ValueError("every household needs the same number of nights")
    values = ordered[list(NIGHT_FEATURE_NAMES)].to_numpy(dtype=float)
    return values.reshape(len(ids), counts[0], len(NIGHT_FEATURE_NAMES)), ids


def random_campaigns(
    is_constrained: NDArray,
    n_campaigns: int,
    rng: np.random.Generator,
    max_constrained: int = 4,
    max_normal: int = 8,
    n_constrained: int | None = None,
    n_normal: int | None = None,
) -> NDArray[np.bool_]:
    """Masks of random campaigns over one household's night layout.

    Each campaign draws its numbers of constrained and normal nights uniformly from
    0…``max_constrained`` and 0…``max_normal`` (at least one night in all), unless fixed by
    ``n_constrained`` / ``n_normal``, then picks that many nights of each kind at random.

    Parameters
    ----------
    is_constrained : bool array (n_nights,)
    n_campaigns : int
    rng : Generator

    Returns
    -------
    bool array (n_campaigns, n_nights)
    """
    cons = np.asarray(is_constrained, bool)
    size = (n_campaigns,)
    k_c = np.full(size, n_constrained) if n_constrained is not None else \
        rng.integers(0, max_constrained + 1, size)
    k_n = np.full(size, n_normal) if n_normal is not None else \
        rng.integers(0, max_normal + 1, size)
    k_n = np.where((k_c == 0) & (k_n == 0), 1, k_n)
    keys = rng.random((n_campaigns, cons.size))
    out = np.zeros((n_campaigns, cons.size), bool)
    for kind, k in ((cons, k_c), (~cons, k_n)):
        rank = np.argsort(np.argsort(np.where(kind, keys, np.inf), axis=1), axis=1)
        out |= kind & (rank < k[:, None])
    return out


def gateway_campaigns(
    values: NDArray,
    rng: np.random.Generator,
    n_constrained: int = 2,
    n_normal: int = 6,
    max_invalid: int = 3,
) -> NDArray[np.bool_]:
    """Masks of the campaigns the gateway's fixed campaign delivers, one per row of ``values``.

    ``n_normal`` normal nights at random; the constrained nights in random order, each kept if
    valid, until ``n_constrained`` are valid or ``max_invalid`` were not (the gateway gives up:
    ``campaign.max_invalid_nights``), so a campaign may hold fewer. A constrained night is
    invalid when its ``cooling_time_h`` is NaN (the population's verdict: too short after the
    emitter lag, :class:`impctl.population.ImpSimConfig` ``min_usable_h``); invalid nights are
    not in the mask (the gateway neither exports nor classifies them).

    Parameters
    ----------
    values : array (n_rows, n_nights, n_night_features)
        Night features in :data:`impctl.imp.NIGHT_FEATURE_NAMES` order, one household per row,
        all rows with the same night layout.
    rng : Generator

    Returns
    -------
    bool array (n_rows, n_nights)
    """
    cons = values[0, :, _IX["is_constrained"]] == 1.0
    out = random_campaigns(cons, len(values), rng, n_constrained=0, n_normal=n_normal)
    valid = np.isfinite(values[..., _IX["cooling_time_h"]])
    for row in range(len(values)):
        order = rng.permutation(np.flatnonzero(cons))
        ok = valid[row, order]
        out[row, order[campaign_runs(ok, n_constrained, max_invalid) & ok]] = True
    return out
