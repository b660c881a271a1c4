"""The unmetered heat a house gets at night (sleepers, base load): what is assumed of it.

An occupied house never has 0 W at night: each sleeper gives ≈ 70–80 W and the night base
load (fridge, router, standby) ≈ 80–180 W, 100–400 W in all (real-houses.md §4; the realistic
plant draws it over that range). IMP nights cannot separate a constant gain from the HLC
(Q = HLC·ΔT − G), so a fit that assumes 0 W puts it into the HLC: every house low (README
"Accuracy", issue 14). The night fit (``impctl.fit.NightFit(night_gain_w=…)``), the flex coast
and the gateway config (``[fit] night_gain_w``) use these constants — one assumption, not
several. Pure constants: imported by the daemon's config, so no numpy here.
"""

from __future__ import annotations

#: Documented range of the mean night gain [W] (real-houses.md §4).
NIGHT_GAIN_RANGE_W = (100.0, 400.0)
#: Assumed mean night gain [W] when the installer does not know the household: the centre of
#: :data:`NIGHT_GAIN_RANGE_W`.
NIGHT_GAIN_W = 0.5 * (NIGHT_GAIN_RANGE_W[0] + NIGHT_GAIN_RANGE_W[1])
#: SD [W] of that assumption: the range as a uniform distribution, width/√12 ≈ 87 W.
NIGHT_GAIN_SD_W = (NIGHT_GAIN_RANGE_W[1] - NIGHT_GAIN_RANGE_W[0]) / 12.0 ** 0.5
#: Accepted values of an installer's night gain [W] (config, ``impctl fit --night-gain-w``):
#: 0 (an empty house, or the ideal 5R1C) up to a large household with equipment running.
NIGHT_GAIN_LIMITS_W = (0.0, 2000.0)
