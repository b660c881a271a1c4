"""An adaptive campaign run by the real daemon against the simulator, end to end (issue 18).

In-process :class:`~impctl.daemon.service.Daemon` on the accelerated clock (on the
virtual-time loop, see test_daemon_campaign), the in-process simulator on loopback Modbus TCP
(the heavy house, 0 °C outdoors), a real SQLite file, and the fit after every valid night in
real subprocesses (``impctl export`` → ``impctl fit`` → ``impctl campaign next``; not niced
here, see :func:`test_daemon_campaign.unniced_fits`). A loose target keeps it short: the
campaign must stop by itself — at the target, or at ``max_nights`` — never run two
constrained nights in a row, store each fit with its night count and predictions, run nothing
after the stop, and leave the heat pump as the owner had it.
"""

from __future__ import annotations

import asyncio
from datetime import datetime

from daemon_fixtures import OWNER_MODE, OWNER_SETPOINT_C
from reliability_fixtures import run_virtual
from test_daemon_campaign import FINAL, FITS_TIMEOUT_S, TZ, _campaign, unniced_fits

from impctl.campaign import FitSummary, parse_candidates
from impctl.cli.device.status import collect_status, format_status
from impctl.daemon.nights.schedule import next_act_time
from impctl.store import Store

#: A day of simulated time in 4 s of the virtual-time loop (the nights take no real time, and
#: miss no sample however loaded the machine). A fit (three subprocesses) takes ~10–15 s of
#: real time and no simulated time: the loop's clock waits for the subprocesses.
SPEED = 21600.0
TARGET = {"hlc": 0.30, "tau": 0.40}
MAX_NIGHTS = 3


def _stopped(db) -> bool:
    """A stop decided, and the fit of every valid night stored (the aggregator's result)."""
    if not db.exists():
        return False
    with Store(db) as store:
        decisions, fits = store.decisions(1), store.fits()
        return (bool(decisions) and decisions[0].action == "stop" and bool(fits)
                and fits[-1].night_count == len(store.nights(valid=True)))


async def _after_the_stop(cfg, clock) -> int:
    """The nights at the stop, after the next act time has passed (nothing may run then)."""
    with Store(cfg.db_path) as store:
        at_stop = len(store.nights())
    after = next_act_time(cfg, clock.now())
    while clock.now() < after:
        await asyncio.sleep(0.1)
    await asyncio.sleep(1.0)
    return at_stop


async def _adaptive_campaign(tmp_path):
    result = await _campaign(
        tmp_path, datetime(2026, 1, 12, 19, 0, tzinfo=TZ), SPEED,
        {"mode": "adaptive", "target_rel_halfwidth": TARGET, "max_nights": MAX_NIGHTS,
         "constrained_setpoint_c": 21.0, "normal_setpoints_c": [21.0, 22.0]},
        until=_stopped, timeout_s=FITS_TIMEOUT_S, night={"sample_interval_s": 600},
        after=_after_the_stop)
    return result["cfg"], result["watch"], result["plant"], result["after"]


def test_adaptive_campaign_stops_by_itself_and_restores(tmp_path, monkeypatch):
    unniced_fits(monkeypatch)
    cfg, watch, plant, at_stop = run_virtual(_adaptive_campaign(tmp_path))
    with Store(cfg.db_path) as store:
        nights = store.nights()
        fits = store.fits()
        decisions = store.decisions(10 ** 6)[::-1]
        pending = store.journal_pending()
        events = [m for _, _, m in store.events(50)]
        assert store.integrity_check() == "ok"
    # Every night ran to its end, valid (the heavy house at 0 °C), and was restored.
    assert nights and all(n.state in FINAL and n.valid for n in nights), [
        (n.id, n.state, n.reasons) for n in nights]
    kinds = [n.kind for n in nights]
    assert kinds[0] == "constrained" and "normal" in kinds
    assert ("constrained", "constrained") not in set(zip(kinds, kinds[1:], strict=False))
    assert len(nights) <= MAX_NIGHTS and len(nights) == at_stop  # none after the stop
    # One decision per act time: a run for every night (in order), no skip (each fit was
    # stored before the next act time: the clock waited for it), and one stop — the last
    # decision, recorded once.
    runs = [d for d in decisions if d.action == "run"]
    assert [(d.kind, d.setpoint_c) for d in runs] == [(n.kind, n.setpoint_c) for n in nights]
    assert [d.action for d in decisions] == ["run"] * len(runs) + ["stop"], [
        (d.action, d.reason) for d in decisions]
    stops = [d for d in decisions if d.action == "stop"]
    assert len(stops) == 1 and decisions[-1] is stops[-1]
    stop = stops[0]
    assert stop.forecast_source.startswith("mean T_out of night ")
    assert abs(stop.forecast_t_out_c - 0.0) < 1.0  # the simulator's constant 0 °C
    # A fit after each valid night from the first pair of kinds on, with its night count; the
    # stop follows from the last one.
    assert fits and fits[-1].night_count == len(nights)
    assert [f.night_count for f in fits] == sorted({f.night_count for f in fits})
    last = FitSummary.from_fit_json(fits[-1].result, fits[-1].night_count)
    if stop.reached:
        assert last.hlc_rel <= TARGET["hlc"] and last.tau_rel <= TARGET["tau"], last
        assert f"after {len(nights)} nights" in stop.reason
    elif len(nights) < MAX_NIGHTS:  # the other stops say why, in the household's words
        assert ("precision limited" in stop.reason or "would not help" in stop.reason
                or "cannot be identified" in stop.reason), stop.reason
    # Predictions of `impctl campaign next` stored with the fits, for both kinds.
    cands = parse_candidates(fits[-1].candidates)
    assert {c.kind for c in cands} == {"constrained", "normal"}
    assert fits[-1].candidates["forecast_source"].startswith("mean T_out of night ")
    assert any(e.startswith("campaign stop: ") for e in events)
    # The heat pump showed only the owner's state between and after the nights.
    assert watch.idle_states
    assert {(sp, mode) for _, sp, mode in watch.idle_states} == {(OWNER_SETPOINT_C, OWNER_MODE)}
    assert plant == (OWNER_SETPOINT_C, OWNER_MODE) and pending == []
    # `impctl status` tells the story: the mode, the nights, how the intervals shrank, why.
    st = collect_status(cfg)
    camp = st["campaign"]
    assert (camp["mode"], camp["nights_run"], camp["nights_valid"]) == (
        "adaptive", len(nights), len(nights))
    assert [f["valid_nights"] for f in camp["intervals"]] == [f.night_count for f in fits]
    assert camp["last_decision"]["action"] == "stop"
    text = format_status(st, "Europe/Ljubljana")
    assert f"after {fits[-1].night_count} valid nights: HLC" in text
    assert "decision:  stop" in text and stop.reason in text
    assert st["next_night"]["kind"] is None and st["next_night"]["why_none"] == stop.reason
