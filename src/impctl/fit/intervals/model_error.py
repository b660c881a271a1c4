"""Model-error share of the intervals, calibrated on the realistic virtual population.

The Laplace/sandwich intervals and the type-B shares (:mod:`.uncertainty`) describe the
measurement; a real house also differs from the 5R1C in ways the nights cannot show (emitter
and furniture dynamics the nuisance terms only approximate, gains, control). How far that moves
HLC, C_m and τ is learnt from a *virtual* population of realistic houses (domain randomisation,
:mod:`impctl.plant`), never the held-out bench households: ``bench/calibrate_intervals.py`` fits
each with the share switched off and records |log(estimate/true)| next to what the fit can see
(:func:`diagnostics`). Households fall into a few groups by those diagnostics (:func:`group_of`);
per group and quantity the share s is the smallest log-space SD that, added in quadrature to each
household's own interval SD, puts the truth inside the 95 % interval of ⌈0.95·(n + 1)⌉ of the n
households (split-conformal: a finite-sample guarantee for an exchangeable house). The share is
calibrated separately for two bands of night counts (:func:`band_of`): "few" (≤
:data:`FEW_MAX_NIGHTS` nights, the adaptive and the fixed 2 + 3 campaigns: each calibration house
is also fitted on the night sequences those campaigns end on, at the gateway's setpoints —
``CampaignConfig``'s defaults, recorded as the band's ``protocol``) and "many" (the full 2 + 6
protocol) — a fit of two to five nights is not as wrong, or as sure, as one of eight. At fit time
the share of the fit's band and group is added in quadrature (:func:`widen`). Widening only: no bias
correction is learnt from the simulator, a real house not being the simulator.

The calibration is a small JSON file next to this module (:data:`CALIBRATION_FILE`, schema
:data:`SCHEMA`) with its provenance (seed, N, plant version, the regenerating command).
"""

from __future__ import annotations

import json
import math
from functools import lru_cache
from pathlib import Path

import numpy as np

from ...errors import InputError
from ..nights.data import Estimate

#: /3: the few band is calibrated on the gateway's campaign nights and records their
#: setpoints (``bands.few.protocol``); a /2 file (the 2 + 6 protocol's first nights) is refused.
SCHEMA = "impctl-model-error/3"
#: The grouping rule's version: a calibration file made with another rule is refused.
GROUPING = "nights-rows-residuals-nuisance-discharge/6"
GROUPS = ("clean", "plain", "nuisance", "slow", "coarse")
CALIBRATION_FILE = Path(__file__).with_name("model_error.json")
QUANTITIES = ("hlc", "c_m", "tau")
Z95 = 1.959964
COVERAGE = 0.95
#: A group with fewer calibration households than this takes the pooled share.
MIN_GROUP = 20
#: Emitter discharge [h] past which a constrained night is "slow" (underfloor-like: the screed
#: keeps heating the room well after switch-off; real-houses.md §2).
SLOW_DISCHARGE_H = 2.0
#: "Clean" residuals (:func:`group_of`): lag-1 autocorrelation and RMSE/noise of the held-night
#: power below these (between the ideal 5R1C's largest and the realistic houses' 10th percentile).
RHO_CLEAN = 0.15
RMSE_CLEAN = 1.1
#: Median row interval [s] of the fitted nights above which a fit is in the "coarse" group:
#: 15-minute rows and coarser (the fine groups are calibrated on 5-minute rows, 1-minute rows are
#: fitted as 5-minute means; a gateway's 10-minute rows, jittering around 600 s, stay fine).
COARSE_STEP_S = 720.0
#: Fits of at most this many nights take the "few" band's shares (:func:`band_of`).
FEW_MAX_NIGHTS = 5
BANDS = ("few", "many")


