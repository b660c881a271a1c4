"""The records the adaptive campaign's policy reads and writes: the precision target, the
nights run, the fit summaries, the predictions of ``impctl campaign next`` (candidates and
outlook) and the decision — with the parsers of the JSON they come in.

Standard library only: the daemon imports this module (idle RSS ≤ 60 MB).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

CONSTRAINED = "constrained"
NORMAL = "normal"
KINDS = (CONSTRAINED, NORMAL)
#: "Dominated by the floor": the floor's worst ratio is at least this fraction of the latest
#: fit's (0.35: the floor is at least an eighth of the variance; 1/2 before h18d; README
#: "Adaptive campaign").
FLOOR_DOMINANT = 0.35
Z95 = 1.959964


@dataclass(frozen=True)
class Target:
    """The precision the aggregator needs and what the household will give for it.

    Attributes
    ----------
    hlc_rel, tau_rel : 95 % interval half-width relative to the estimate (0.05 = ±5 %)
    max_nights : nights run (valid or not) at most — the household's cost; default 5, the
        fixed 2 + 3 plan's nights, so the adaptive campaign never asks more of a household
        unless raised
    min_each : valid nights of each kind before precision may stop the campaign
    stall_nights : "cannot be identified" when the worst ratio did not shrink by ≥ 10 % over
        this many valid nights
    floor_dominance : "precision limited" needs the floor's worst ratio ≥ this fraction of the
        latest fit's (default 0.35: the floor is at least an eighth of the variance; 0: stop
        as soon as the floor alone misses the target)
    """

    hlc_rel: float = 0.05
    tau_rel: float = 0.08
    max_nights: int = 5
    min_each: int = 1
    stall_nights: int = 3
    floor_dominance: float = FLOOR_DOMINANT

    def __post_init__(self) -> None:
        if not (isinstance(self.floor_dominance, (int, float))
                and 0.0 <= self.floor_dominance <= 1.0):
            raise ValueError(f"target floor_dominance must be within 0..1, got "
                             f"{self.floor_dominance!r}")
        for name in ("hlc_rel", "tau_rel"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"target {name} must be a positive number, got {value!r}")
        for name, low in (("max_nights", 1), ("min_each", 1), ("stall_nights", 1)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                raise ValueError(f"target {name} must be an integer >= {low}, got {value!r}")

    def ratio(self, hlc_rel: float, tau_rel: float) -> float:
        """The worst of the two half-widths over their targets (≤ 1: target met)."""
        return max(_num(hlc_rel) / self.hlc_rel, _num(tau_rel) / self.tau_rel)


@dataclass(frozen=True)
class NightRecord:
    """A night that was run: its kind, setpoint [°C], whether the fit could use it, and its
    mean outdoor temperature [°C] when known."""

    kind: str
    setpoint_c: float
    valid: bool
    t_out_mean_c: float | None = None


@dataclass(frozen=True)
class FitSummary:
    """One fit after ``nights`` valid nights: HLC [W/K] and τ [h] with 95 % intervals.

    ``hlc_floor_rel`` and ``tau_floor_rel`` are the relative 95 % half-widths of the interval's
    type-B shares alone (sensor offsets, meter, night gains, structure, model error): what no
    number of nights removes (0 = not stated by the fit). ``too_few_nights``: the intervals
    rest on too few nights to mean much (the fit's ``interval_basis`` says so, or a
    night-clustered sandwich from 2 nights, with Student-t's t(1) = 12.7, is wider than
    ±100 %) — show "too few nights yet", not the numbers. ``hlc_floor_by`` and
    ``tau_floor_by``: the largest share of each floor, in words (:data:`FLOOR_LABELS`).
    """

    nights: int
    hlc_w_per_k: float
    hlc_low: float
    hlc_high: float
    tau_h: float
    tau_low: float
    tau_high: float
    hlc_floor_rel: float = 0.0
    tau_floor_rel: float = 0.0
    too_few_nights: bool = False
    hlc_floor_by: str = ""
    tau_floor_by: str = ""

    @classmethod
    def from_fit_json(cls, result: dict, nights: int) -> FitSummary:
        """From the JSON written by ``impctl fit --json`` (schema ``impctl-fit/1``).

        A missing or non-finite value becomes NaN, so its relative half-width is infinite:
        never mistaken for a precise result.
        """
        lumped = result.get("lumped") if isinstance(result, dict) else None
        if not isinstance(lumped, dict):
            raise ValueError("fit result has no 'lumped' block (not an impctl-fit/1 JSON)")

        def get(name: str, key: str) -> float:
            block = lumped.get(name)
            value = block.get(key) if isinstance(block, dict) else None
            return _num(value, math.nan)

        fit = result.get("fit") if isinstance(result.get("fit"), dict) else {}
        sources = fit.get("interval_source") if isinstance(fit.get("interval_source"),
                                                            dict) else {}
        basis = fit.get("interval_basis")
        parts = type_b_parts(result)
        floor = {name: math.sinh(Z95 * math.sqrt(sum(v * v for v in parts[name].values())))
                 for name in ("hlc", "tau")}
        by = {name: (FLOOR_LABELS[max(parts[name], key=parts[name].get)]
                     if any(parts[name].values()) else "") for name in ("hlc", "tau")}
        rel = {name: _rel(get(name, "value"), get(name, "low"), get(name, "high"))
               for name in ("hlc", "tau")}
        # The fit's own word wins; else a 2-night sandwich wider than ±100 % (t(1) = 12.7)
        too_few = (("too few" in basis) if isinstance(basis, str) else
                   int(nights) <= 2 and any(sources.get(n) == "sandwich" and rel[n] > 1.0
                                            for n in rel))
        return cls(nights=int(nights),
                   hlc_w_per_k=get("hlc", "value"), hlc_low=get("hlc", "low"),
                   hlc_high=get("hlc", "high"),
                   tau_h=get("tau", "value"), tau_low=get("tau", "low"),
                   tau_high=get("tau", "high"),
                   hlc_floor_rel=floor["hlc"], tau_floor_rel=floor["tau"],
                   too_few_nights=bool(too_few), hlc_floor_by=by["hlc"],
                   tau_floor_by=by["tau"])

    @property
    def hlc_rel(self) -> float:
        """Half-width of the HLC interval relative to the estimate (inf when unknown)."""
        return _rel(self.hlc_w_per_k, self.hlc_low, self.hlc_high)

    @property
    def tau_rel(self) -> float:
        """Half-width of the τ interval relative to the estimate (inf when unknown)."""
        return _rel(self.tau_h, self.tau_low, self.tau_high)


#: What each type-B share is, in the household's words (the stop reason names the largest).
FLOOR_LABELS = {"offsets": "the room and outdoor sensors' offsets",
                "gains": "unmetered night gains (sleepers, base load)",
                "meter": "the heat meter's gain error",
                "structure": "the model's structure",
                "model_error": "the model's error on houses like this one"}


def type_b_parts(result: dict) -> dict[str, dict[str, float]]:
    """Each type-B share of an ``impctl fit`` JSON's log-space sd [–] per lumped quantity
    (hlc, tau, c_m), by :data:`FLOOR_LABELS` key: ``fit.offset_allowance`` (sensor offsets,
    night gains, meter — HLC and C_m only —, structure) and ``fit.model_error.share``. Missing
    fields count as 0 (an older fit states fewer shares)."""
    fit = result.get("fit") if isinstance(result, dict) else None
    fit = fit if isinstance(fit, dict) else {}
    allowance = fit.get("offset_allowance")
    allowance = allowance if isinstance(allowance, dict) else {}
    model_error = fit.get("model_error")
    blocks = {"structure": allowance.get("structure_relative_sd"),
              "model_error": model_error.get("share") if isinstance(model_error, dict) else None}
    out = {}
    for name in ("hlc", "tau", "c_m"):
        parts = {"offsets": _num(allowance.get("relative_sd"), 0.0),
                 "gains": _num(allowance.get("night_gain_relative_sd"), 0.0),
                 "meter": (_num(allowance.get("meter_relative_sd"), 0.0)
                           if name in ("hlc", "c_m") else 0.0)}
        for key, block in blocks.items():
            parts[key] = _num(block.get(name), 0.0) if isinstance(block, dict) else 0.0
        out[name] = parts
    return out


def type_b_shares(result: dict) -> dict[str, tuple[float, float, float]]:
    """The type-B shares of :func:`type_b_parts` grouped by how nights move them: (sensor
    offsets, which scale with 1/mean ΔT; unmetered night gains, likewise; the rest — meter,
    structure and model-error shares — which no night changes), per lumped quantity."""
    out = {}
    for name, p in type_b_parts(result).items():
        out[name] = (p["offsets"], p["gains"],
                     math.sqrt(p["meter"] ** 2 + p["structure"] ** 2 + p["model_error"] ** 2))
    return out


@dataclass(frozen=True)
class Outlook:
    """What ``impctl campaign next`` predicts beyond tonight: the relative 95 % half-widths of
    HLC and τ after ``nights`` more nights (the most informative of each kind, alternating),
    and the floor then (type-B shares alone, at the mean ΔT those nights bring)."""

    nights: int
    hlc_rel_pred: float
    tau_rel_pred: float
    hlc_floor_rel: float
    tau_floor_rel: float


@dataclass(frozen=True)
class Candidate:
    """A possible next night and the predicted relative half-widths after it."""

    kind: str
    setpoint_c: float
    hlc_rel_pred: float
    tau_rel_pred: float


@dataclass(frozen=True)
class Decision:
    """What to do tonight.

    Attributes
    ----------
    action : "run" | "skip" (tonight only) | "stop" (the campaign ends)
    kind, setpoint_c : the night to run [°C]; None unless ``action == "run"``
    reason : one plain sentence for ``impctl status``, logs and Home Assistant
    reached : True when stopped because the precision target is met
    """

    action: str
    kind: str | None
    setpoint_c: float | None
    reason: str
    reached: bool = False


def parse_candidates(block: dict) -> list[Candidate]:
    """The candidates of the JSON written by ``impctl campaign next``.

    ``{"forecast_t_out_c": x, "candidates": [{"kind", "setpoint_c", "hlc_rel_pred",
    "tau_rel_pred"}, ...]}``; a null prediction becomes inf (never chosen); raises ValueError
    naming the entry and the problem.
    """
    if not isinstance(block, dict) or not isinstance(block.get("candidates"), list):
        raise ValueError("campaign JSON has no 'candidates' list")
    out = []
    for i, entry in enumerate(block["candidates"]):
        if not isinstance(entry, dict):
            raise ValueError(f"candidates[{i}] is not an object")
        kind = entry.get("kind")
        if kind not in KINDS:
            raise ValueError(f"candidates[{i}].kind must be 'constrained' or 'normal', "
                             f"got {kind!r}")
        values = []
        for key in ("setpoint_c", "hlc_rel_pred", "tau_rel_pred"):
            value = entry.get(key)
            if value is None and key != "setpoint_c":
                value = math.inf   # written as null: the prediction failed (never chosen)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"candidates[{i}].{key} must be a number, got {value!r}")
            values.append(float(value))
        out.append(Candidate(kind, *values))
    return out


def parse_outlook(block: dict) -> Outlook | None:
    """The ``outlook`` of the JSON written by ``impctl campaign next`` (None when absent, as
    from an older impctl); raises ValueError naming the field and the problem."""
    entry = block.get("outlook") if isinstance(block, dict) else None
    if entry is None:
        return None
    if not isinstance(entry, dict):
        raise ValueError("outlook is not an object")
    nights = entry.get("nights")
    if isinstance(nights, bool) or not isinstance(nights, int) or nights < 1:
        raise ValueError(f"outlook.nights must be an integer >= 1, got {nights!r}")
    values = []
    for key in ("hlc_rel_pred", "tau_rel_pred", "hlc_floor_rel", "tau_floor_rel"):
        value = entry.get(key)
        if value is None:
            value = math.inf if key.endswith("_pred") else 0.0   # null: not predicted
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
            raise ValueError(f"outlook.{key} must be a number >= 0, got {value!r}")
        values.append(float(value))
    return Outlook(nights, *values)


def _num(value: object, default: float = math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return default
    value = float(value)
    return value if not math.isnan(value) else default


def _rel(value: float, low: float, high: float) -> float:
    if not all(math.isfinite(x) for x in (value, low, high)) or value <= 0 or high < low:
        return math.inf
    return 0.5 * (high - low) / value
