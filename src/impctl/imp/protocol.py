"""The IMP night protocol's defaults: one set of numbers for the gateway and every simulation.

The gateway's ``[campaign]`` / ``[night]`` defaults (:mod:`impctl.config`), the night plans
(:mod:`impctl.imp.plan`), the bench's and the interval calibration's nights
(:func:`impctl.population.imp_run.synth.imp_schedule`) and the classifiers' virtual population
(:class:`impctl.population.imp_run.setup.ImpSimConfig`) all read them, so the product is measured
on the protocol it runs (bench/RESULTS.md, issue 14: "one protocol", branch h14q). Pure
constants: imported by the daemon's config, so no numpy or pandas here.
"""

from __future__ import annotations

#: T_set [°C] of the constrained nights: held at T_max = T_set + ΔT for the pre-heat, then the
#: heating is off in the window.
DEFAULT_CONSTRAINED_SETPOINT_C = 21.0
#: T_set [°C] of the normal nights, in turn (held through the window, heat output logged).
DEFAULT_SETPOINTS_C = (22.0, 23.0, 24.0)
#: Comfort band ΔT [K] around T_set: constrained nights pre-heat to T_set + ΔT and end at
#: T_set − ΔT. 2.5 K since branch h14w (the paper's case study and the product before: 1.5 K):
#: with 1.5 K about half of the realistic houses' constrained nights reach T_min with less than
#: MIN_NIGHT_H of cooling after the lag and a third of the households never record a valid one
#: (bench/RESULTS.md, "Issue 14: the gateway's constrained nights everywhere").
DEFAULT_BAND_K = 2.5
#: Time [h] the night's pre-window setpoint (T_max or T_set) is held before the window.
DEFAULT_PREHEAT_H = 2.0

#: Heat output above which the heating counts as running [W]: a constrained night's data end
#: where it resumes (the fit's cut and the gateway's validity read the same number).
Q_ON_W = 100.0

#: Hours of data a night needs to be valid [h] — for a constrained night counted after the
#: switch-off plus the emission lag (the part the fit uses). The gateway's assessment
#: (:func:`impctl.controller.assess.assess_night`), the fit's shortest night
#: (``NightFit(min_night_h)``) and the bench's gateway nights read it (issue 14, branch h14w).
MIN_NIGHT_H = 3.0
#: A constrained night that reached T_min before MIN_NIGHT_H of cooling and failed nothing
#: else: too short for the IMP fit, yet the house cooling from T_max is what gives the season
#: model its time constant (in a house that cools fast, the only constrained nights there
#: are). The gateway's verdict (a reason of the stored night) and the NIGHTS ``label`` of
#: such a night: the season model reads it, the IMP fit, the classifiers and the campaign
#: leave it out (:func:`impctl.imp.night.split_owner`).
SHORT_NIGHT = "short night (read by the season model only)"
#: How a constrained night ends on the gateway before T_min (:class:`impctl.controller.plan.
#: NightPolicy`, mirrored by the simulations; the rule itself is :func:`anticipates_t_min`): the
#: least-squares trend of T_air over the last TREND_WINDOW_S [s] (at least MIN_TREND_SPAN_S)
#: reaches T_min within ANTICIPATE_S [s] while T_air is within ANTICIPATE_WITHIN_K [K] of it.
ANTICIPATE_S = 1800.0
ANTICIPATE_WITHIN_K = 1.0
TREND_WINDOW_S = 1800.0
MIN_TREND_SPAN_S = 600.0
#: A constrained night switches the heating off only if T_air is this far above T_min at the
#: window's start [K]; otherwise the heating is left on and the night is not valid.
SWITCH_OFF_MIN_K = 1.5


def anticipates_t_min(t_air_c, slope_k_per_s, t_min_c, within_k=ANTICIPATE_WITHIN_K,
                      ahead_s=ANTICIPATE_S):
    """Whether a constrained night ends before T_min: T_air [°C] within ``within_k`` [K] of
    T_min [°C] and its trend ``slope_k_per_s`` [K/s] reaching T_min within ``ahead_s`` [s].

    The one rule for the gateway (:func:`impctl.controller.plan.anticipated_end`) and the
    simulated nights (:func:`impctl.population.imp_run.gateway.gateway_end`, the virtual
    population's plant); each computes the trend where it has its readings. Floats give a bool,
    numpy arrays an element-wise array (hence ``&``, not ``and``).
    """
    return ((t_air_c <= t_min_c + within_k) & (slope_k_per_s < 0)
            & (t_air_c + slope_k_per_s * ahead_s <= t_min_c))


#: The emitters an installer may declare (``[fit] emitter``, ``--emitter``): the season model's
#: bound on the emitter's lag follows it (:mod:`impctl.season.emitter`). A mixed house (a
#: screed downstairs, radiators upstairs) declares the slower, underfloor: its bound holds both.
EMITTER_KINDS = ("radiators", "underfloor")
