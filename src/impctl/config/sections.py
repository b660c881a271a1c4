"""The sections of the gateway's ``config.toml`` as frozen dataclasses, with their defaults:
``[night]``, ``[campaign]`` (and its ``target_rel_halfwidth`` table), ``[fit]``, ``[clock]``
and the whole :class:`Config` (``[heatpump]`` and ``[mqtt]`` come from their packages).

Temperatures °C, durations s unless the key says ``_h`` or ``_min``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..heatpump import HeatPumpConfig
from ..imp.protocol import (
    DEFAULT_BAND_K,
    DEFAULT_CONSTRAINED_SETPOINT_C,
    DEFAULT_PREHEAT_H,
    DEFAULT_SETPOINTS_C,
)
from ..mqtt.config import MqttConfig
from ..mqtt.inputs import InputsConfig
from ..numtext import parse_int


@dataclass(frozen=True)
class NightConfig:
    """How one IMP night runs."""

    window: str = "22:00-05:00"
    comfort_band_k: float = DEFAULT_BAND_K
    sample_interval_s: float = 60.0
    abort_margin_k: float = 0.5
    link_lost_limit_s: float = 900.0
    t_out_min_c: float = -25.0
    t_out_max_c: float = 8.0
    constrained_action: str = "loop_off"  # "loop_off" (mode 0) or "setpoint_floor"
    setpoint_floor_c: float = 18.0
    preheat_h: float = DEFAULT_PREHEAT_H
    emission_lag_h: float = 1.0
    min_coverage: float = 0.8
    max_comfort_band_k: float = 3.0


@dataclass(frozen=True)
class TargetHalfwidth:
    """``[campaign] target_rel_halfwidth``: 95 % interval half-width / estimate (0.05 = ±5 %)."""

    hlc: float = 0.05
    tau: float = 0.08


@dataclass(frozen=True)
class CampaignConfig:
    """Which nights to run and when to fit.

    ``mode = "fixed"`` (the default): the ``constrained_nights`` + setpoints ×
    ``normal_nights_per_setpoint`` plan. ``mode = "adaptive"``: after every valid night the
    daemon fits, predicts what each possible next night would bring (``impctl campaign next``)
    and runs, skips or stops by :func:`impctl.campaign.decide` until HLC and τ are known to
    ``target_rel_halfwidth``, at most ``max_nights`` nights, running the fixed plan's nights in
    :func:`impctl.campaign.plan_order` (``next_night = "information"``: the candidate the latest
    fit predicts most informative instead). Fixed is the default: the adaptive campaign's accuracy
    is about the plan's, not shown at least as good (README "Adaptive campaign");
    ``max_nights`` defaults to the fixed plan's 5,
    so opting in never costs a household more nights than the plan unless it is raised.
    """

    mode: str = "fixed"
    target_rel_halfwidth: TargetHalfwidth = field(default_factory=TargetHalfwidth)
    max_nights: int = 5
    min_each_kind: int = 1
    stall_nights: int = 3
    # adaptive: "plan" (the fixed plan's nights in plan order) or "information" (the night the
    # current fit predicts most informative; README "Adaptive campaign" for why plan is default)
    next_night: str = "plan"
    constrained_nights: int = 2
    constrained_setpoint_c: float = DEFAULT_CONSTRAINED_SETPOINT_C
    normal_setpoints_c: tuple[float, ...] = DEFAULT_SETPOINTS_C
    normal_nights_per_setpoint: int = 1
    misfire_grace_s: float = 3600.0
    fit_when_complete: bool = True  # fixed mode: fit after every valid night (false: never)
    # fixed mode: stop repeating after this many scheduled nights ended invalid (the household
    # is not asked for a cold night, night after night, that the house cannot make valid)
    max_invalid_nights: int = 3
    enabled: bool = True

    @property
    def adaptive(self) -> bool:
        """True in ``mode = "adaptive"``."""
        return self.mode == "adaptive"


@dataclass(frozen=True)
class FitConfig:
    """What the daemon's fit (``impctl fit`` in a subprocess) is told about the house."""

    # the house's mean night gain [W] (≈ 75 W per sleeper + base load), declared: known.
    # None (the key absent): not declared — the fit measures it from p_house_w, else
    # estimates or assumes it (impctl.imp.gain), and says which
    night_gain_w: float | None = None
    # SD of the declared gain [W]; None: 0 (known exactly)
    night_gain_sd_w: float | None = None
    # SD of the indoor / outdoor sensor's offset [K] and the heat meter's maximum error (a
    # fraction: 0.02 class 2, 0.05 class 3), declared; None: assumed (impctl.fit.checks.instruments)
    t_air_offset_sd_k: float | None = None
    t_out_offset_sd_k: float | None = None
    meter_error: float | None = None
    # the emitter, declared: one of impctl.imp.protocol.EMITTER_KINDS (known; a mixed house
    # declares the slower, underfloor). "" (the key absent): read from the heating water, else
    # assumed, said so
    emitter: str = ""



