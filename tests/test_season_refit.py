"""The season model alone and its morning refit: ``impctl season`` as a real subprocess, the
daemon's refit (:func:`impctl.daemon.fitting.refresh_season`) on a real SQLite store whose owner
records hold a simulated winter of a realistic household (the first of the run's shared winter,
``winter_season`` in conftest.py: its owner nights, one of them labelled).

What is promised: a search started where the last fit ended finds what the full search finds
(the same house, one night more); its result replaces the newest fit's season block and nothing
else of it; a full fit stored meanwhile wins; a start that is not a season result is one line,
exit status 2, nothing written.
"""

from __future__ import annotations

import asyncio
import json
from datetime import datetime, timedelta
from zoneinfo import ZoneInfo

import pytest
from test_nights_owner import run_cli
from test_season_emitter import without_fade

from impctl.config import load_config
from impctl.daemon.fitting import refresh_season
from impctl.imp.files.nights_csv import read_nights, write_nights
from impctl.population.season_run.nights import household_nights
from impctl.season.fit import fit_nights
from impctl.store import Store
from impctl.store.records import Sample

TZ = "Europe/Ljubljana"
KEYS = ("hlc_w_per_k", "tau_h", "c_m_j_per_k")


@pytest.fixture(scope="module")
def owner_nights(winter_season):
    nights = [n for n in household_nights(winter_season, 0) if n.kind == "owner"]
    assert sum(not n.label for n in nights) >= 8
    return nights


def _store_records(store: Store, nights) -> None:
    """Each owner night as the recorder would have stored and closed it."""
    for n in nights:
        start = n.start.to_pydatetime()
        rid = store.open_owner_record(start, start + timedelta(days=1))
        for i, t in enumerate(n.time_s):
            dhw = 0.0 if n.dhw is None else float(n.dhw[i])
            store.add_owner_row(Sample(
                night_id=rid, ts=start + timedelta(seconds=float(t)),
                t_air_c=float(n.t_air_c[i]), t_out_c=float(n.t_out_c[i]),
                q_hc_w=float(n.q_hc_w[i]), setpoint_c=21.0, dhw_share=dhw,
                defrost=bool(n.defrost_share[i] > 0) if n.defrost_share is not None else False,
                snapshots=3))
        end = start + timedelta(seconds=float(n.time_s[-1]) + 300.0)
        store.close_owner_record(rid, [n.label] if n.label else [], 21.0, start, end)


def test_impctl_season_warm_starts_where_the_last_result_ended(tmp_path, owner_nights):
    csv = write_nights(owner_nights, tmp_path / "nights.csv")
    first, warm = tmp_path / "first.json", tmp_path / "warm.json"
    res = run_cli("season", "--nights", str(csv), "--json", str(first),
                  model_dir=tmp_path / "no-models")
    assert res.returncode == 0, res.stderr
    assert "season model:" in res.stdout and "against owner nights" in res.stdout
    a = json.loads(first.read_text())["season"]
    assert set(a["theta"]) == {"tau_mm_s", "w", "tau_e_s", "f_sun", "tau_r_s"}
    assert a["search"]["warm_start"] is False
    res = run_cli("season", "--nights", str(csv), "--warm-start", str(first), "--json",
                  str(warm), "--no-convergence", model_dir=tmp_path / "no-models")
    assert res.returncode == 0, res.stderr
    assert "the search started from" in res.stdout and "against owner nights" not in res.stdout
    b = json.loads(warm.read_text())["season"]
    assert b["search"]["warm_start"] is True and "convergence" not in b
    assert b["hlc_w_per_k"]["value"] == pytest.approx(a["hlc_w_per_k"]["value"], rel=1e-3)
    # owner nights alone: τ and C_m not given, and why (their intervals need the IMP nights)
    for k in ("tau_h", "c_m_j_per_k"):
        assert a[k]["value"] is b[k]["value"] is b[k]["low"] is None
        assert "needs the IMP nights" in b[k]["why_missing"]
    assert "tau          — h      needs the IMP nights" in res.stdout


