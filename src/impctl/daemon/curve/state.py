"""The last heating-curve result the daemon keeps, read as plain numbers (no pandas here).

After each fit the daemon runs ``impctl curve`` in the fit's subprocess chain
(:mod:`..fitting`); its ``impctl-curve/1`` JSON is kept as ``<state_dir>/curve.json``. The
daemon reads it to publish the suggested flow temperature and the expected saving, and to
know which curve to set when the owner asked for it (``[curve] apply``).
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

from ...atomic import replacing

_LOG = logging.getLogger("impctl.daemon")
#: The file in the state directory.
CURVE_FILE = "curve.json"
#: Outdoor temperatures of the curve's two points [°C] (as :mod:`impctl.curve.need`).
POINTS_T_OUT_C = (-15.0, 15.0)


def curve_path(state_dir: str | Path) -> Path:
    """Where the daemon keeps the last curve result."""
    return Path(state_dir) / CURVE_FILE


def keep_curve(state_dir: str | Path, source: Path) -> None:
    """Make ``source`` (a fresh ``impctl curve --json``) the kept result, atomically."""
    # the report and the CLI read it as another user
    with replacing(curve_path(state_dir), mode=0o644) as tmp:
        tmp.write_bytes(Path(source).read_bytes())


def _number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def curve_problem(data) -> str | None:
    """The first way ``data`` is not an ``impctl-curve/1`` result the daemon can use."""
    if not isinstance(data, dict) or data.get("schema") != "impctl-curve/1":
        return "not an impctl-curve/1 object"
    rec = data.get("recommended")
    if not isinstance(rec, dict) or not (isinstance(rec.get("flow_c"), list)
                                         and len(rec["flow_c"]) == 2
                                         and all(_number(v) for v in rec["flow_c"])):
        return "recommended.flow_c is not two numbers"
    return None


def load_curve(state_dir: str | Path) -> dict | None:
    """The kept curve result, or None (none yet, or unreadable: logged)."""
    path = curve_path(state_dir)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        _LOG.warning("kept heating curve %s unreadable: %s", path, exc)
        return None
    why = curve_problem(data)
    if why is not None:
        _LOG.warning("kept heating curve %s ignored: %s", path, why)
        return None
    return data


def line_flow_c(points_c: tuple[float, float] | list[float], t_out_c: float) -> float:
    """The flow of a two-point curve at ``t_out_c`` [°C] (the line, extrapolated)."""
    a, b = POINTS_T_OUT_C
    fa, fb = float(points_c[0]), float(points_c[1])
    return fa + (fb - fa) * (float(t_out_c) - a) / (b - a)


def suggested_flow_c(curve: dict | None, t_out_c: float | None) -> float | None:
    """The recommended curve's flow at the outdoor temperature now [°C], or None."""
    if curve is None or t_out_c is None:
        return None
    return round(line_flow_c(curve["recommended"]["flow_c"], t_out_c), 1)
