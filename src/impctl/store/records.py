"""Plain records read from and written to the store (units in the field names)."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime

#: The kinds of IMP night (the heat pump driven); the third kind, "owner", is recorded only.
IMP_KINDS = ("constrained", "normal")


@dataclass(frozen=True)
class Night:
    """One IMP night as stored, or one owner record (``kind`` "owner").

    ``state`` runs planned → active → restoring → done; ``aborted`` when an abort condition
    stopped it (restored), ``interrupted`` when the process died during it (restored at the
    next start). ``valid`` is None until assessed; ``reasons`` lists why a night is not valid
    (or notes on a valid one).

    An owner record (the house recorded read-only,
    :mod:`impctl.controller.recording.recorder`) spans ``window_start`` (local noon) to
    ``window_end`` (the next local noon); ``state`` is
    "recording" until it is closed ("done"), ``reasons`` are its labels ("data missing: …"),
    ``valid`` is True without a label, and ``setpoint_c`` is the owner's loop-1 setpoint at
    night (None when it was never read).
    """

    id: int
    kind: str
    setpoint_c: float | None
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
    raw register codes; ``t_flow_target_c`` is the loop-1 calculated flow target (2128, the
    heating curve the heat pump runs), ``system_on`` the heating system switch (2012).

    A row of an owner record is the mean of ``snapshots`` snapshots taken in [``ts``, ``ts`` +
    the row interval): temperatures and powers are means (None when fewer than the minimum
    coverage of the row's snapshots had the value), ``dhw_share`` the share of them that
    charged hot water (0–1), ``defrost`` True when any of them defrosted, ``error_bits`` the
    bits any of them showed; ``setpoint_c``, ``loop_mode``, ``system_on`` and
    ``working_function`` are the last values read. An IMP night's sample is one snapshot
    (``snapshots`` and ``dhw_share`` None).
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
    t_flow_target_c: float | None = None
    dhw_share: float | None = None
    system_on: int | None = None
    snapshots: int | None = None


SAMPLE_COLUMNS = (
    "t_air_c", "t_out_c", "q_hc_w", "p_el_w", "t_supply_c", "t_return_c", "working_function",
    "defrost", "error_bits", "loop_mode", "setpoint_c", "dhw_active", "t_flow_target_c",
    "dhw_share", "system_on", "snapshots",
)


@dataclass(frozen=True)
class JournalEntry:
    """The owner's value of one register, recorded BEFORE impctl first wrote it.

    ``raw_value`` is the register's raw 16-bit content (restored verbatim); ``restored`` is
    None until a read-back confirmed the restore. ``confirmed_raw``: what impctl last wrote
    into the register and read back (raw), None while a write is not read back or nothing is
    known; a restore after the process died tells the owner's later change by it.
    """

    id: int
    night_id: int | None
    register: str
    address: int
    raw_value: int
    recorded: datetime
    restored: datetime | None = None
    confirmed_raw: int | None = None


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