@pytest.mark.parametrize("content, words", [
    ('{"season": {"hlc_w_per_k": {"value": 150}}}', "season.theta missing"),
    ("not json", "not a readable JSON result"),
])
def test_a_start_that_is_no_season_result_is_one_line_and_exit_2(tmp_path, owner_nights,
                                                                  content, words):
    csv = write_nights(owner_nights[:6], tmp_path / "nights.csv")
    bad = tmp_path / "start.json"
    bad.write_text(content)
    out = tmp_path / "out.json"
    res = run_cli("season", "--nights", str(csv), "--warm-start", str(bad), "--json", str(out),
                  model_dir=tmp_path / "no-models")
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and str(bad) in lines[0] and "--warm-start" in lines[0]
    assert words in lines[0]
    assert not out.exists()


def test_a_start_from_an_earlier_version_of_the_model_is_a_full_search(tmp_path,
                                                                        owner_nights):
    """A fit stored before the model's θ gained a coordinate (the room's lag) is no bad
    input: the morning refit after an update searches afresh and says why."""
    csv = write_nights(owner_nights[:6], tmp_path / "nights.csv")
    old = tmp_path / "old.json"
    old.write_text(json.dumps({"season": {"theta": {
        "tau_mm_s": 90000.0, "w": 0.9, "tau_e_s": 7200.0, "f_sun": 0.05}}}))
    out = tmp_path / "out.json"
    res = run_cli("season", "--nights", str(csv), "--warm-start", str(old), "--json", str(out),
                  "--no-convergence", model_dir=tmp_path / "no-models")
    assert res.returncode == 0, res.stderr
    assert "an earlier version's" in res.stdout and "tau_r_s" in res.stdout
    assert "the search started from" not in res.stdout
    assert json.loads(out.read_text())["season"]["search"]["warm_start"] is False


def test_the_morning_refit_replaces_the_newest_fits_season_and_nothing_else(tmp_path,
                                                                           owner_nights):
    state = tmp_path / "state"
    state.mkdir()
    config = tmp_path / "config.toml"
    config.write_text(f'state_dir = "{state}"\n[heatpump]\nhost = "127.0.0.1"\n')
    cfg = load_config(config)
    earlier, _ = fit_nights(owner_nights[:-1])  # yesterday's fit: one owner night fewer
    with Store(cfg.db_path) as store:
        _store_records(store, owner_nights)
        # a fit without a season model: nothing to start from, nothing run
        store.add_fit([], {"hlc": "imp"})
        assert asyncio.run(refresh_season(store, cfg)) is None
        fit_id = store.add_fit([3, 5], {"hlc": "imp", "season": earlier.as_dict()})
        block = asyncio.run(refresh_season(store, cfg))
        assert block is not None and block["search"]["warm_start"] is True
        newest_id, result = store.newest_fit()
        assert newest_id == fit_id and result["hlc"] == "imp"  # the IMP fit's fields stay
        assert store.last_fit()[1] == [3, 5]
        season = result["season"]
        # what the full search finds on every night, as the refit's export wrote them
        everything, _ = fit_nights(read_nights(state / "fit" / "season_nights.csv", TZ))
        assert season["owner_nights"] == everything.owner_nights == earlier.owner_nights + 1
        assert season["hlc_w_per_k"]["value"] == pytest.approx(
            everything.values["hlc_w_per_k"], rel=5e-3)
        assert any(m.startswith("season model refreshed") for _, _, m in store.events(5))
        # a full fit stored while a refit ran wins: the refit's block is dropped
        newer = store.add_fit([3, 5, 7], {"hlc": "imp2", "season": earlier.as_dict()})
        assert not store.refresh_fit_season(fit_id, block)
        assert store.newest_fit() == (newer, {"hlc": "imp2", "season": earlier.as_dict()})


