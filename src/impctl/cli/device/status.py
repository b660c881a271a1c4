"""``impctl status``: what the daemon is doing, read from the store (no IPC needed)."""

from __future__ import annotations

import math
from pathlib import Path
from zoneinfo import ZoneInfo

from ...errors import InputError


def _copy_hint(exc: InputError, cfg) -> InputError:
    """The store's error, plus what its copy outside it says is still to restore."""
    from ...store.restore.owner_file import OWNER_FILE, read_owner_values

    copy = Path(cfg.state_dir) / OWNER_FILE
    try:
        entries, _ = read_owner_values(copy)
    except (FileNotFoundError, InputError):
        return exc
    if not entries:
        return exc
    return InputError(f"{exc.problem}; the heat pump may still be in an experiment's state: "
                      f"{copy} lists {', '.join(e.register for e in entries)} to restore "
                      "(run impctl restore)", exc.source, exc.place)


def collect_status(cfg) -> dict:
    """Daemon liveness, current night with its latest sample, the next night, campaign, last
    fit, link events, write counters."""
    from ...daemon.locks.store import probe
    from ...heatpump import WriteBudget
    from ...heatpump.health import read_health
    from ...store import Store

    info = probe(cfg.state_dir)
    out: dict = {"state_dir": cfg.state_dir, "daemon": {
        "running": info.running, "responding": info.running and not info.stale,
        "pid": info.pid, "role": info.role,
        "heartbeat_age_s": None if info.heartbeat_age_s is None else round(
            info.heartbeat_age_s, 1),
        "summary": info.describe()}}
    # The broker link as the running daemon last noted it (written on change only).
    out["mqtt"] = None if cfg.mqtt is None else {
        "configured": True, **((info.notes.get("mqtt") or {}) if info.running else {})}
    try:
        store = Store(cfg.db_path, create=False)
    except InputError as exc:
        raise _copy_hint(exc, cfg) from None
    with store:
        running = store.nights(states=["preparing", "active", "restoring"])
        if running:
            night = running[-1]
            samples = store.samples(night.id)
            last = samples[-1] if samples else None
            out["current_night"] = {
                # Without a live daemon the row is what a dead process left: nobody runs it.
                "supervised": info.running and not info.stale,
                "id": night.id, "kind": night.kind, "state": night.state,
                "setpoint_c": night.setpoint_c, "t_min_c": night.t_min_c,
                "window_start": night.window_start, "window_end": night.window_end,
                "samples": len(samples),
                "last_sample": None if last is None else {
                    "ts": last.ts, "t_air_c": last.t_air_c, "t_out_c": last.t_out_c,
                    "q_hc_w": last.q_hc_w, "p_el_w": last.p_el_w, "defrost": last.defrost},
            }
        else:
            out["current_night"] = None
        plan = store.campaign()
        out["campaign"] = {"valid": sum(1 for *_, v in plan if v), "planned": len(plan),
                           "entries": [{"seq": s, "kind": k, "setpoint_c": sp, "night": n,
                                        "valid": v} for s, k, sp, n, v in plan],
                           **_campaign(store, cfg)}
        fit = store.last_fit()
        out["last_fit"] = None if fit is None else {
            "created": fit[0], "nights": fit[1],
            "lumped": fit[2].get("lumped") if isinstance(fit[2], dict) else None}
        out["events"] = [{"ts": t, "level": lvl, "message": m} for t, lvl, m in store.events(8)]
        out["pending_restore"] = [e.register for e in store.journal_pending()]
        # impctl's heating curve, set on the owner's word and watched by a live daemon: held,
        # not waiting to be restored (without a live daemon it is unsupervised like the rest)
        from ...daemon.curve.watch import KEEP

        alive = info.running and not info.stale
        held = [r for r in out["pending_restore"] if r in KEEP] if alive else []
        out["curve_held"] = held
        out["restore"] = _restore_state([r for r in out["pending_restore"] if r not in held],
                                        out["current_night"], info)
        out["pending_requests"] = len(store.pending_requests())
        out["skip_tonight"] = _skips(store)
        out["next_night"] = _next_night(store, cfg)
        if out["next_night"] is not None:  # the night job honours a waiting skip first
            out["next_night"]["skipped_by"] = (out["skip_tonight"][0]["id"]
                                               if out["skip_tonight"] else None)
        from .inputs_status import inputs_status

        out["inputs"] = inputs_status(cfg, store)  # [inputs]: the house's own sensors
        from .record_status import record_status

        out["record"] = record_status(cfg, store, info)  # [record]: the owner recording
    out["heatpump"] = read_health(cfg.state_dir)  # generation evidence, quirks
    if cfg.budget_path.exists():
        from ...daemon.configured import clock_from_config

        # The budget counts per UTC day of the clock the daemon runs on (the accelerated
        # clock of a demo or test, else real time).
        day = clock_from_config(cfg).now().date()
        with WriteBudget(cfg.budget_path, cfg.heatpump.writes.daily_budget) as budget:
            out["writes_today"] = {str(ma): {"used": budget.used(ma, day),
                                             "limit": budget.limit(ma)}
                                   for ma in (2187, 2042)}
    else:
        out["writes_today"] = {}
    return out


