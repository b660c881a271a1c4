"""What one poll of the heat pump means for a night: the stored sample, alarms, missing
readings, fitness to start, the progress line.

Pure functions of a :class:`~impctl.heatpump.Snapshot`; the night state machine
(:mod:`.night`) decides what to do with their answers.
"""

from __future__ import annotations

from ..heatpump import Snapshot
from ..store import Sample
from .plan import NightPolicy, NightRequest

#: Working function (2001) of a heat pump switched off by its remote-off input.
_REMOTE_OFF_FUNCTION = 7


def sample_from_snapshot(night_id: int, snap: Snapshot) -> Sample:
    """A store sample from a snapshot (missing readings become None)."""
    v = snap.values()

    def flag(x: float | None) -> bool | None:
        return None if x is None else bool(x)

    return Sample(
        night_id=night_id, ts=snap.timestamp, t_air_c=v["t_air_c"], t_out_c=v["t_out_c"],
        q_hc_w=v["q_hc_w"], p_el_w=v["p_el_w"], t_supply_c=v["t_supply_c"],
        t_return_c=v["t_return_c"],
        working_function=None if v["working_function"] is None else int(v["working_function"]),
        defrost=flag(v["defrost"]), error_bits=_error_bits(snap),
        loop_mode=None if v["loop1_mode"] is None else int(v["loop1_mode"]),
        setpoint_c=v["loop1_setpoint_c"],
        dhw_active=None if v["working_function"] is None else int(v["working_function"]) == 1,
        t_flow_target_c=v["loop1_target_c"],
        system_on=None if v["system_on"] is None else int(v["system_on"]),
    )


def readings_problem(snap: Snapshot) -> str | None:
    """Why the readings a night needs are missing (an incident), or None."""
    codes = sorted({r.reason for r in snap.readings().values()
                    if r.missing and r.reason and r.reason.startswith("Modbus exception")})
    if codes:
        return "heat pump answers " + ", ".join(codes)
    for name in ("t_air_c", "t_out_c", "q_hc_w"):
        reading = getattr(snap, name)
        if reading.missing:
            return f"{name} missing ({reading.reason})"
    return None


def _error_bits(snap: Snapshot) -> int | None:
    """errors_1 | errors_2 << 16 (None when neither could be read)."""
    e1, e2 = snap.errors_1.value, snap.errors_2.value
    if e1 is None and e2 is None:
        return None
    return int(e1 or 0) | (int(e2 or 0) << 16)


def alarm_reason(snap: Snapshot) -> str | None:
    """Why the heat pump is not fit to run an experiment now, or None."""
    if snap.error_summary.value == 2:
        return "heat pump reports an error (2006 = 2)"
    bits = _error_bits(snap)
    if bits:
        return f"heat pump error bits set (2114/2115 = {bits:#x})"
    if snap.error_active.value:
        return "heat pump error display active (2113)"
    return None


def unfit(snap: Snapshot, policy: NightPolicy) -> str | None:
    """Why the heat pump or the weather is not fit to start a night now, or None."""
    alarm = alarm_reason(snap)
    if alarm:
        return alarm
    if snap.working_function.value == _REMOTE_OFF_FUNCTION:
        return "heat pump is remote-off (working function 7)"
    if snap.system_on.value == 0:
        return "heating system switched off by the owner (2012 = 0)"
    if snap.loop1_mode.value == 0:
        return "loop 1 switched off by the owner (2042 = 0)"
    if snap.defrost.value:
        return "defrost running"
    if snap.t_air_c.missing:
        return f"no indoor temperature: {snap.t_air_c.reason}"
    if snap.t_out_c.missing:
        return f"no outdoor temperature: {snap.t_out_c.reason}"
    t_out = snap.t_out_c.value
    if not policy.t_out_min_c <= t_out <= policy.t_out_max_c:
        return (f"outdoor {t_out:.1f} °C outside the band {policy.t_out_min_c:g}…"
                f"{policy.t_out_max_c:g} °C")
    return None


def status_line(night_id: int, req: NightRequest, snap: Snapshot | None) -> str:
    """One line of progress for systemd STATUS= and the CLI (°C, W)."""
    if snap is None:
        return f"night {night_id} ({req.kind}): link lost"
    t_air = snap.t_air_c.value
    q = snap.q_hc_w.value
    return (f"night {night_id} ({req.kind} {req.setpoint_c:g} °C) "
            f"{snap.timestamp:%Y-%m-%d %H:%M}Z T_air "
            f"{'—' if t_air is None else f'{t_air:.1f}'} °C, Q_HC "
            f"{'—' if q is None else f'{q:.0f}'} W")
