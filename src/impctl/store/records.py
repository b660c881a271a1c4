"""Plain records read from and written to the store (units in the field names)."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime


@dataclass(frozen=True)
class Night:
    """One IMP night as stored.

    ``state`` runs planned → active → restoring → done; ``aborted`` when an abort condition
    stopped it (restored), ``interrupted`` when the process died during it (restored at the
    next start). ``valid`` is None until assessed; ``reasons`` lists why a night is not valid
    (or notes on a valid one).
    """

    id: int
    kind: str
    setpoint_c: float
    t_min_c: float | None
    t_max_c: float | None
    window_start: datetime
    window_end: datetime
    state: str
    source: str
    valid: bool | None = None
    reasons: tuple[str, ...] = ()
    started: datetime | None = None
    ended: datetime | None = None


@dataclass(frozen=True)
class Sample:
    """One snapshot of the heat pump during a night; None = missing (sensor absent, sentinel).

    Temperatures °C, powers W; ``working_function``, ``error_bits`` and ``loop_mode`` are the
    raw register codes.
    """

    night_id: int
    ts: datetime
    t_air_c: float | None = None
    t_out_c: float | None = None
    q_hc_w: float | None = None
    p_el_w: float | None = None
    t_supply_c: float | None = None
    t_return_c: float | None = None
    working_function: int | None = None
    defrost: bool | None = None
    error_bits: int | None = None
    loop_mode: int | None = None
    setpoint_c: float | None = None
    dhw_active: bool | None = None


SAMPLE_COLUMNS = (
    "t_air_c", "t_out_c", "q_hc_w", "p_el_w", "t_supply_c", "t_return_c", "working_function",
    "defrost", "error_bits", "loop_mode", "setpoint_c", "dhw_active",
)


@dataclass(frozen=True)
class JournalEntry:
    """The owner's value of one register, recorded BEFORE impctl first wrote it.

    ``raw_value`` is the register's raw 16-bit content (restored verbatim); ``restored`` is
    None until a read-back confirmed the restore.
    """

    id: int
    night_id: int | None
    register: str
    address: int
    raw_value: int
    recorded: datetime
    restored: datetime | None = None


@dataclass(frozen=True)
class TriggerRequest:
    """A manual night request queued by ``impctl trigger`` for the running daemon."""

    id: int
    kind: str
    setpoint_c: float | None
    when: str  # "now" or "tonight"
    created: datetime
    taken: datetime | None = None
    extra: dict = field(default_factory=dict)
    expires: datetime | None = None  # on the daemon's clock; None = never
    outcome: str | None = None  # "taken", "cancelled" or "expired" once no longer pending


@dataclass(frozen=True)
class Command:
    """A household command queued for the running daemon (over MQTT, for instance).

    ``name`` is ``abort`` (end the running night now and restore the owner's settings) or
    ``skip_tonight`` (do not start the next scheduled night; expires after 24 h).
    """

    id: int
    name: str
    source: str
    created: datetime
    taken: datetime | None = None


@dataclass(frozen=True)
class FitRecord:
    """One stored fit: the valid nights it used (ids and how many), the ``impctl fit`` JSON,
    and in adaptive mode the predictions ``impctl campaign next`` made from it."""

    id: int
    created: datetime
    nights: list[int]
    night_count: int
    result: dict
    candidates: dict | None = None


@dataclass(frozen=True)
class CampaignDecision:
    """What the adaptive campaign decided for one night, and why.

    ``action``: "run" (``kind`` at ``setpoint_c`` °C), "skip" (tonight only) or "stop" (the
    campaign ended; ``reached`` when the precision target was met). ``forecast_t_out_c`` [°C]
    with ``forecast_source`` saying where it came from.
    """

    id: int
    created: datetime
    act: datetime | None
    action: str
    kind: str | None
    setpoint_c: float | None
    reason: str
    reached: bool = False
    forecast_t_out_c: float | None = None
    forecast_source: str | None = None