def _restore_state(pending: list[str], night: dict | None, info) -> dict | None:
    """Who puts the owner's settings back: ``state`` is "night" (a supervised night will
    restore them at its end), "daemon" (no night runs; the live daemon retries the restore)
    or "unsupervised" (no live process holds the lock: nothing will, until one starts)."""
    if not pending:
        return None
    alive = info.running and not info.stale
    state = ("unsupervised" if not alive else "night" if night is not None else "daemon")
    return {"registers": pending, "state": state, "pid": info.pid if alive else None,
            "role": info.role if alive else None}


def _skips(store) -> list[dict]:
    """The household's waiting skips of the next night (what the night job will honour)."""
    from ...daemon.nights.waiting import waiting_skips

    return [{"id": c.id, "source": c.source, "created": c.created}
            for c in waiting_skips(store)]


def _restore_lines(rs: dict | None) -> list[str]:
    if rs is None:
        return []
    regs = ", ".join(rs["registers"])
    who = f"{rs['role'] or 'daemon'} PID {rs['pid']}"
    if rs["state"] == "night":
        return [f"restore:   night in progress, supervised by {who}; the heat pump will be "
                f"restored at its end ({regs})"]
    if rs["state"] == "daemon":
        return [f"restore:   pending ({regs}); {who} restores them as soon as the heat pump "
                "answers"]
    return [f"RESTORE PENDING: {regs}: nothing supervises the heat pump; start the daemon "
            "(it restores first) or run impctl restore"]


def _campaign(store, cfg) -> dict:
    """Mode, nights run / valid, how the intervals shrank fit after fit, the last decision."""
    from ...daemon.nights.adaptive import absurd, campaign_state, decide_now, fit_history, rel_pct

    st = campaign_state(store, cfg)
    camp = cfg.campaign
    history = [{"valid_nights": f.nights, "hlc_w_per_k": _finite(f.hlc_w_per_k),
                "hlc_rel_pct": rel_pct(f.hlc_rel), "tau_h": _finite(f.tau_h),
                "tau_rel_pct": rel_pct(f.tau_rel),
                "interval_note": (None if not f.too_few_nights else "too few nights yet"
                                  if absurd(f) else "too few nights yet: model-based")}
               for f in fit_history(store)]
    out = {"mode": st.mode, "nights_run": st.nights_run, "nights_valid": st.nights_valid,
           "status": st.status, "reason": st.reason, "intervals": history,
           "target_rel_pct": {"hlc": 100 * camp.target_rel_halfwidth.hlc,
                              "tau": 100 * camp.target_rel_halfwidth.tau},
           "max_nights": camp.max_nights if st.mode == "adaptive" else None,
           "last_decision": None,
           "decisions": [{"act": d.act, "action": d.action, "kind": d.kind,
                          "setpoint_c": d.setpoint_c, "reason": d.reason}
                         for d in reversed(store.decisions(50))]}
    d = st.decision
    if d is not None:
        out["last_decision"] = {"act": d.act, "action": d.action, "kind": d.kind,
                                "setpoint_c": d.setpoint_c, "reason": d.reason,
                                "reached": d.reached, "forecast_t_out_c": d.forecast_t_out_c,
                                "forecast_source": d.forecast_source}
    if st.mode == "adaptive" and camp.enabled:
        decision, fc = decide_now(store, cfg)  # what the next act would decide, as of now
        out["next_decision"] = {"action": decision.action, "reason": decision.reason,
                                "forecast_t_out_c": fc.t_out_c, "forecast_source": fc.source}
    return out


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None  # JSON has no NaN: a missing value is null


