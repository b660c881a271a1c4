"""Which night gain a fit uses, and what it says of it: declared, measured, estimated, assumed.

:func:`resolve` reads the fit's options and its nights once, before the problems are laid out
(:mod:`.steps.problems`): a declared gain (``NightFit(night_gain_w=…)``) is known and used as
declared; else the nights' ``p_house_w``/``occupants`` measure it, night by night; else the
fit's gain term estimates it where that term is switched on and kept by the likelihood-ratio
test (:func:`.selection.gain_statement`); else the assumption of :mod:`impctl.imp.gain`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from ..imp.gain import (
    NIGHT_GAIN_SD_W,
    NIGHT_GAIN_W,
    SLEEPER_W,
    measured_gain_w,
    measured_sd_w,
)
from ..imp.night import NightSamples


@dataclass(frozen=True)
class GainSource:
    """The night gain a fit pins when no gain term is fitted, and where it comes from.

    ``value_w`` [W] is the campaign's value (the measured nights' mean when measured);
    ``per_night_w`` the measured gain of each night that has one [W] (the fit uses each
    night's own, the others get ``value_w``); ``sd_w`` [W] its uncertainty."""

    source: str                    # "declared" | "measured" | "assumed"
    value_w: float
    sd_w: float
    per_night_w: dict[str, float] = field(default_factory=dict)
    detail: str = ""

    def statement(self, value_w: float | None = None) -> str:
        """The plain sentence of this gain (``value_w``: the value the fit used)."""
        g = self.value_w if value_w is None else value_w
        if self.source == "declared":
            return (f"night gain declared {g:.0f} W" + (f" ± {self.sd_w:.0f} W" if self.sd_w
                                                         else " (known, ± 0 W)")
                    + (f" ({self.detail})" if self.per_night_w else ""))
        if self.source == "measured":
            return f"night gain measured {g:.0f} ± {self.sd_w:.0f} W ({self.detail})"
        return (f"night gain assumed {g:.0f} ± {self.sd_w:.0f} W, not measured (the "
                "population's 100–400 W)" + (f"; {self.detail}" if self.detail else ""))


def resolve(night_gain_w: float | None, night_gain_sd_w: float | None,
            nights: Sequence[NightSamples]) -> GainSource:
    """The gain a fit with these options uses on ``nights`` (the nights it fits): declared
    by the options, else by the nights' ``night_gain_w`` column (each night its own), else
    measured by their ``p_house_w``/``occupants``, else assumed (the fit may estimate it)."""
    measured = {n.night_id: (n.p_house_w, 0.0 if math.isnan(n.occupants) else n.occupants)
                for n in nights if not math.isnan(n.p_house_w)}
    sd = 0.0 if night_gain_sd_w is None else float(night_gain_sd_w)
    if night_gain_w is not None:
        note = ("p_house_w in the nights not used: the gain is declared" if measured else "")
        return GainSource("declared", float(night_gain_w), sd, detail=note)
    declared = {n.night_id: n.night_gain_w for n in nights if not math.isnan(n.night_gain_w)}
    if declared:   # the nights' own night_gain_w column: declared night by night
        value = sum(declared.values()) / len(declared)
        return GainSource("declared", value, sd, dict(declared),
                          f"night_gain_w column on {len(declared)} of {len(nights)} nights"
                          + ("; p_house_w not used" if measured else ""))
    if measured:
        per_night = {i: measured_gain_w(p, o) for i, (p, o) in measured.items()}
        p_mean = sum(p for p, _ in measured.values()) / len(measured)
        occ = sum(o for _, o in measured.values()) / len(measured)
        value = sum(per_night.values()) / len(per_night)
        detail = (f"p_house_w {p_mean:.0f} W mean on {len(measured)} of {len(nights)} nights"
                  + (f" + {occ:.1f} sleepers × {SLEEPER_W:.0f} W" if occ > 0 else ""))
        return GainSource("measured", value, measured_sd_w(p_mean, occ), per_night, detail)
    return GainSource("assumed", NIGHT_GAIN_W,
                      NIGHT_GAIN_SD_W if night_gain_sd_w is None else float(night_gain_sd_w))
