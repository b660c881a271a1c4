"""Whether the controller follows the curve points impctl wrote: its own flow target (2128)
must have moved as the line moved at the outdoor temperature now — from the points the target
was read under to impctl's — within :data:`FOLLOW_TOL_K`.

The controller works out 2128 on its own cycle, not at the moment a point is written: read
within that cycle, it still says what the points before asked for. Both reads the check
compares are therefore taken only once the points have stood :data:`SETTLE_S`: the one
before impctl's write under points unchanged that long (seen so at the watch's looks, the
wait starting again whenever they change or the watch itself writes), the one it is judged on
that long after impctl's last write was read back. Otherwise a restore just before (the
daemon's start putting the owner's points back, ``impctl curve --restore`` and ``--apply``)
leaves a baseline that is still impctl's own curve, and a controller that follows looks as if
it did not. The loop-1 setpoint moves 2128 too: a setpoint that changed between the two reads
(the owner's, a night's) voids the check rather than failing it.
"""

from __future__ import annotations

from dataclasses import dataclass

from .intent import CURVE_REGISTERS
from .state import line_flow_c

#: How far the controller's flow target may have moved otherwise than the line [K] (a
#: controller's own curve need not be straight between its points).
FOLLOW_TOL_K = 1.5
#: How long points stand before 2128 is read as theirs [simulated s]: the simulated
#: controller works it out each model step (a minute); a real one's cycle is not documented,
#: so a margin of several.
SETTLE_S = 300.0
#: What the watch reads at a look: the points, the controller's flow target, the outdoor
#: temperature, and the loop-1 setpoint, which moves the flow target too.
LOOKED_AT = (*CURVE_REGISTERS, 2128, 2103, 2187)


class Settling:
    """The curve points as the watch last saw them, and since when they stand unchanged."""

    def __init__(self) -> None:
        self._seen: tuple[tuple[int, ...], float] | None = None

    def settled(self, raw: tuple[int, ...], now_s: float) -> bool:
        """Whether the points ``raw`` (raw words) have stood :data:`SETTLE_S` by ``now_s``
        (monotonic simulated s); first seen now, the wait begins."""
        if self._seen is None or self._seen[0] != raw:
            self._seen = (raw, now_s)
        return now_s - self._seen[1] >= SETTLE_S

    def forget(self) -> None:
        """The watch wrote the points: they stand from its next look, whatever they hold (the
        same words again after other ones in between would otherwise look unchanged)."""
        self._seen = None


@dataclass(frozen=True)
class FollowCheck:
    """A check waiting: 2128 [°C] read under the points ``under`` [°C], both settled, and
    the loop-1 setpoint then [°C] (None: unknown)."""

    target_c: float
    under: tuple[float, float]
    setpoint_c: float | None = None

    def void(self, setpoint_c: float | None) -> bool:
        """Whether the setpoint now (``setpoint_c`` [°C]) is not the one 2128 was first read
        under: its move would then not be the curve's alone."""
        return (self.setpoint_c is None or setpoint_c is None
                or abs(setpoint_c - self.setpoint_c) > 0.05)

    def moves(self, held: tuple[float, float], t_out_c: float,
              target_c: float) -> tuple[float, float]:
        """(how far 2128 moved, how far the line moved) [K] from ``under`` to ``held``."""
        return (target_c - self.target_c,
                line_flow_c(held, t_out_c) - line_flow_c(self.under, t_out_c))

    @staticmethod
    def due(written_s: float | None, now_s: float) -> bool:
        """Whether impctl's last write, read back at ``written_s``, has stood long enough to
        be judged (monotonic simulated s)."""
        return written_s is not None and now_s - written_s >= SETTLE_S
