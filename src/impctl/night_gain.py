"""The heat a house gets at night besides the heating (sleepers, base load): known, measured,
estimated or assumed — in that order.

An occupied house never has 0 W at night: each sleeper gives ≈ 70–80 W and the night base
load (fridge, router, standby) ≈ 80–180 W, 100–400 W in all (real-houses.md §4; the realistic
plant draws it over that range). IMP nights cannot separate a constant gain from the HLC
(Q = HLC·ΔT − G), so a fit that assumes 0 W puts it into the HLC: every house low (README
"Accuracy", issue 14). The night fit (``impctl.fit.NightFit(night_gain_w=…)``), the flex coast
and the gateway config (``[fit] night_gain_w``) use these constants — one assumption, not
several. Pure constants: imported by the daemon's config, so no numpy here.

Where the gain comes from, in this order (:mod:`impctl.fit.gain`):

* **declared** (known): the installer says it (``impctl fit --night-gain-w``, ``[fit]
  night_gain_w``): that value, ± 0 W unless an SD is declared too;
* **measured**: the NIGHTS column ``p_house_w`` (household electricity besides the heat
  pump) and ``occupants``: :data:`INDOOR_SHARE` of the electricity plus :data:`SLEEPER_W` per
  sleeper, with the uncertainty of :func:`measured_sd_w`;
* **estimated**: a gain term fitted with the other parameters, where the nights inform it;
* **assumed**: :data:`NIGHT_GAIN_W` ± :data:`NIGHT_GAIN_SD_W`, last, and said to be assumed.
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

#: The sources of a night gain, in the order they are used.
GAIN_SOURCES = ("declared", "measured", "estimated", "assumed")
#: Heat of a sleeping adult [W]: 0.7 met ≈ 40 W/m² at 1.8 m² (real-houses.md §4, ASHRAE);
#: women ≈ 85 %, children ≈ 75 % of it.
SLEEPER_W = 75.0
#: SD of one sleeper's heat [W]: the 55–80 W of a child to an adult.
SLEEPER_SD_W = 10.0
#: Share of a household's electricity that ends as heat inside the heated envelope at night:
#: nearly all (fridge, router, standby, lights), less what leaves as outdoor or garage loads,
#: warm water drained and exhaust air [own choice: 90–100 %, a uniform].
INDOOR_SHARE = (0.90, 1.00)
#: Half-width of the household electricity meter's relative error: ±2 % (a MID class A
#: meter's maximum permissible error; class B and C meters and the utility's meter do better,
#: a clamp-on sensor may not).
HOUSE_METER_ERROR = 0.02


def measured_gain_w(p_house_w: float, occupants: float = 0.0) -> float:
    """The night gain [W] of a night with mean household electricity ``p_house_w`` [W] and
    ``occupants`` sleepers: the central indoor share of the electricity plus the sleepers."""
    share = 0.5 * (INDOOR_SHARE[0] + INDOOR_SHARE[1])
    return share * p_house_w + SLEEPER_W * occupants


def measured_sd_w(p_house_w: float, occupants: float = 0.0) -> float:
    """SD [W] of :func:`measured_gain_w`: the indoor share and the meter's error (uniforms,
    width/√12 each) on the electricity, :data:`SLEEPER_SD_W` per sleeper; systematic over a
    campaign (the same house and meter), so it does not shrink with the number of nights."""
    share_sd = (INDOOR_SHARE[1] - INDOOR_SHARE[0]) / 12.0 ** 0.5
    meter_sd = 2.0 * HOUSE_METER_ERROR / 12.0 ** 0.5
    rel = (share_sd ** 2 + meter_sd ** 2) ** 0.5
    return ((rel * p_house_w) ** 2 + (SLEEPER_SD_W * occupants) ** 2) ** 0.5
