"""The heat-pump side of ``impctl status``: generation evidence and recognised link quirks.

The daemon's client writes ``heatpump.json`` in the state directory (:meth:`HeatPumpClient.
write_health`) after detection and whenever a new quirk is recognised; ``impctl status`` reads
it, so no IPC is needed.
"""

from __future__ import annotations

import json
from pathlib import Path

#: File name in the state directory.
HEALTH_FILE = "heatpump.json"


def read_health(state_dir: str | Path) -> dict | None:
    """The last health record written by the daemon, or None (none yet, or unreadable)."""
    try:
        return json.loads((Path(state_dir) / HEALTH_FILE).read_text())
    except (OSError, ValueError):
        return None


def health_lines(health: dict | None) -> list[str]:
    """A few status lines: generation with its evidence, then one line per quirk."""
    if not health:
        return []
    gen = health.get("generation") or {}
    lines = []
    if gen:
        head = f"generation: {gen.get('generation')} ({gen.get('source')})"
        if gen.get("doubt"):
            head += f" — {gen['doubt']}"
        lines.append(head)
        lines.extend(f"  {check}: {finding}" for check, finding in
                     (gen.get("evidence") or {}).items())
    for name, text in (health.get("quirks") or {}).items():
        lines.append(f"quirk:     {name}: {text}")
    return lines