def _next_night(store, cfg) -> dict | None:
    """What the daemon would run at its next night (without taking any request)."""
    from ...daemon.configured import clock_from_config
    from ...daemon.nights.next_night import peek_next_night, why_no_night
    from ...daemon.nights.schedule import next_act_time, retry_waits

    act = next_act_time(cfg, clock_from_config(cfg).now())
    req, request_id = peek_next_night(store, cfg, act)
    if req is None:
        return {"preheat_start": act, "kind": None, "why_none": why_no_night(store, cfg)}
    return {"preheat_start": act, "kind": req.kind, "setpoint_c": req.setpoint_c,
            "t_min_c": req.t_min_c, "t_max_c": req.t_max_c, "window_start": req.window_start,
            "window_end": req.window_end, "source": req.source, "request": request_id,
            "campaign_seq": req.campaign_seq,
            "retry_waits": req.source == "schedule" and retry_waits(store)}


def _value(v: float | None, unit: str, spec: str = ".1f") -> str:
    """A reading with its unit, or "—" when missing."""
    return "—" if v is None else f"{v:{spec}} {unit}"


def _campaign_lines(camp: dict, zone: ZoneInfo) -> list[str]:
    tgt = camp["target_rel_pct"]
    if camp["mode"] == "adaptive":
        head = (f"campaign:  adaptive (target HLC ±{tgt['hlc']:g} %, τ ±{tgt['tau']:g} %, at "
                f"most {camp['max_nights']} nights): {camp['nights_run']} nights run, "
                f"{camp['nights_valid']} valid; {camp['status']}")
    else:
        head = (f"campaign:  fixed plan, {camp['valid']}/{camp['planned']} valid nights "
                f"({camp['nights_run']} run)")
    lines = [head]
    for f in camp["intervals"]:
        def pct(v):
            return "undetermined" if v is None else f"±{v:.1f} %"
        if f.get("interval_note") == "too few nights yet":
            lines.append(f"  after {f['valid_nights']} valid nights: "
                         f"HLC {_value(f['hlc_w_per_k'], 'W/K', '.0f')}, "
                         f"τ {_value(f['tau_h'], 'h', '.0f')}; interval: {f['interval_note']}")
            continue
        lines.append(f"  after {f['valid_nights']} valid nights: "
                     f"HLC {_value(f['hlc_w_per_k'], 'W/K', '.0f')} "
                     f"{pct(f['hlc_rel_pct'])}, τ {_value(f['tau_h'], 'h', '.0f')} "
                     f"{pct(f['tau_rel_pct'])} (target ±{tgt['hlc']:g} % / ±{tgt['tau']:g} %)"
                     + (f"; interval: {f['interval_note']}" if f.get("interval_note") else ""))
    d = camp.get("last_decision")
    if d is not None:
        when = "" if d["act"] is None else f" ({d['act'].astimezone(zone):%Y-%m-%d %H:%M})"
        lines.append(f"decision:  {d['action']}{when}: {d['reason']}")
    nxt = camp.get("next_decision")
    if nxt is not None and nxt["action"] == "run" and (d is None or nxt["reason"] != d["reason"]):
        lines.append(f"choice:    {nxt['reason']}")
    if nxt is not None:
        fc = nxt["forecast_t_out_c"]
        lines.append("forecast:  " + ("no outdoor reading yet" if fc is None else
                                      f"T_out {fc:.1f} °C ({nxt['forecast_source']})"))
    return lines


def _mqtt_lines(mq: dict | None, zone: ZoneInfo) -> list[str]:
    """One line on the Home Assistant link (nothing when ``[mqtt]`` is not configured)."""
    if mq is None:
        return []
    if "connected" not in mq:
        return ["mqtt:      configured; no link state (the daemon is not running or just "
                "started)"]
    from datetime import datetime

    since = datetime.fromisoformat(mq["since"]).astimezone(zone)
    if mq["connected"]:
        return [f"mqtt:      connected to {mq['broker']} since {since:%Y-%m-%d %H:%M %Z}"]
    why = f": {mq['error']}" if mq.get("error") else ""
    return [f"mqtt:      broker {mq['broker']} UNAVAILABLE since {since:%Y-%m-%d %H:%M %Z}"
            f"{why} (nights run on; Home Assistant shows impctl unavailable)"]