def test_the_daemon_refits_the_season_when_an_owner_night_closes(tmp_path, owner_nights):
    """The real daemon against the real simulator: it records the owner's day (read only),
    closes the record at noon and refits the season model in a subprocess from the newest fit;
    the IMP fit's fields stay, the season block is the refit's with one more owner night."""
    from daemon_fixtures import (
        daemon_mapping,
        sim_process,
        start_daemon,
        stop_process,
        store_query,
        wait_until,
        write_config,
    )

    from impctl.store.export import export_nights

    state = tmp_path / "state"
    state.mkdir()
    db = state / "impctl.db"
    earlier, _ = fit_nights(owner_nights)
    with Store(db) as store:
        _store_records(store, owner_nights)  # 20 Nov – mid-December 2026
        export_nights(store, tmp_path / "before.csv", "csv")
        fit_id = store.add_fit([], {"hlc": "imp", "season": earlier.as_dict()})
    # 21:30 on 19 December: the record begins half an hour before the night's window
    # (22:00–05:00) and closes at noon on the 20th, a usable owner night
    epoch = datetime(2026, 12, 19, 21, 30, tzinfo=ZoneInfo(TZ))
    with sim_process(tmp_path, epoch, 3600.0) as sim:
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            state, sim.port, sim.clock, night={"sample_interval_s": 300},
            record={"keep_days": 400}))
        d = start_daemon(config, db, tmp_path / "daemon.log")
        try:
            wait_until(lambda: any(m.startswith("season model refreshed") for _, _, m in
                                   store_query(db, lambda s: s.events(20))), 300,
                       "the season refit", proc=d.proc)
            newest = store_query(db, lambda s: s.newest_fit())
            records = store_query(db, lambda s: s.owner_records())
        finally:
            stop_process(d.proc)
    log = (tmp_path / "daemon.log").read_text()
    assert "Traceback" not in log
    assert newest[0] == fit_id and newest[1]["hlc"] == "imp"
    season = newest[1]["season"]
    # started from the newest fit's θ (the simulator's house is not the recorded season's:
    # where the water then reads another emitter the full search decides, and says so)
    assert season["search"]["start_given"] is True
    # the model reads the closed records' rows, labelled ones too (a setpoint change is data)
    closed = [r for r in records if r.state == "done"]
    assert earlier.owner_nights < season["owner_nights"] <= len(closed)
    # the simulator's house is not the recorded season's: the two together leave the values
    # open, which the refit stores as missing (the values are the store-level test's)
    assert all(season[k]["value"] is None or season[k]["low"] < season[k]["value"]
               for k in KEYS)


def test_a_record_of_one_row_is_not_exported_and_the_file_reads(tmp_path, owner_nights):
    """A daemon started a minute before noon leaves a record of one row: the export leaves it
    out, else the NIGHTS reader refuses the whole file and no fit runs again."""
    from impctl.store.export import export_nights

    with Store(tmp_path / "impctl.db") as store:
        _store_records(store, owner_nights[:6])
        start = owner_nights[5].start.to_pydatetime() + timedelta(days=1)
        rid = store.open_owner_record(start, start + timedelta(days=1))
        store.add_owner_row(Sample(night_id=rid, ts=start, t_air_c=21.0, t_out_c=0.0,
                                   q_hc_w=2000.0, setpoint_c=21.0, dhw_share=0.0,
                                   defrost=False, snapshots=1))
        store.close_owner_record(rid, ["data missing"], 21.0, start, start)
        n = export_nights(store, tmp_path / "nights.csv", "csv")
    nights = read_nights(tmp_path / "nights.csv", TZ)
    assert len(nights) == 6 and n == sum(len(x.time_s) for x in owner_nights[:6])


def test_a_record_still_recording_is_not_exported(tmp_path, owner_nights):
    """The day being recorded has no labels yet (a setpoint change, hot water, missing data
    are found when it closes): the export and so every fit wait until it is closed."""
    from impctl.store.export import export_nights

    with Store(tmp_path / "impctl.db") as store:
        _store_records(store, owner_nights[:6])
        last = owner_nights[6]
        start = last.start.to_pydatetime()
        rid = store.open_owner_record(start, start + timedelta(days=1))
        for i, t in enumerate(last.time_s[:20]):
            store.add_owner_row(Sample(
                night_id=rid, ts=start + timedelta(seconds=float(t)),
                t_air_c=float(last.t_air_c[i]), t_out_c=float(last.t_out_c[i]),
                q_hc_w=float(last.q_hc_w[i]), setpoint_c=21.0, dhw_share=0.0,
                defrost=False, snapshots=3))
        n_open = export_nights(store, tmp_path / "open.csv", "csv")
        store.close_owner_record(rid, [], 21.0, start, start + timedelta(hours=2))
        n_closed = export_nights(store, tmp_path / "closed.csv", "csv")
    assert len(read_nights(tmp_path / "open.csv", TZ)) == 6
    assert n_open == sum(len(x.time_s) for x in owner_nights[:6])
    assert len(read_nights(tmp_path / "closed.csv", TZ)) == 7 and n_closed == n_open + 20


