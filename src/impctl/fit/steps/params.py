"""What the steps of a fit read of their :class:`~impctl.fit.NightFit`: its constructor
parameters, as a typing protocol, so that :mod:`.problems` and :mod:`.statement` need not
import the estimator that imports them (the parameters' meaning and units: NightFit's
docstring)."""

from __future__ import annotations

from typing import Protocol

from ..prior import PopulationPrior


class FitParams(Protocol):
    """The constructor parameters of a NightFit that its steps read (typing only)."""

    normal_model: str
    emission_lag_h: float
    ach_vent: float
    ach_infl: float
    timestamps: str
    smooth_air_h: float
    smooth_out_h: float
    physical_bounds: dict[str, tuple[float, float]] | None
    n_starts: int
    per_night: bool
    min_night_h: float
    ridge: float
    resume_threshold_w: float
    seed: int
    fit_step_s: float
    night_gain: bool | str
    emitter_state: bool
    furniture_state: bool
    sensor_offsets_k: tuple[float | None, float | None] | None
    meter_error: float | None
    night_gain_w: float | None
    night_gain_sd_w: float | None
    settle_h: float
    structure_share: bool
    solver: str
    emitter_lag: bool
    settle_until_held: bool
    prior: str | PopulationPrior | None