def diagnostics(fit) -> dict:
    """What a fitted :class:`~impctl.fit.NightFit` shows about its own model error (JSON-ready).

    Keys: ``nuisance_selected`` (the LR test kept the emitter/furniture terms),
    ``adequate`` (:func:`.quality.adequacy`), ``rho_constrained``, ``rho_power`` (lag-1 residual
    autocorrelation), ``rmse_over_noise_constrained``, ``rmse_over_noise_power``,
    ``emitter_discharge_h`` (median over the used constrained nights, h), ``structure_share``
    (largest of the three, log), ``n_nights`` (used), ``row_step_s`` (median interval of the
    fitted rows, s; 1-minute rows are fitted as 5-minute means).
    """
    ad = getattr(fit, "adequacy_", None) or {"adequate": True, "groups": {}}
    groups = ad.get("groups", {})

    def g(name, key):
        v = groups.get(name, {}).get(key)
        return None if v is None else float(v)

    discharge = [q["emitter_discharge_h"] for q in (getattr(fit, "night_quality_", None) or [])
                 if q.get("used") and q["kind"] == "constrained"
                 and q.get("emitter_discharge_h") is not None]
    share = getattr(fit, "structure_share_", None) or {}
    nights = getattr(fit, "nights_", None) or []
    steps = np.concatenate([np.diff(np.asarray(n.time_s, float)) for n in nights]) if nights \
        else np.array([])
    return {
        "nuisance_selected": bool((getattr(fit, "nuisance_check_", None) or {}).get("selected")),
        "adequate": bool(ad.get("adequate", True)),
        "rho_constrained": g("constrained", "lag1_autocorrelation"),
        "rho_power": g("normal_power", "lag1_autocorrelation"),
        "rmse_over_noise_constrained": g("constrained", "rmse_over_noise"),
        "rmse_over_noise_power": g("normal_power", "rmse_over_noise"),
        "emitter_discharge_h": float(np.median(discharge)) if discharge else None,
        "structure_share": max(share.values()) if share else 0.0,
        "n_nights": len(nights),
        "row_step_s": float(np.median(steps)) if len(steps) else None,
    }


def group_of(diag: dict) -> str:
    """The calibration group of a fit's :func:`diagnostics` (rule :data:`GROUPING`).

    * ``"clean"``: the held-night power residuals are white (lag-1 ρ < :data:`RHO_CLEAN`) and at
      the reading noise (RMSE < :data:`RMSE_CLEAN` × noise) — the 5R1C describes the nights (the
      ideal model: ρ ≤ 0.08, ratio ≤ 1.01 on 40 ideal houses; 3 of 160 realistic ones);
    * ``"plain"``: structured residuals but the LR test kept no nuisance term — the worst group
      on realistic houses (mostly underfloor: a slow screed release the mass absorbs);
    * ``"slow"``: terms kept and the emitter discharge lasts ≥ :data:`SLOW_DISCHARGE_H`;
    * ``"nuisance"``: terms kept, faster discharge;
    * ``"coarse"``: rows more than :data:`COARSE_STEP_S` apart (15-minute and hourly rows),
      whatever the residuals say —
      coarse means hide the emitter and the cycling (at hourly rows 63 of 80 realistic houses
      looked "clean", median HLC error 16 %; at 15-minute rows 38 of the bench's 50), so the
      residuals cannot tell the groups apart. Calibrated on hourly rows: for 15–60-minute rows
      a share measured where the errors are largest.
    """
    step = diag.get("row_step_s")
    if step is not None and step > COARSE_STEP_S:
        return "coarse"
    rho, ratio = diag.get("rho_power"), diag.get("rmse_over_noise_power")
    if rho is not None and ratio is not None and rho < RHO_CLEAN and ratio < RMSE_CLEAN:
        return "clean"
    if not diag.get("nuisance_selected"):
        return "plain"
    dis = diag.get("emitter_discharge_h")
    if dis is not None and dis >= SLOW_DISCHARGE_H:
        return "slow"
    return "nuisance"


def band_of(diag: dict) -> str:
    """The night-count band of a fit's :func:`diagnostics`: ``"few"`` for at most
    :data:`FEW_MAX_NIGHTS` fitted nights (calibrated on 2–5-night subsets), else ``"many"``
    (calibrated on 8 nights; 6–7 nights take it too)."""
    n = diag.get("n_nights")
    return "few" if n is not None and n <= FEW_MAX_NIGHTS else "many"


def entry_of(cal: dict, diag: dict) -> tuple[str, str, dict]:
    """(band, group, the calibration's entry {"n", "share", "source"}) of a fit's diagnostics."""
    band, group = band_of(diag), group_of(diag)
    return band, group, cal["bands"][band]["groups"][group]


