"""``[record]`` in ``impctl status``: whether the daemon records the house now, the owner records
kept (how many, from which day to which, how many labelled and why) and the store's size."""

from __future__ import annotations

from datetime import datetime
from zoneinfo import ZoneInfo


def record_status(cfg, store, info) -> dict:
    """The recording for ``impctl status --json``; ``info`` is the daemon lock's probe."""
    summary = store.owner_summary()
    zone = ZoneInfo(cfg.timezone)
    alive = info.running and not info.stale
    note = (info.notes.get("record") or {}) if alive else {}
    if not cfg.record.enabled:
        state, why = "off", "record.enabled = false"
    elif not alive:
        state, why = "not running", "the daemon is not running"
    else:
        state, why = note.get("state", "starting"), note.get("why")
    return {
        "enabled": cfg.record.enabled, "state": state, "why": why,
        "interval_s": cfg.record.interval_s,
        "sample_interval_s": cfg.record.snapshot_interval_s(cfg.night),
        "keep_days": cfg.record.keep_days,
        "records": summary.count, "open": summary.recording,
        "first_day": _day(summary.first, zone), "last_day": _day(summary.last, zone),
        "first": summary.first, "last": summary.last,
        "labelled": summary.labelled, "rows": summary.rows, "last_row": summary.last_row,
        "store_bytes": store.size_bytes(),
    }


def _day(ts: datetime | None, zone: ZoneInfo) -> str | None:
    """The local day a record's window starts on (None without one)."""
    return None if ts is None else f"{ts.astimezone(zone):%Y-%m-%d}"


def record_lines(st: dict | None, zone: ZoneInfo) -> list[str]:
    """Status lines of the recording and the store's size."""
    if st is None:
        return []
    every = (f"a snapshot every {st['sample_interval_s']:g} s, rows of "
             f"{st['interval_s']:g} s")
    if st["state"] == "recording":
        head = f"recording: on ({every})"
    elif st["state"] == "paused":
        head = f"recording: paused: {st['why']}"
    elif st["state"] == "failed":
        head = f"recording: FAILING: {st['why']} (the daemon retries)"
    elif st["state"] == "off":
        head = "recording: off (record.enabled = false)"
    else:
        head = f"recording: not now ({st['why'] or st['state']})"
    lines = [head]
    if st["records"]:
        labelled = sum(st["labelled"].values())
        why = ", ".join(f"{k} {n}" for k, n in st["labelled"].items())
        last = ("" if st["last_row"] is None else
                f"; last row {st['last_row'].astimezone(zone):%Y-%m-%d %H:%M}")
        lines.append(f"owner:     {st['records']} records kept ({st['first_day']} … "
                     f"{st['last_day']}, {st['open']} open), {labelled} labelled"
                     + (f" ({why})" if why else "") + last
                     + f"; kept {st['keep_days']} days")
    else:
        lines.append("owner:     no owner record yet")
    lines.append(f"store:     {st['store_bytes'] / 1e6:.1f} MB")
    return lines
