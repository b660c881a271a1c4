"""``impctl status``: what the daemon is doing, read from the store (no IPC needed)."""

from __future__ import annotations

from zoneinfo import ZoneInfo


def collect_status(cfg) -> dict:
    """Current night with its latest sample, campaign, last fit, link events, write counters."""
    from ..heatpump import WriteBudget
    from ..heatpump.health import read_health
    from ..store import Store

    out: dict = {"state_dir": cfg.state_dir}
    with Store(cfg.db_path, create=False) as store:
        running = store.nights(states=["preparing", "active", "restoring"])
        if running:
            night = running[-1]
            samples = store.samples(night.id)
            last = samples[-1] if samples else None
            out["current_night"] = {
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
                                        "valid": v} for s, k, sp, n, v in plan]}
        fit = store.last_fit()
        out["last_fit"] = None if fit is None else {
            "created": fit[0], "nights": fit[1],
            "lumped": fit[2].get("lumped") if isinstance(fit[2], dict) else None}
        out["events"] = [{"ts": t, "level": lvl, "message": m} for t, lvl, m in store.events(8)]
        out["pending_restore"] = [e.register for e in store.journal_pending()]
        out["pending_requests"] = len(store.pending_requests())
    out["heatpump"] = read_health(cfg.state_dir)  # issue 15: generation evidence, quirks
    if cfg.budget_path.exists():
        from ..daemon.service import clock_from_config

        # The budget counts per UTC day of the clock the daemon runs on (the accelerated
        # clock of a demo or test, else real time).
        day = clock_from_config(cfg).now().date()
        with WriteBudget(cfg.budget_path, cfg.heatpump.writes.daily_budget) as budget:
            out["writes_today"] = {str(ma): f"{budget.used(ma, day)}/{budget.limit(ma)}"
                                   for ma in (2187, 2042)}
    else:
        out["writes_today"] = {}
    return out


def format_status(st: dict, tz: str = "UTC") -> str:
    """The status as a few readable lines."""
    zone = ZoneInfo(tz)
    lines = []
    cur = st["current_night"]
    if cur is None:
        lines.append("night:     none running")
    else:
        s = cur["last_sample"] or {}
        lines.append(f"night:     {cur['id']} {cur['kind']} T_set {cur['setpoint_c']:g} °C, "
                     f"{cur['state']}, {cur['samples']} samples")
        if s:
            def fmt(v, unit, spec=".1f"):
                return "—" if v is None else f"{v:{spec}} {unit}"
            lines.append(f"live:      {s['ts'].astimezone(zone):%Y-%m-%d %H:%M %Z} "
                         f"T_air {fmt(s['t_air_c'], '°C')}, T_out {fmt(s['t_out_c'], '°C')}, "
                         f"Q_HC {fmt(s['q_hc_w'], 'W', '.0f')}, "
                         f"P_el {fmt(s['p_el_w'], 'W', '.0f')}")
    camp = st["campaign"]
    lines.append(f"campaign:  {camp['valid']}/{camp['planned']} valid nights")
    fit = st["last_fit"]
    if fit is None:
        lines.append("last fit:  none")
    else:
        hlc = ((fit.get("lumped") or {}).get("hlc") or {}).get("value")
        lines.append(f"last fit:  {fit['created']:%Y-%m-%d %H:%M} UTC, nights {fit['nights']}"
                     + ("" if hlc is None else f", HLC {hlc:.1f} W/K"))
    link = next((e for e in st["events"] if "link" in e["message"]), None)
    lines.append("link:      " + ("no incident recorded" if link is None else
                                  f"{link['message']} ({link['ts']:%Y-%m-%d %H:%M} UTC)"))
    if st["pending_restore"]:
        lines.append("RESTORE PENDING: " + ", ".join(st["pending_restore"]))
    writes = ", ".join(f"{ma}: {v}" for ma, v in st["writes_today"].items()) or "none"
    lines.append(f"writes:    today {writes}")
    from ..heatpump.health import health_lines

    lines.extend(health_lines(st.get("heatpump")))  # issue 15
    return "\n".join(lines)