def required_share(log_error: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """Per household, the smallest share s [log] with |log_error| ≤ Z95·√(sd² + s²)."""
    need = (np.abs(np.asarray(log_error, float)) / Z95) ** 2 - np.asarray(sd, float) ** 2
    return np.sqrt(np.clip(need, 0.0, None))


def conformal_share(log_error, sd, coverage: float = COVERAGE) -> float:
    """The split-conformal share: the ⌈coverage·(n + 1)⌉-th smallest required share (module
    docstring); inf when n is too small for that rank."""
    s = np.sort(required_share(log_error, sd))
    n = len(s)
    k = math.ceil(coverage * (n + 1))
    return float(s[k - 1]) if 0 < k <= n else float("inf")


def calibrate(records: list[dict], provenance: dict, coverage: float = COVERAGE,
              protocol: dict | None = None) -> dict:
    """The calibration (JSON-ready) from per-fit ``records`` with keys ``diagnostics``,
    ``log_error`` {q: log(est/true)} and ``sd`` {q: log-space SD of the fit's own interval};
    per band (:func:`band_of`) and group (:func:`group_of`). ``protocol``: the few band's
    nights ({"constrained_setpoint_c" [°C], "normal_setpoints_c" [°C], "sequences"}).

    A cell with fewer than :data:`MIN_GROUP` fits is too small for the conformal rank:
    "clean" then takes the conformal share of the clean fits of both bands when they are
    enough (the nights are described by the model in both; with many nights only a few
    realistic fits look clean, 3 of 274, too few to say anything alone), else the largest share
    any of its fits needed (0 if none: no evidence of model error to add); either no more than
    its band's pooled share (a group the model describes is no reason to be wider than the
    whole band). The others take the larger of their band's pooled share and the same group's
    share in the other band (e.g. "coarse" with few nights: the coarse rows' share or the few
    nights', whichever is wider).
    """
    def share(rs):
        return {q: conformal_share([r["log_error"][q] for r in rs], [r["sd"][q] for r in rs],
                                   coverage) for q in QUANTITIES}

    by_band = {b: [r for r in records if band_of(r["diagnostics"]) == b] for b in BANDS}
    pooled = {b: share(rs) for b, rs in by_band.items()}
    cells = {b: {g: [r for r in rs if group_of(r["diagnostics"]) == g] for g in GROUPS}
             for b, rs in by_band.items()}
    conformal = {b: {g: share(rs) for g, rs in c.items() if len(rs) >= MIN_GROUP}
                 for b, c in cells.items()}
    clean = [r for c in cells.values() for r in c["clean"]]
    bands = {}
    for b in BANDS:
        other = next(x for x in BANDS if x != b)
        groups = {}
        for name, rs in cells[b].items():
            if name in conformal[b]:
                entry = {"share": conformal[b][name], "source": f"conformal, {coverage:.0%}"}
            elif name == "clean" and len(clean) >= MIN_GROUP:
                entry = {"share": {q: min(pooled[b][q], v) for q, v in share(clean).items()},
                         "source": f"conformal, {coverage:.0%}, over the {len(clean)} clean "
                                   f"fits of both bands ({len(rs)} in this one, fewer than "
                                   f"{MIN_GROUP}), at most the band's pooled share"}
            elif name == "clean":
                entry = {"share": {q: min(pooled[b][q], float(max(
                    required_share([r["log_error"][q] for r in rs], [r["sd"][q] for r in rs]),
                    default=0.0))) for q in QUANTITIES},
                         "source": f"largest needed by its {len(rs)} fits (fewer than "
                                   f"{MIN_GROUP}), at most the band's pooled share"}
            else:
                alt = conformal[other].get(name, pooled[other])
                entry = {"share": {q: max(pooled[b][q], alt[q]) for q in QUANTITIES},
                         "source": f"fewer than {MIN_GROUP}: the wider of the band's pooled "
                                   f"share and the group's in band {other!r}"}
            groups[name] = {"n": len(rs), **entry}
        bands[b] = {"n": len(by_band[b]), "pooled": pooled[b], "groups": groups}
    bands["few"]["max_nights"] = FEW_MAX_NIGHTS
    bands["few"]["protocol"] = protocol or {}
    return {"schema": SCHEMA, "grouping": GROUPING, "coverage": coverage,
            "share_unit": "log-space SD, added in quadrature to the fit's own", "bands": bands,
            "pooled": {"n": len(records), "share": share(records)}, "provenance": provenance}


def _protocol_ok(protocol) -> bool:
    if not isinstance(protocol, dict):
        return False
    c, n = protocol.get("constrained_setpoint_c"), protocol.get("normal_setpoints_c")
    return (isinstance(c, (int, float)) and isinstance(n, list) and len(n) > 0
            and all(isinstance(x, (int, float)) for x in n))


def few_protocol(cal: dict) -> tuple[float, tuple[float, ...]]:
    """(constrained setpoint, normal setpoints) [°C] the few band was calibrated on."""
    p = cal["bands"]["few"]["protocol"]
    return float(p["constrained_setpoint_c"]), tuple(float(x) for x in p["normal_setpoints_c"])


@lru_cache(maxsize=4)
def load_calibration(path: str | None = None) -> dict:
    """The calibration file (default :data:`CALIBRATION_FILE`), checked.

    Raises
    ------
    InputError
        One line naming the file and what is wrong with it.
    """
    p = Path(path) if path else CALIBRATION_FILE
    try:
        cal = json.loads(p.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{p}: model-error calibration unreadable ({exc}); regenerate it with "
                         "`python bench/calibrate_intervals.py`") from None
    problem = None
    if not isinstance(cal, dict) or cal.get("schema") != SCHEMA:
        problem = f"schema is not {SCHEMA!r}"
    elif cal.get("grouping") != GROUPING:
        problem = f"grouping {cal.get('grouping')!r} is not this code's {GROUPING!r}"
    elif not _protocol_ok(((cal.get("bands") or {}).get("few") or {}).get("protocol")):
        problem = ("band 'few' has no protocol (constrained_setpoint_c, normal_setpoints_c "
                   "[°C]): not calibrated on campaign nights")
    else:
        for band in BANDS:
            for name in GROUPS:
                share = ((((cal.get("bands") or {}).get(band) or {}).get("groups") or {})
                         .get(name) or {}).get("share") or {}
                bad = [q for q in QUANTITIES if not (isinstance(share.get(q), (int, float))
                                                     and 0.0 <= share[q] < 5.0)]
                if bad:
                    problem = (f"band {band!r}, group {name!r}: share of {', '.join(bad)} "
                               "missing or not in [0, 5)")
                    break
            if problem:
                break
    if problem:
        raise InputError(f"{p}: model-error calibration invalid: {problem}; regenerate it with "
                         "`python bench/calibrate_intervals.py`")
    return cal


def widen(lumped: dict[str, Estimate], diag: dict, cal: dict) -> tuple[dict, dict]:
    """Add the calibrated share of ``diag``'s band and group in quadrature to each log-space
    interval.

    Returns
    -------
    (lumped with widened intervals, {"group", "band", "share" {q: log SD}, "n_calibration",
    "method"})
    """
    band, group, entry = entry_of(cal, diag)
    out = {}
    for name, e in lumped.items():
        s = float(entry["share"].get(name, 0.0))
        sd = math.hypot(math.log(e.high / e.low) / (2 * Z95), s)
        out[name] = Estimate(e.value, float(e.value * math.exp(-Z95 * sd)),
                             float(e.value * math.exp(Z95 * sd)), e.determined)
    prov = cal.get("provenance", {})
    n_fits = int(cal.get("pooled", {}).get("n", 0))
    n_cal = int(prov.get("n_households") or n_fits)
    info = {"group": group, "band": band,
            "share": {q: float(entry["share"][q]) for q in QUANTITIES},
            "n_group": int(entry.get("n", 0)), "n_calibration": n_cal, "n_fits": n_fits,
            "seed": prov.get("seed"), "version": prov.get("created"),
            "method": (f"sandwich + type-B + model-error share calibrated on {n_cal} realistic "
                       f"virtual households ({n_fits} fits), group {group!r}, "
                       f"{'≤ ' + str(FEW_MAX_NIGHTS) if band == 'few' else 'more'} nights")}
    return out, info
