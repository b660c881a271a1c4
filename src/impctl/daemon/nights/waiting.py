"""What waits for the daemon: manual night requests and a household's skip, queued once,
shown by ``impctl status`` and cancelled by ``impctl trigger --cancel``.

The CLI and the MQTT commands go through these functions, so a button pressed a hundred
times queues one request, and whatever is queued can be seen and taken back.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from ...store import Command, Store, TriggerRequest

#: A skip request older than this is stale (it was for a night that has passed) [h].
SKIP_VALID_H = 24.0


def queue_night(store: Store, kind: str, setpoint_c: float, when: str,
                expires: datetime, forced: bool = False) -> tuple[int, bool]:
    """Queue a manual night, or keep the identical one already waiting: (id, joined).
    ``forced``: a ``now`` night that may run in daytime (``--force``)."""
    return store.queue_request(kind, setpoint_c, when, expires=expires, forced=forced)


def describe_queued(rid: int, joined: bool, kind: str, setpoint_c: float, when: str) -> str:
    """One line on what :func:`queue_night` did."""
    what = f"{kind} night at {setpoint_c:g} °C ({when})"
    if joined:
        return f"request {rid} already waiting: {what}; not queued again"
    return f"queued request {rid}: {what}"


def queue_skip(store: Store, source: str, now: datetime | None = None) -> tuple[int, bool]:
    """Queue a skip of the next night, or keep a skip already waiting: (id, joined)."""
    now = now or datetime.now(UTC)  # commands are stamped in real time
    return store.queue_command("skip_tonight", source,
                               join_since=now - timedelta(hours=SKIP_VALID_H))


def waiting_skips(store: Store, now: datetime | None = None) -> list[Command]:
    """The skip requests the next night job will honour (not taken, not stale)."""
    now = now or datetime.now(UTC)
    return [c for c in store.pending_commands("skip_tonight")
            if now - c.created <= timedelta(hours=SKIP_VALID_H)]


def cancel_waiting(store: Store) -> tuple[list[TriggerRequest], list[Command]]:
    """Cancel every waiting manual request and skip; returns what was cancelled (one event
    each)."""
    requests = [r for r in store.pending_requests() if store.close_request(r.id, "cancelled")]
    for r in requests:
        store.add_event("info", f"request {r.id} cancelled")
    skips = [c for c in store.pending_commands("skip_tonight") if store.take_command(c.id)]
    for c in skips:
        store.add_event("info", f"skip_tonight {c.id} ({c.source}) cancelled")
    return requests, skips
