"""The report's heating-curve section, for the people who live in the house: what to set the
heat pump to and what it saves, in plain words, with the curves drawn (``impctl curve``'s
``impctl-curve/1`` result)."""

from __future__ import annotations

import html
import json
from pathlib import Path

from ..errors import InputError

#: The outdoor temperatures of the section's table [°C].
TABLE_T_OUT_C = (-15.0, -5.0, 0.0, 5.0, 15.0)


def read_curve_json(path: str | Path) -> dict:
    """An ``impctl curve --json`` result, checked (one line naming the file otherwise)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"not a readable JSON file: {exc}", path) from None
    if not isinstance(data, dict) or data.get("schema") != "impctl-curve/1":
        raise InputError("not an `impctl curve --json` result (schema impctl-curve/1)", path)
    for key in ("recommended", "need", "advice"):
        if key not in data:
            raise InputError(f"key '{key}' missing (not an impctl curve result)", path)
    return data


def _flow(points: list[float], t_out_c: float) -> float:
    fa, fb = points
    return fa + (fb - fa) * (t_out_c + 15.0) / 30.0


def curve_section(curve: dict, out: Path, img) -> list[str]:
    """The HTML parts of the section; its figure drawn into ``out``/fig_curve.png and
    embedded by ``img``."""
    from ..curve.plot import plot_curve

    rec = curve["recommended"]["flow_c"]
    run = (curve.get("running") or {}).get("flow_c")
    rows = []
    for t in TABLE_T_OUT_C:
        cells = [f"{t:+.0f} °C".replace("-", "−"), f"{_flow(rec, t):.0f} °C"]
        cells.append("—" if run is None else f"{_flow(run, t):.0f} °C")
        rows.append(cells)
    head = "".join(f"<th>{h}</th>" for h in ("outside", "suggested", "your heat pump now"))
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>"
                   for r in rows)
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in curve.get("notes", []))
    sp = curve["setpoint_c"]["value"]
    return [
        "<h2>Your heating curve</h2>",
        f"<div class='household'><p class='lead'>{html.escape(curve['advice'])}</p>",
        f"<p>The heating curve tells the heat pump how warm to make the water for the "
        f"radiators or the floor at each outdoor temperature. The suggested one keeps the "
        f"rooms at {sp:.1f} °C with {curve['margin_k']:g} K to spare, from what the nights "
        "showed of this house and its radiators or floor.</p>",
        f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>",
        img(plot_curve(curve, out / "fig_curve.png")),
        f"<ul>{notes}</ul>" if notes else "",
    ]
