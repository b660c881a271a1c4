"""Reading a fit result (the ``impctl fit --json`` file) for the report, checked before use.

The report draws from ``lumped`` (HLC, C_m, τ), ``parameters`` and, when present, ``bounds``,
``classes``, ``predictions`` and ``validation``. A file that is not such an object — a list,
binary data, another program's JSON — is refused with one line naming the file and the first
key that does not fit, before anything is drawn or written.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from ..errors import InputError

_LUMPED = ("hlc", "c_m", "tau")


def _number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _pair(x: Any) -> bool:
    return isinstance(x, list) and len(x) == 2 and all(_number(v) for v in x)


def _numbers(x: Any) -> bool:
    return isinstance(x, list) and all(v is None or _number(v) for v in x)


def fit_problem(fit: Any) -> str | None:
    """The first way ``fit`` differs from an ``impctl fit`` result, or ``None``."""
    if not isinstance(fit, dict):
        return f"expected a JSON object (an `impctl fit --json` result), got a {type(fit).__name__}"
    schema = fit.get("schema", "impctl-fit/1")
    if not isinstance(schema, str) or not schema.startswith("impctl-fit/"):
        return f"key 'schema' is {schema!r}, not 'impctl-fit/…'"
    for key in ("bounds", "units", "determined", "basis", "classes", "validation"):
        if key in fit and not isinstance(fit[key], dict):
            return f"key '{key}' is not an object"
    if not isinstance(fit.get("interval_method", ""), str):
        return "key 'interval_method' is not a string"
    notes = fit.get("notes", [])
    if not isinstance(notes, list) or not all(isinstance(n, str) for n in notes):
        return "key 'notes' is not a list of strings"
    lumped = fit.get("lumped")
    if not isinstance(lumped, dict):
        return "key 'lumped' missing or not an object (not an `impctl fit --json` result)"
    for key in _LUMPED:
        e = lumped.get(key)
        if not isinstance(e, dict) or not _number(e.get("value")) or not e["value"] > 0:
            return f"key 'lumped.{key}.value' missing or not a positive number"
        for side in ("low", "high"):
            if e.get(side) is not None and not _number(e[side]):
                return f"key 'lumped.{key}.{side}' is not a number"
    params = fit.get("parameters")
    if not isinstance(params, dict) or not params:
        return "key 'parameters' missing or not an object"
    for name, value in params.items():
        if not _number(value):
            return f"key 'parameters.{name}' is not a number"
    for name, rng in fit.get("bounds", {}).items():
        if not _pair(rng):
            return f"key 'bounds.{name}' is not a [low, high] pair"
    classes = fit.get("classes", {})
    if not isinstance(classes, dict):
        return "key 'classes' is not an object"
    for name, c in classes.items():
        if not isinstance(c, dict) or not _pair(c.get("range")):
            return f"key 'classes.{name}.range' is not a [low, high] pair"
        if c.get("probability") is not None and not _number(c["probability"]):
            return f"key 'classes.{name}.probability' is not a number"
    return _curves_problem(fit)


def _curves_problem(fit: dict) -> str | None:
    preds = fit.get("predictions") or []
    if not isinstance(preds, list):
        return "key 'predictions' is not a list"
    for i, p in enumerate(preds):
        where = f"predictions[{i}]"
        if not isinstance(p, dict) or not _numbers(p.get("time_s")) or "night_id" not in p \
                or not isinstance(p.get("kind"), str):
            return f"key '{where}' lacks time_s, night_id or kind"
        n = len(p["time_s"])
        for col in ("t_air_measured_c", "t_air_model_c", "q_measured_w", "q_model_w"):
            if p.get(col) is not None and (not _numbers(p[col]) or len(p[col]) != n):
                return f"key '{where}.{col}' is not a list of {n} numbers"
        if p.get("t_air_model_c") is None and p.get("q_model_w") is not None:
            if p.get("q_measured_w") is None:
                return f"key '{where}.q_measured_w' missing"
        elif p.get("t_air_measured_c") is None:
            return f"key '{where}.t_air_measured_c' missing"
    validation = fit.get("validation", {})
    mean = validation.get("mean") or {}
    if not isinstance(mean, dict) or not all(
            mean.get(k) is None or _number(mean[k])
            for k in ("eps_pct", "dq_total_kwh", "dq_power_kw", "rmse_k")):
        return "key 'validation.mean' is not an object of numbers"
    rows = validation.get("normal") or []
    if not isinstance(rows, list):
        return "key 'validation.normal' is not a list"
    for i, row in enumerate(rows):
        if not isinstance(row, dict) or "night_id" not in row or not all(
                _number(row.get(k)) for k in ("q_measured_kwh", "q_model_kwh")):
            return f"key 'validation.normal[{i}]' lacks night_id, q_measured_kwh or q_model_kwh"
    return None


def read_fit_json(path: str | Path) -> dict:
    """Read and check a fit JSON (see the module docstring).

    Raises
    ------
    InputError
        Unreadable, not UTF-8 JSON, or not a fit result; one line naming the file.
    """
    path = Path(path)
    try:
        fit = json.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path) from None
    except UnicodeDecodeError:
        raise InputError("not a fit JSON: not UTF-8 text (binary data?)", path) from None
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON: {exc.msg}", path,
                         f"line {exc.lineno} column {exc.colno}") from None
    except RecursionError:
        raise InputError("not a fit JSON: nested too deeply", path) from None
    why = fit_problem(fit)
    if why is not None:
        raise InputError(f"not a fit JSON: {why}", path)
    return fit
