"""Night-time Neural-ODE fit of the 5R1C parameters (the paper's step 4).

:class:`NightFit` fits the seven Table IV parameters — each inside a sigmoid-bounded range: the
classified range for floor_area, c_f and u_walls, physical bounds for the others — plus one free
initial mass temperature per night, to IMP nights (:class:`~impctl.imp.night.NightSamples`).
The dynamics are the paper's eq. 6 on constrained nights (from switch-off + the emission lag) and
eq. 5 (or its demand form) on normal nights, integrated by ``torchdiffeq`` (:mod:`.ode.node`); the
optimiser is :mod:`.optim.lm`. Two modes are always computed: one joint fit over all nights with
shared parameters (the headline) and per-night fits averaged afterwards (the paper's way).

What is reported as *measured* is what the data determines (identifiability.md): the lumped
HLC, C_m and τ with 95 % intervals, and for each physical parameter whether the data pins it
down or only its search range does (:mod:`.intervals.uncertainty`).

Class ranges are a prior, and a wrong class biases even the lumped quantities. The joint fit is
therefore run twice in the same batch — inside the class ranges and inside the whole prior
ranges — and a likelihood-ratio test decides: if the data fit clearly better outside the class
ranges, the classification is reported as contradicted and the prior-range fit is used.

Here is the estimator and its procedure in a few steps; the steps live by concern:
:mod:`.steps.problems` (the nights prepared, the problems laid out: :mod:`.layout`),
:mod:`.steps.weights` (the noise weights and the refits they ask for), :mod:`.steps.statement`
(the problem reported, by the likelihood-ratio tests of :mod:`.checks.selection`, and every
fitted attribute, with :mod:`.intervals` and :mod:`.checks.validation`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import torch

from ..imp.features import Q_ON_W
from ..imp.night import NightSamples
from ..imp.plan import EMISSION_LAG_H
from ..imp.protocol import MIN_NIGHT_H
from .intervals import model_error
from .layout import stop_units
from .ode.solver import METHODS
from .optim import lm
from .prior import PopulationPrior
from .steps.problems import prepare
from .steps.statement import choose, statement
from .steps.weights import NOISE_PASSES, NOISE_RTOL, Weights, settle

# NOISE_PASSES and NOISE_RTOL live with the noise weights (:mod:`.steps.weights`); named here
# too, as the ``noise`` option's documentation names them
__all__ = ["NOISE_MODELS", "NOISE_PASSES", "NOISE_RTOL", "NORMAL_MODELS", "NightFit"]

NORMAL_MODELS = ("demand", "series", "mean")
NOISE_MODELS = ("night", "kind")


class NightFit:
    """Fit the night-time 5R1C model to IMP nights (scikit-learn style estimator).

    Parameters
    ----------
    normal_model : {"demand", "series", "mean"}
        How normal nights enter. "mean": the paper's eq. 5 with Φ_HC the night's mean power;
        "series": eq. 5 driven by the measured Φ_HC series; "demand" (default): the same 5R1C
        equations read the other way round — the held T_air drives the model and the heat power
        is its output, compared with the measured power. Measured on the benchmark (``bench/fit.py
        --compare``, 20 households, 5-min samples): median HLC error 19 % (mean: the mass keeps
        charging after the setpoint step, identifiability.md §11.1), 3.5 % (series: the power
        noise enters as an input, errors in variables, §11.3) and 0.8 % (demand).
    emission_lag_h : float
        Constrained nights are fitted from switch-off + this lag [h] (the paper's 1 h).
    ach_vent, ach_infl : float
        Fixed air changes [1/h]; default the paper's (and the virtual population's) 0 and 0.01.
    timestamps : {"instant", "interval"}
        Sample convention (:func:`~impctl.fit.ode.packing.pack_nights`).
    smooth_air_h : float
        Width [h] of the moving average of the held T_air that drives "demand" rows, so that
        quantisation flicker does not reach the predicted power through the massless air node.
    smooth_out_h : float
        Width [h] of the moving average of T_out in every row (outdoor-sensor noise would
        otherwise enter as errors in the variables).
    physical_bounds : dict, optional
        Search bounds of the non-classified parameters (default :data:`PHYSICAL_BOUNDS`), and the
        prior ranges of the classified ones.
    n_starts : int
        Starts per problem (the first at the centre of the box, the others random); the best is
        kept. One by default (the centre): against two, paired on 200 held-out realistic
        households with the whole prior ranges, the classifiers' and each house's true classes,
        the same median errors within their 95 % CIs (differences −0.1 … +0.6 points) and the
        same coverage, the twin houses' HLC within 0.3 points, at about 0.6 of a fleet's CPU
        (two against four: 0.7; decision record 0018).
    max_iter : int
        Levenberg–Marquardt iterations (per pass).
    optimizer : {"lm", "adam"}
        Levenberg–Marquardt (default) or the paper's Adam with backprop through the solver
        (10·max_iter steps; much slower, see ``bench/fit.py --compare``).
    per_night : bool
        Also fit each night alone (the paper's per-night-then-average mode).
    min_night_h : float
        Nights shorter than this after cutting [h] are skipped (``skipped_``).
    ridge : float
        Weight of the weak prior at the centre of each range (decides exactly flat directions).
    resume_threshold_w : float
        Heat power [W] that marks resumed heating on a constrained night.
    seed : int
        Seed of the random starts.
    fit_step_s : float
        Rows finer than this [s] are combined into blocks of this length before the fit
        (temperatures by a centred mean, power by the block's mean;
        :mod:`.nights.resample`); 0 keeps every row. Only with "instant" stamps.
    solver : {"exact", "rk4"}
        How the night ODE is integrated (:class:`~impctl.fit.ode.solver.NightODE`): "exact" (the
        default; the closed-form solution per sample interval) or "rk4" (``torchdiffeq.odeint``);
        they agree to rk4's error, "exact" is several times cheaper.
    night_gain : {"prior", True, False}
        The night gain when it is neither declared nor measured (``night_gain_w``): "prior"
        (default) fits it in every joint problem under a Gaussian prior, the assumption
        :data:`~impctl.imp.gain.NIGHT_GAIN_W` ± :data:`~impctl.imp.gain.NIGHT_GAIN_SD_W`
        (a MAP estimate; its posterior SD enters the intervals) — reported *estimated* where
        the nights shrink the prior's SD to ≤ 0.7 of it, else *assumed*; True: a term the
        likelihood-ratio test keeps with the others; False: pinned to the assumption.
    emitter_state, furniture_state : bool
        Nuisance terms of the night model (:data:`~.ode.parameters.NUISANCE_NAMES`): the
        emitter's release after switch-off (amplitude and time constant); air/furniture
        capacity at the air node (counted in the reported C_m, τ). Kept only when a
        likelihood-ratio test says the data need them.
    sensor_offsets_k : (float or None, float or None) or None
        SD of the T_air and T_out sensors' offsets [K] (a type-B interval share), declared;
        None (or a None element): assumed, 0.5 K indoors and 1.0 K outdoors
        (:data:`.instruments.ASSUMED_SENSOR_OFFSETS_K`), and said so.
    meter_error : float or None
        Half-width of the heat meter's systematic relative error (0.02: class 2, 0.05: class 3),
        added to the HLC and C_m intervals as a uniform type-B share, declared; None: assumed
        0.05, and said so.
    settle_h : float
        Hours after the start of a held night whose heat power is not compared (the setpoint
        step charges emitter, air and furniture); T_air still drives the model.
    settle_until_held : bool
        Also leave out a held night's power until T_air first comes within 0.2 K of the
        level it is held at (the median of the night's second half): while it climbs, the
        heat pump runs at capacity and the emitter charges (:func:`.data.settled`).
    emitter_lag : bool
        The heat meter measures the heat into the emitter, not into the room (the accuracy page of
        the documentation): a share of C_m (``emitter_share``, 0–0.6) sits in an emitter node
        between the meter and the air with the time constant ``emitter_tau_h`` of the release after
        switch-off, one pair for both kinds of night. Held nights compare P + τ_e·dP/dt +
        C_e·dT_air/dt with the metered power (P the 5R1C's heat to the room); constrained nights add
        the heat the emitter gives back while the room cools. A nuisance term like the others (needs
        ``emitter_state``; same likelihood-ratio test).
    structure_share : bool
        Widen the intervals by half the log-difference of HLC, C_m, τ between the fits with and
        without the nuisance terms (a structural-sensitivity share).
    night_gain_w : float or None
        The mean night gain [W] (sleepers ≈ 75 W each + base load), **declared**: known,
        used as given (± ``night_gain_sd_w``, 0 W unless given) — 0 on an empty house or the
        ideal 5R1C. None (default): not declared; the nights' ``p_house_w``/``occupants``
        measure it (each night its own, :func:`impctl.imp.gain.measured_gain_w`), else the
        gain term estimates it (``night_gain``, when the likelihood-ratio test keeps it), else
        it is **assumed**: :data:`impctl.imp.gain.NIGHT_GAIN_W` (250 W, real-houses.md §4)
        ± :data:`~impctl.imp.gain.NIGHT_GAIN_SD_W`. A gain not fitted enters the model as
        a constant internal gain (split over the air, surface and mass nodes as ISO 13790
        C.1–C.3 splits Φ_int) on every night of both kinds; ``night_gain_`` says which
        source was used (:mod:`.gain`).
    night_gain_sd_w : float or None
        SD [W] of a declared or assumed gain (default: 0 W declared, 300/√12 ≈ 87 W
        assumed), added to the intervals as the share night_gain_sd_w/(HLC·mean ΔT) when no
        gain term is fitted (see :func:`.uncertainty.offset_allowance`); a measured gain
        carries its measurement's SD.
    prior : {"population", None} or PopulationPrior
        A population prior inside the class ranges (:mod:`.prior`): "population" (default)
        puts the virtual population's ln C_m distribution inside the search box (seed 0, the
        classifiers' population) into the objective as a penalty residual, weighted as the
        intervals weigh the data (:meth:`~impctl.fit.prior.PopulationPrior.tempered`), so
        the fit is a MAP estimate and its intervals are posterior intervals; a
        :class:`~impctl.fit.prior.PopulationPrior` chooses the quantities, the population or
        the class probabilities of a mixture; None: no prior.
        Measured (``bench/fit.py``, 50 realistic households, gateway's nights): C_m median
        error 21.1 → 14.5 %. Reported in ``prior_`` (centre, SD, posterior/prior SD ratio,
        prior-dominated).
    noise : {"night", "kind"}
        The noise model of the residuals, i.e. how the nights weigh against each other.
        "night" (default): one noise SD per night, estimated in the likelihood — the joint
        problems are refitted with each night's RMS residual as its σ until those settle
        (at most :data:`NOISE_PASSES` refits; iteratively reweighted least squares, whose
        fixed point is the maximum-likelihood fit with an unknown variance per night). A
        cycling heat pump's night, a night the model fits worse, or a night with a noisier
        sensor then weighs less; at the fixed point every night's weighted residuals sum to
        about its number of compared samples. "kind": one σ
        per residual kind (constrained T_air, normal T_air, normal power); "night" measured
        HLC 15.9 → 13.7 %, τ 14.3 → 12.1 % median on the realistic plant's gateway nights
        (decision record 0008).
    model_error : str or None
        Model-error share calibrated on the realistic virtual population, added to the
        intervals in quadrature (:mod:`.model_error`): "default" (the packaged calibration), a
        path to a calibration JSON, or None (off: the intervals describe the measurement only).

    Attributes (after :meth:`fit`)
    ------------------------------
    parameters_ : dict[str, float]  joint-fit physical parameters (units as the house TOML)
    bounds_ : dict[str, (lo, hi)]   the search box of the reported fit
    determined_ : dict[str, bool]   whether the data (not the box) pins each parameter down
    lumped_ : dict[str, Estimate]   hlc [W/K], c_m [J/K], tau [h] with 95 % intervals
    class_check_ : dict             likelihood-ratio test of the class ranges (see module doc)
    t_m0_c_ : dict[str, float]      fitted initial mass temperature per night [°C]
    per_night_ : list[dict]         per-night fits (parameters, lumped) — the paper's mode
    per_night_mean_ : dict          their averaged parameters and lumped values
    validation_ : dict              heat demand on normal nights, T_air RMSE on constrained ones
    predictions_ : list[dict]       measured vs fitted series per night (for plots)
    sigma_ : dict[str, float]       residual standard deviation per group
    sigma_night_ : dict[str, float] per used night, the σ its residuals were weighted with
                                    (K on constrained nights, W on held nights; ``noise``)
    skipped_ : list[(night_id, reason)]
    gaps_ : list[impctl.imp.gaps.Gap]  gaps inside nights; each night was cut to one gap-free
                                       piece first (rule in :mod:`impctl.imp.gaps`)
    night_quality_ : list[dict]     per given night: rows, cycles/h, interruptions, emitter
                                    discharge, T_air resolution, used/usable_h/reason
                                    (:mod:`.nights.quality`)
    night_gain_ : dict              the night gain used [W]: value_w, sd_w, source
                                    ("declared" | "measured" | "estimated" | "assumed"),
                                    assumed (source "assumed"), statement
    cross_checks_ : dict            the room sensors' and the outdoor reference's offsets
    prior_ : dict or None           the prior used: per quantity its centre, prior and
                                    posterior SD (log) and whether it is prior-dominated
    adequacy_ : dict                residual RMSE and autocorrelation per group, and whether
                                    the model describes the data well enough for its intervals
    loss_, n_iter_, fit_time_s_ : float, int, float
    """

    def __init__(self, *, normal_model: str = "demand", emission_lag_h: float = EMISSION_LAG_H,
                 ach_vent: float = 0.0, ach_infl: float = 0.01, timestamps: str = "instant",
                 smooth_air_h: float = 1.0, smooth_out_h: float = 0.0,
                 physical_bounds: dict[str, tuple[float, float]] | None = None,
                 n_starts: int = 1, max_iter: int = 40, optimizer: str = "lm",
                 per_night: bool = True, min_night_h: float = MIN_NIGHT_H, ridge: float = 1e-2,
                 resume_threshold_w: float = Q_ON_W, seed: int = 0, fit_step_s: float = 300.0,
                 night_gain: bool | str = "prior", emitter_state: bool = True,
                 furniture_state: bool = True,
                 sensor_offsets_k: tuple[float | None, float | None] | None = None,
                 meter_error: float | None = None, night_gain_w: float | None = None,
                 night_gain_sd_w: float | None = None,
                 settle_h: float = 1.0, structure_share: bool = True, solver: str = "exact",
                 emitter_lag: bool = False, settle_until_held: bool = False,
                 noise: str = "night", model_error: str | None = "default",
                 prior: str | PopulationPrior | None = "population"):
        self.normal_model = normal_model
        self.emission_lag_h = emission_lag_h
        self.ach_vent = ach_vent
        self.ach_infl = ach_infl
        self.timestamps = timestamps
        self.smooth_air_h = smooth_air_h
        self.smooth_out_h = smooth_out_h
        self.physical_bounds = physical_bounds
        self.n_starts = n_starts
        self.max_iter = max_iter
        self.optimizer = optimizer
        self.per_night = per_night
        self.min_night_h = min_night_h
        self.ridge = ridge
        self.resume_threshold_w = resume_threshold_w
        self.seed = seed
        self.fit_step_s = fit_step_s
        self.night_gain = night_gain
        self.emitter_state = emitter_state
        self.furniture_state = furniture_state
        self.sensor_offsets_k = sensor_offsets_k
        self.solver = solver
        self.meter_error = meter_error
        self.night_gain_w = night_gain_w
        self.night_gain_sd_w = night_gain_sd_w
        self.settle_h = settle_h
        self.structure_share = structure_share
        self.emitter_lag = emitter_lag
        self.settle_until_held = settle_until_held
        self.noise = noise
        self.model_error = model_error
        self.prior = prior

    def fit(self, nights: Sequence[NightSamples],
            ranges: dict[str, tuple[float, float]] | None = None) -> NightFit:
        """Fit to ``nights`` with floor_area, c_f, u_walls bounded by ``ranges`` (if given).

        Raises
        ------
        InputError
            When no night is usable (each skipped night is named).
        """
        if self.normal_model not in NORMAL_MODELS:
            raise ValueError(f"normal_model must be one of {NORMAL_MODELS}")
        if self.optimizer not in ("lm", "adam"):
            raise ValueError("optimizer must be 'lm' or 'adam'")
        if self.solver not in METHODS:
            raise ValueError(f"solver must be one of {METHODS}")
        if not (self.prior is None or self.prior == "population"
                or isinstance(self.prior, PopulationPrior)):
            raise ValueError("prior must be None, 'population' or a PopulationPrior")
        if self.noise not in NOISE_MODELS:
            raise ValueError(f"noise must be one of {NOISE_MODELS}")
        started = time.perf_counter()
        threads = torch.get_num_threads()
        torch.set_num_threads(1)  # the per-household target is for one core
        try:
            self._fit(nights, ranges)
        finally:
            torch.set_num_threads(threads)
        self.fit_time_s_ = time.perf_counter() - started
        return self

    # ------------------------------------------------------------------ fit
    def _fit(self, nights, ranges) -> None:
        # a broken calibration file is named before any work is done
        cal = (None if self.model_error is None else model_error.load_calibration(
            None if self.model_error == "default" else str(self.model_error)))
        problems = prepare(self, nights, ranges)
        # the optimiser step reads the context here (also the fleet's batched one, .optim.batch)
        self._ctx, self._group_n = problems.ctx, problems.group_n
        weights = Weights.guessed(problems)
        rows = weights.rows(problems)
        result = self._optimise(rows, problems.lay["u0"],
                                problems.initial_mass(self.ach_vent, self.ach_infl),
                                problems.lay["group"])
        weights = settle(problems, weights, rows, result, self._optimise, self.noise)
        choice = choose(problems, weights.rows(problems), result)
        vars(self).update(statement(self, problems, weights, result, choice, cal))
        # the reported problem's rows and optimum, which its intervals can be recomputed from
        self._sub, self._u, self._t_m0 = choice.sub, choice.u, choice.t_m0

    def _optimise(self, rows, u0, t_m0, groups) -> lm.LMResult:
        if self.optimizer == "adam":
            return lm.adam(self._ctx, rows, u0, t_m0, n_iter=10 * self.max_iter)
        return lm.levenberg_marquardt(self._ctx, rows, u0, t_m0, groups=groups,
                                      units=stop_units(groups), max_iter=self.max_iter)

    def to_dict(self) -> dict:
        """JSON-ready summary (see :mod:`.result.report`)."""
        from .result.report import fit_to_dict

        return fit_to_dict(self)