def format_status(st: dict, tz: str = "UTC") -> str:
    """The status as a few readable lines."""
    zone = ZoneInfo(tz)
    lines = [f"daemon:    {st['daemon']['summary']}"]
    cur = st["current_night"]
    if cur is None:
        lines.append("night:     none running")
    else:
        s = cur["last_sample"] or {}
        lines.append(f"night:     {cur['id']} {cur['kind']} T_set {cur['setpoint_c']:g} °C, "
                     f"{cur['state']}, {cur['samples']} samples")
        if not cur["supervised"]:
            lines.append(f"WARNING:   night {cur['id']} is NOT supervised: the process running "
                         "it is gone; the values below are its last ones. Start the daemon "
                         "(it restores first) or run impctl restore")
        if s:
            lines.append(f"live:      {s['ts'].astimezone(zone):%Y-%m-%d %H:%M %Z} "
                         f"T_air {_value(s['t_air_c'], '°C')}, "
                         f"T_out {_value(s['t_out_c'], '°C')}, "
                         f"Q_HC {_value(s['q_hc_w'], 'W', '.0f')}, "
                         f"P_el {_value(s['p_el_w'], 'W', '.0f')}")
    nxt = st.get("next_night")
    if nxt is not None:
        act = nxt["preheat_start"].astimezone(zone)
        if nxt["kind"] is None:
            lines.append(f"next:      nothing at the next night ({act:%Y-%m-%d}): "
                         f"{nxt['why_none']}")
        else:
            what = (f"T_max {nxt['t_max_c']:g} → T_min {nxt['t_min_c']:g} °C"
                    if nxt["kind"] == "constrained" else f"held at {nxt['setpoint_c']:g} °C")
            origin = (f"manual request {nxt['request']}" if nxt["request"] is not None
                      else "campaign; the invalid constrained night is retried after a "
                      "normal one" if nxt.get("retry_waits") and nxt["kind"] == "normal"
                      else "campaign")
            skipped = "skipped on request: " if nxt.get("skipped_by") is not None else ""
            lines.append(f"next:      {skipped}{nxt['kind']} night ({what}, {origin}), window "
                         f"{nxt['window_start'].astimezone(zone):%Y-%m-%d %H:%M}–"
                         f"{nxt['window_end'].astimezone(zone):%H:%M %Z}, preheat from "
                         f"{act:%H:%M}")
    if st.get("pending_requests"):
        lines.append(f"requests:  {st['pending_requests']} waiting")
    for skip in st.get("skip_tonight") or []:
        lines.append(f"skip:      the next night is skipped on request (skip {skip['id']} from "
                     f"{skip['source']}, {skip['created'].astimezone(zone):%Y-%m-%d %H:%M}); "
                     "impctl trigger --cancel takes it back")
    lines.extend(_campaign_lines(st["campaign"], zone))
    fit = st["last_fit"]
    if fit is None:
        lines.append("last fit:  none")
    else:
        hlc = ((fit.get("lumped") or {}).get("hlc") or {}).get("value")
        lines.append(f"last fit:  {fit['created']:%Y-%m-%d %H:%M} UTC, nights {fit['nights']}"
                     + ("" if hlc is None else f", HLC {hlc:.1f} W/K"))
    lines.extend(_mqtt_lines(st.get("mqtt"), zone))
    from .inputs_status import inputs_lines

    lines.extend(inputs_lines(st.get("inputs"), zone))
    from .record_status import record_lines

    lines.extend(record_lines(st.get("record"), zone))
    link = next((e for e in st["events"] if "link" in e["message"]), None)
    lines.append("link:      " + ("no incident recorded" if link is None else
                                  f"{link['message']} ({link['ts']:%Y-%m-%d %H:%M} UTC)"))
    lines.extend(_restore_lines(st.get("restore")))
    if st.get("curve_held"):
        lines.append("curve:     impctl's heating curve is set (the owner's points are "
                     "journaled: impctl curve --restore, a stop or impctl restore gives them "
                     "back)")
    writes = ", ".join(f"{ma}: {v['used']}/{v['limit']}"
                       for ma, v in st["writes_today"].items()) or "none"
    lines.append(f"writes:    today {writes}")
    from ...heatpump.health import health_lines

    lines.extend(health_lines(st.get("heatpump")))
    return "\n".join(lines)