@dataclass(frozen=True)
class RecordConfig:
    """``[record]``: the house recorded read-only around the clock while no IMP night runs.

    A snapshot every ``sample_interval_s`` (absent: ``night.sample_interval_s``), averaged
    into rows of ``interval_s``; a column with fewer than ``night.min_coverage`` of a row's
    snapshots is missing. One ``owner`` record per local day (12:00 to 12:00); records older
    than ``keep_days`` are deleted once a day. Nothing is ever written to the heat pump.
    """

    enabled: bool = True
    interval_s: float = 300.0
    keep_days: int = 400
    sample_interval_s: float | None = None

    def snapshot_interval_s(self, night: NightConfig) -> float:
        """Seconds between two snapshots: ``sample_interval_s``, or the night's."""
        return night.sample_interval_s if self.sample_interval_s is None else (
            self.sample_interval_s)


@dataclass(frozen=True)
class CurveConfig:
    """The heating curve (``impctl curve``): advice always; set on the heat pump only when the
    owner asks.

    Attributes
    ----------
    apply : set the recommended curve on the heat pump's loop-1 curve points (an extended
        controller with its adaptive curve off) and watch comfort; ``impctl curve --apply`` and
        ``--restore`` say the same at run time and win over this key.
    margin_k : kelvin of flow temperature kept above the bound of what the house needs [K].
    raise_k : how much the comfort watch raises both curve points at a time [K].
    short_k : the room counts as short when it is on average more than this below its
        setpoint [K].
    short_h : over this window [h]: the watch raises the curve when the room's mean over the
        last ``short_h`` is short.
    """

    apply: bool = False
    margin_k: float = 1.0
    raise_k: float = 1.0
    short_k: float = 0.5
    short_h: float = 1.0


@dataclass(frozen=True)
class ClockConfig:
    """Simulated time for a dry run: ``speed`` × real time from ``epoch``.

    Load-sensitive: simulated time runs on while the daemon waits for the CPU, so on a busy
    or slow gateway a night may start late or miss samples. The demo and the in-process tests
    run on a virtual-time event loop instead (:mod:`impctl.clock.loop`), where it cannot; the
    tests that start the daemon as its own process use this clock, at speeds slow enough that
    a busy machine's pauses do not skip what they check.
    """

    epoch: str = ""                      # ISO 8601 instant; empty = real time
    speed: float = 1.0
    wall_epoch_s: float = 0.0            # POSIX s at which the clock showed epoch; 0 = start


@dataclass(frozen=True)
class Config:
    """The whole daemon configuration."""

    state_dir: str = "/var/lib/impctl"
    timezone: str = "Europe/Ljubljana"
    log_level: str = "info"
    model_dir: str = ""
    heatpump: HeatPumpConfig = field(default_factory=HeatPumpConfig)
    night: NightConfig = field(default_factory=NightConfig)
    campaign: CampaignConfig = field(default_factory=CampaignConfig)
    clock: ClockConfig = field(default_factory=ClockConfig)
    record: RecordConfig = field(default_factory=RecordConfig)
    fit: FitConfig = field(default_factory=FitConfig)
    mqtt: MqttConfig | None = None  # [mqtt]: off unless the section is present
    inputs: InputsConfig | None = None  # [inputs]: the house's own sensors over MQTT
    curve: CurveConfig = field(default_factory=CurveConfig)
    source: str = ""

    @property
    def db_path(self) -> Path:
        """The SQLite store in the state directory."""
        return Path(self.state_dir) / "impctl.db"

    @property
    def budget_path(self) -> Path:
        """The write-counter database in the state directory."""
        return Path(self.state_dir) / "writes.db"

    @property
    def window_minutes(self) -> tuple[int, int]:
        """The night window as minutes after local midnight (start, end)."""
        return _window(self.night.window)




def _window(text: str) -> tuple[int, int]:
    a, b = text.split("-")
    out = []
    for part in (a, b):
        h, m = part.strip().split(":")
        hh, mm = parse_int(h), parse_int(m)  # '２２' is not 22
        if not (0 <= hh < 24 and 0 <= mm < 60):
            raise ValueError(text)
        out.append(hh * 60 + mm)
    return out[0], out[1]