def test_impctl_fit_computes_the_season_beside_the_imp_fit_and_alone_alike(owner_nights):
    """``impctl fit`` runs the season model in a forked process while torch loads; what comes
    back is what the model gives in the command's own process, and a child that dies is
    computed again in the parent."""
    from impctl.cli.analysis.fit_cmd import _season, _SeasonJob

    alone, _, lines = _season(owner_nights, None)
    assert "convergence" in alone and lines
    job = _SeasonJob(owner_nights)
    beside, note = job.result()
    assert job._proc is not None and job._proc.exitcode == 0 and note is None
    assert beside == alone
    killed = _SeasonJob(owner_nights)
    killed._proc.kill()
    again, _ = killed.result()
    assert killed._proc.exitcode != 0 and again == beside


def test_impctl_season_takes_a_declared_emitter_and_refuses_an_unknown_one(tmp_path,
                                                                           owner_nights):
    csv = write_nights(owner_nights, tmp_path / "nights.csv")
    out = tmp_path / "season.json"
    res = run_cli("season", "--nights", str(csv), "--json", str(out), "--no-convergence",
                  "--emitter", "underfloor", model_dir=tmp_path / "no-models")
    assert res.returncode == 0, res.stderr
    assert "emitter: underfloor (declared" in res.stdout
    emitter = json.loads(out.read_text())["season"]["emitter"]
    assert emitter["source"] == "declared" and emitter["tau_e_max_h"] == 5.0
    bad = tmp_path / "bad.json"
    res = run_cli("season", "--nights", str(csv), "--json", str(bad), "--emitter", "screed",
                  model_dir=tmp_path / "no-models")
    assert res.returncode == 2 and "--emitter" in res.stderr and not bad.exists()


def _earlier_and_counted(winter_season, monkeypatch, before_last: int, fade: bool = True):
    """(household 1's nights, a fit of them up to its ``before_last``-th last owner night, a
    counter of the season residual's evaluations from here on — [n]); ``fade=False``: no water
    on the constrained nights (the lag bounded by the emitter's class)."""
    from impctl.season.projection import solve

    nights = household_nights(winter_season, 1)
    if not fade:
        nights = without_fade(nights)
    owner = [i for i, n in enumerate(nights) if n.kind == "owner"]
    earlier, _ = fit_nights(nights[:owner[-before_last]])
    calls = [0]
    real = solve.projected_residual

    def counted(*a, **kw):
        calls[0] += 1
        return real(*a, **kw)

    monkeypatch.setattr(solve, "projected_residual", counted)
    return nights, earlier, calls


def test_a_warm_search_stops_sooner_and_lands_where_the_strict_stop_does(winter_season,
                                                                         monkeypatch):
    """From an earlier fit's θ the search stops at a looser tolerance than the full search
    (one start: no other start to overtake it): fewer evaluations of the residuals, the same
    HLC, τ and C_m to 0.5 %."""
    from impctl.season.projection import solve

    # under the emitter class's bound, where the lag walks to its bound (decision 0031)
    nights, earlier, calls = _earlier_and_counted(winter_season, monkeypatch, 3, fade=False)
    warm, _ = fit_nights(nights, start=earlier.theta)
    loose, calls[0] = calls[0], 0
    monkeypatch.setattr(solve, "WARM_TOL", 1e-8)
    strict, _ = fit_nights(nights, start=earlier.theta)
    assert warm.warm_start and strict.warm_start
    assert loose < calls[0]
    for k in KEYS:
        assert warm.values[k] == pytest.approx(strict.values[k], rel=5e-3)


def test_a_warm_search_steps_shorter_and_lands_where_the_full_search_does(winter_season,
                                                                          monkeypatch):
    """From an earlier fit's θ, near the new optimum, the search's first step is bounded by
    |u| instead of MINPACK's 100 |u|: fewer evaluations of the residuals than the long first
    step, and the HLC, τ and C_m of the full search from the grid to a twentieth of their
    95 % interval (the loss is flat along C_m: the two stop 0.8 % apart on it here, a
    twenty-fifth of its interval's width)."""
    from impctl.season.projection import solve

    nights, earlier, calls = _earlier_and_counted(winter_season, monkeypatch, 2)
    short, _ = fit_nights(nights, start=earlier.theta)
    few, calls[0] = calls[0], 0
    monkeypatch.setattr(solve, "WARM_STEP", solve.FULL_STEP)
    fit_nights(nights, start=earlier.theta)
    assert few < calls[0]
    full, _ = fit_nights(nights)
    for k in KEYS:
        assert abs(short.values[k] - full.values[k]) < 0.05 * (full.high[k] - full.low[k])
