"""``[inputs]`` in ``impctl status`` and ``impctl check-config``: which of the house's own
sensors are read, what they said last, and the heat pump's outdoor sensor against the
reference."""

from __future__ import annotations

from zoneinfo import ZoneInfo


def describe_inputs(inputs) -> str:
    """One line: which inputs are read (``inputs`` is an :class:`InputsConfig` or None)."""
    if inputs is None:
        return "none (the night gain is assumed; see [inputs])"
    parts = []
    if inputs.house_power_w:
        parts.append("household power" + (
            " minus the heat pump's own (register 2129, extended controllers)"
            if inputs.house_power_includes_heat_pump else ""))
    if inputs.room_temperature_c:
        n = len(inputs.room_temperature_c)
        parts.append(f"{n} room sensor{'s' if n > 1 else ''}")
    if inputs.outdoor_temperature_c:
        parts.append("an outdoor reference")
    if inputs.occupants:
        parts.append("occupants")
    what = ", ".join(parts) or "no topic set"
    return (f"{what}; a value older than {inputs.max_age_s:g} s "
            f"(occupants {inputs.occupants_max_age_s:g} s) counts as missing")


def inputs_status(cfg, store) -> dict | None:
    """The inputs for ``impctl status --json``: the newest stored row and the outdoor check."""
    if cfg.inputs is None:
        return None
    row = store.latest_house_inputs()
    offset = store.outdoor_offset() if cfg.inputs.outdoor_temperature_c else None
    return {
        "configured": describe_inputs(cfg.inputs),
        "latest": None if row is None else {
            "ts": row.ts, "night": row.night_id, "p_house_w": row.p_house_w,
            "house_power_w": row.house_power_w, "t_rooms_c": row.t_rooms_c,
            "t_out_ref_c": row.t_out_ref_c, "occupants": row.occupants},
        "t_out_offset": None if offset is None else {
            "offset_k": round(offset.offset_k, 2), "pairs": offset.pairs,
            "span_h": round(offset.span_h, 2), "persistent": offset.persistent,
            "text": offset.describe()},
    }


def _v(v: float | None, unit: str, spec: str = ".1f") -> str:
    return "—" if v is None else f"{v:{spec}} {unit}"


def inputs_lines(st: dict | None, zone: ZoneInfo) -> list[str]:
    """Status lines (nothing when ``[inputs]`` is not configured)."""
    if st is None:
        return []
    lines = [f"inputs:    {st['configured']}"]
    last = st["latest"]
    if last is not None:
        lines.append(f"           last {last['ts'].astimezone(zone):%Y-%m-%d %H:%M %Z}: "
                     f"house {_v(last['p_house_w'], 'W', '.0f')}, "
                     f"rooms {_v(last['t_rooms_c'], '°C')}, "
                     f"outdoor ref {_v(last['t_out_ref_c'], '°C')}, "
                     f"occupants {_v(last['occupants'], '', '.0f').strip()}")
    off = st["t_out_offset"]
    if off is not None:
        lines.append(("WARNING:   " if off["persistent"] else "outdoor:   ") + off["text"])
    return lines
