"""The owner's word on impctl's heating curve, and the points it covers.

The owner asks with ``[curve] apply = true`` or ``impctl curve --apply`` and takes it back with
``impctl curve --restore``; the command's word (``<state_dir>/curve-intent.json``) wins over
the configuration. impctl also records "no curve" itself when the curve must not be set again
until the owner asks: it proved too low, the controller did not follow it, or the owner set a
point of their own — seen by the watch while it runs, or by a restore that kept the owner's
point (a restart after the daemon died, ``impctl restore``; :func:`owner_kept_point`).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from pathlib import Path

from ...atomic import replacing
from ...store import JournalEntry

_LOG = logging.getLogger("impctl.daemon")
#: The curve points: documented number → journal name.
CURVE_REGISTERS = {2309: "loop1_curve_cold", 2314: "loop1_curve_mild"}
KEEP = frozenset(CURVE_REGISTERS.values())
#: The owner's word at run time (``impctl curve --apply`` / ``--restore``).
INTENT_FILE = "curve-intent.json"


def intent(state_dir: str | Path) -> bool | None:
    """The owner's last word (True: set the curve; False: give mine back), or None."""
    try:
        data = json.loads((Path(state_dir) / INTENT_FILE).read_text())
    except (OSError, ValueError):
        return None
    value = data.get("apply") if isinstance(data, dict) else None
    return value if isinstance(value, bool) else None


def set_intent(state_dir: str | Path, apply: bool, why: str) -> Path:
    """Record the owner's word (atomically; read by the daemon at its next look)."""
    target = Path(state_dir) / INTENT_FILE
    # readable by the daemon's own user when root wrote it
    with replacing(target, mode=0o644) as tmp:
        tmp.write_text(json.dumps({"apply": apply, "why": why}))
    return target


def no_curve(state_dir: str | Path, why: str) -> None:
    """Keep the decision to set no curve until asked again; a file that cannot be written (a
    full disk) does not stop the owner's points going back."""
    try:
        set_intent(state_dir, False, why)
    except OSError as exc:
        _LOG.error("cannot keep the decision to set no heating curve (%s: %s); the "
                   "owner's points go back all the same", why, exc)


def owner_kept_point(state_dir: str | Path) -> Callable[[JournalEntry], None]:
    """What a restore does when it keeps the owner's value of a register
    (:func:`impctl.controller.restore.on_owner_kept`): for a curve point, impctl sets no
    curve until asked again — set over the owner's point at the next look, it would undo the
    owner's choice, as the watch's own check of the points (running) never does."""
    def kept(entry: JournalEntry) -> None:
        if entry.register not in KEEP or intent(state_dir) is False:
            return
        no_curve(state_dir, "the owner changed the curve points")
        _LOG.info("the owner changed the heating curve (%s): impctl sets no curve until asked "
                  "again (impctl curve --apply)", entry.register)
    return kept
