"""The heating curve on a gateway: the real ``impctl daemon`` against the real simulator over
Modbus TCP — it sets the kept curve only when the owner asks, journals the owner's points
first, checks the controller follows, raises the curve when the room stays short, and gives
the owner's points back on ``impctl curve --restore``, on stop and never on a compact
controller it touches at all."""

from __future__ import annotations

import json
import signal
from datetime import datetime
from pathlib import Path
from zoneinfo import ZoneInfo

from cli_fixtures import run_impctl
from daemon_fixtures import (
    daemon_mapping,
    modbus_read,
    modbus_write,
    run_cli,
    sim_process,
    start_daemon,
    stop_process,
    store_query,
    wait_until,
    write_config,
)

from impctl.model import default_house

TZ = ZoneInfo("Europe/Ljubljana")
EPOCH = datetime(2026, 1, 12, 9, 0, tzinfo=TZ)  # morning: no night window for hours
SPEED = 600.0
KEEP = ("loop1_curve_cold", "loop1_curve_mild")


def _kept_curve(state: Path, points: tuple[float, float], lowers: bool = True) -> None:
    """A kept ``impctl curve`` result with the recommended ``points`` [°C]."""
    state.mkdir(parents=True, exist_ok=True)
    (state / "curve.json").write_text(json.dumps({
        "schema": "impctl-curve/1", "lowers": lowers, "advice": "Your heating runs hot.",
        "recommended": {"t_out_c": [-15.0, 15.0], "flow_c": list(points),
                        "flow_at_0_c": sum(points) / 2}}))


def _points(port: int) -> tuple[int, int]:
    return modbus_read(port, 2309)[0], modbus_read(port, 2314)[0]


def _curve_journal(db: Path) -> list:
    return [e for e in store_query(db, lambda s: s.journal_pending()) if e.register in KEEP]


def _start_with_curve(tmp_path: Path, sim, points: tuple[float, float], **curve):
    """A kept curve of ``points`` [°C], the owner asking for it (``curve``: more of
    ``[curve]``), and the daemon started: (daemon, state dir, config, store)."""
    state = tmp_path / "state"
    _kept_curve(state, points)
    config = write_config(tmp_path / "config.toml", daemon_mapping(
        state, sim.port, sim.clock, curve={"apply": True, **curve}))
    db = state / "impctl.db"
    return start_daemon(config, db, tmp_path / "daemon.log"), state, config, db


def test_the_daemon_sets_the_curve_the_owner_asked_for_and_gives_it_back(tmp_path):
    with sim_process(tmp_path, EPOCH, SPEED) as sim:
        owner = _points(sim.port)
        assert 300 < owner[0] < 600 and owner[1] < owner[0]  # the installer's curve, raw
        new = ((owner[0] - 40) / 10.0, (owner[1] - 20) / 10.0)  # 4 K and 2 K lower
        state = tmp_path / "state"
        _kept_curve(state, new)
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            state, sim.port, sim.clock, curve={"apply": True}))
        db = state / "impctl.db"
        target_before = modbus_read(sim.port, 2128)[0]
        d = start_daemon(config, db, tmp_path / "daemon.log")
        try:
            want = (round(new[0] * 10), round(new[1] * 10))
            wait_until(lambda: _points(sim.port) == want, 30, "the curve set", proc=d.proc)
            # the owner's points journaled before the first write
            journal = {e.register: e.raw_value for e in _curve_journal(db)}
            assert journal == {"loop1_curve_cold": owner[0], "loop1_curve_mild": owner[1]}
            # the line comes after the read-back of the written points
            wait_until(lambda: "heating curve set to" in d.output(), 30, "the line",
                       proc=d.proc)
            # the controller follows: its flow target came down with the curve, and the
            # check at the next look left the curve set
            wait_until(lambda: modbus_read(sim.port, 2128)[0] <= target_before - 20, 30,
                       "the flow target to come down", proc=d.proc)
            wait_until(lambda: "heating curve followed" in d.output(), 30, "the check",
                       proc=d.proc)
            assert "did not follow" not in d.output() and _points(sim.port) == want
            # set on the owner's word, watched: held, not a restore waiting
            st = run_impctl("status", "--config", str(config))
            assert "impctl's heating curve is set" in st.stdout
            assert "restore:" not in st.stdout and "RESTORE PENDING" not in st.stdout

            # the owner takes it back while the daemon runs
            res = run_impctl("curve", "--restore", "--config", str(config))
            assert res.returncode == 0, res.stderr
            assert "the running daemon gives your heating curve back" in res.stdout
            wait_until(lambda: _points(sim.port) == owner, 30, "the owner's curve back",
                       proc=d.proc)
            wait_until(lambda: not _curve_journal(db), 10, "the journal closed")
            # logged just after the journal closes
            wait_until(lambda: "the owner's heating curve restored" in d.output(), 10,
                       "the restore said", proc=d.proc)

            # and asks for it again; a stop gives the owner's points back
            res = run_impctl("curve", "--apply", "--config", str(config))
            assert res.returncode == 0 and "Your heating runs hot." in res.stdout
            wait_until(lambda: _points(sim.port) == want, 30, "the curve set again",
                       proc=d.proc)
            d.proc.send_signal(signal.SIGTERM)
            assert d.proc.wait(30) == 0
            assert _points(sim.port) == owner
            assert not _curve_journal(db)
        finally:
            stop_process(d.proc)


def test_the_watch_raises_a_curve_that_leaves_the_room_short(tmp_path):
    """The room only has to fall short: the default house (it cools fast, as the T_air abort
    tests use it) and the watch's thresholds at their configurable least (0.2 K for 0.25 h)
    get there within hours of simulated time, not the heavy house's day and a half."""
    with sim_process(tmp_path, EPOCH, 3600.0, house=default_house()) as sim:
        # far too low for this house at 0 °C
        d, _, _, db = _start_with_curve(tmp_path, sim, (26.0, 21.0), raise_k=2.0, short_k=0.2,
                                        short_h=0.25)
        try:
            wait_until(lambda: _points(sim.port) == (260, 210), 30, "the curve set",
                       proc=d.proc)
            wait_until(lambda: "heating curve raised by 2 K" in d.output(), 90,
                       "the comfort watch to raise the curve", proc=d.proc)
            assert "below its setpoint 21.0 °C over 0.25 h (more than 0.2 K" in d.output()
            raised = _points(sim.port)
            assert raised[0] >= 280 and raised[1] >= 230
            wait_until(lambda: any("raised by 2 K" in message for _, _, message
                                   in store_query(db, lambda s: s.events(50))),
                       10, "the raise stored as an event", proc=d.proc)
        finally:
            stop_process(d.proc)


def test_no_curve_is_set_on_a_compact_controller_or_without_the_owners_word(tmp_path):
    with sim_process(tmp_path, EPOCH, SPEED, args=("--generation", "compact",
                                                     "--heat-meter-id", "30")) as sim:
        state = tmp_path / "state"
        _kept_curve(state, (40.0, 25.0))
        mapping = daemon_mapping(state, sim.port, sim.clock, curve={"apply": True})
        mapping["heatpump"]["generation"] = "compact"
        mapping["heatpump"]["heat_meter"] = {"device_id": 30, "address": 0,
                                             "datatype": "uint32"}
        config = write_config(tmp_path / "config.toml", mapping)
        db = state / "impctl.db"
        d = start_daemon(config, db, tmp_path / "daemon.log")
        try:
            wait_until(lambda: "compact controller (TT3000) has no heating-curve registers"
                       in d.output(), 30, "the refusal", proc=d.proc)
            assert not _curve_journal(db)
            # said once, not at every look
            wait_until(lambda: store_query(db, lambda s: len(s.events(50))) > 0, 5, "events")
            assert d.output().count("heating curve not set") == 1
        finally:
            stop_process(d.proc)
    (tmp_path / "b").mkdir()
    with sim_process(tmp_path / "b", EPOCH, SPEED) as sim:
        owner = _points(sim.port)
        state = tmp_path / "b" / "state"
        _kept_curve(state, ((owner[0] - 40) / 10.0, (owner[1] - 20) / 10.0))
        config = write_config(tmp_path / "b.toml", daemon_mapping(state, sim.port, sim.clock))
        d = start_daemon(config, state / "impctl.db", tmp_path / "b.log")
        try:  # [curve] apply not set, no impctl curve --apply: advice only
            wait_until(lambda: "next night job at" in d.output(), 30, "the daemon",
                       proc=d.proc)
            res = run_impctl("curve", "--restore", "--config", str(tmp_path / "b.toml"))
            assert res.returncode == 0
            assert _points(sim.port) == owner and not _curve_journal(state / "impctl.db")
        finally:
            stop_process(d.proc)


def test_a_controller_that_does_not_follow_its_points_gets_them_back(tmp_path):
    """The ideal plant keeps its flow target whatever the points say: after the check the
    owner's points are back, the curve stays advice, and impctl does not try again."""
    with sim_process(tmp_path, EPOCH, SPEED, plant="iso") as sim:
        owner = _points(sim.port)
        d, state, _, db = _start_with_curve(tmp_path, sim, (36.0, 24.0))
        try:
            wait_until(lambda: "did not follow the curve points" in d.output(), 30,
                       "the check to fail", proc=d.proc)
            wait_until(lambda: _points(sim.port) == owner, 10, "the owner's points back")
            # The refusal is said after the points are written back: wait for it, not race it.
            wait_until(lambda: "does not follow its curve points" in d.output(), 10,
                       "the refusal", proc=d.proc)
            assert not _curve_journal(db)
            assert json.loads((state / "curve-intent.json").read_text())["apply"] is False
        finally:
            stop_process(d.proc)


def test_the_owners_own_change_is_kept_and_a_night_leaves_the_curve(tmp_path):
    with sim_process(tmp_path, EPOCH, SPEED) as sim:
        owner = _points(sim.port)
        new = ((owner[0] - 40) / 10.0, (owner[1] - 20) / 10.0)
        want = (round(new[0] * 10), round(new[1] * 10))
        state = tmp_path / "state"
        _kept_curve(state, new)
        config = write_config(tmp_path / "config.toml", daemon_mapping(
            state, sim.port, sim.clock, curve={"apply": True},
            night={"window": "10:00-11:30", "preheat_h": 0.25, "sample_interval_s": 120}))
        db = state / "impctl.db"
        d = start_daemon(config, db, tmp_path / "daemon.log")
        try:
            wait_until(lambda: _points(sim.port) == want, 30, "the curve set", proc=d.proc)
            # a night runs and ends: its restore gives back the setpoint, not the curve
            res = run_cli("trigger", "--kind", "normal", "--now", "--force", "--config",
                          str(config))
            assert res.returncode == 0, res.stderr
            wait_until(lambda: store_query(db, lambda s: [n.valid for n in s.nights()]
                                         ) not in ([], [None]), 60,
                       "the night to end", proc=d.proc)
            assert _points(sim.port) == want
            assert {e.register for e in _curve_journal(db)} == set(KEEP)
            # the owner sets a point of their own: kept, and impctl sets no curve any more
            modbus_write(sim.port, 2309, want[0] + 15)
            wait_until(lambda: "the owner changed the heating curve" in d.output(), 30,
                       "the owner's change noticed", proc=d.proc)
            assert not _curve_journal(db)
            assert _points(sim.port)[0] == want[0] + 15
        finally:
            stop_process(d.proc)


def test_curve_restore_gives_the_points_back_when_no_daemon_runs(tmp_path):
    with sim_process(tmp_path, EPOCH, SPEED) as sim:
        owner = _points(sim.port)
        new = ((owner[0] - 40) / 10.0, (owner[1] - 20) / 10.0)
        d, state, config, db = _start_with_curve(tmp_path, sim, new)
        try:
            wait_until(lambda: _points(sim.port) == (round(new[0] * 10), round(new[1] * 10)),
                       30, "the curve set", proc=d.proc)
            d.proc.kill()  # no stop, no restore: the journal keeps the owner's points
            d.proc.wait(10)
        finally:
            stop_process(d.proc)
        assert len(_curve_journal(db)) == 2
        res = run_impctl("curve", "--restore", "--config", str(config))
        assert res.returncode == 0, res.stderr
        assert "your heating curve is back" in res.stdout
        assert _points(sim.port) == owner and not _curve_journal(db)


def test_a_new_fit_asking_past_the_bounds_gives_the_owner_their_curve_back(tmp_path):
    """Never a clamp: a point clamped to 55 °C would read back as somebody else's change, and
    the owner's points would be taken for their own and never come back."""
    with sim_process(tmp_path, EPOCH, SPEED) as sim:
        owner = _points(sim.port)
        assert owner[0] < 550
        new = ((owner[0] - 40) / 10.0, (owner[1] - 20) / 10.0)
        d, state, config, db = _start_with_curve(tmp_path, sim, new)
        try:
            wait_until(lambda: _points(sim.port) == (round(new[0] * 10), round(new[1] * 10)),
                       30, "the curve set", proc=d.proc)
            _kept_curve(state, (56.0, new[1]))  # the next fit: above 55 °C and the owner's
            wait_until(lambda: "the new fit's curve cannot be set" in d.output(), 30,
                       "the refusal", proc=d.proc)
            assert _points(sim.port) == owner and not _curve_journal(db)
            assert "the owner changed" not in d.output()
        finally:
            stop_process(d.proc)


def test_a_cold_point_the_owner_runs_above_55_c_is_lowered_within_it(tmp_path):
    """A radiator house's curve often runs above 55 °C at −15 °C: impctl may set a point up
    to the owner's own there (a value the controller already runs), and gives theirs back."""
    with sim_process(tmp_path, EPOCH, SPEED) as sim:
        modbus_write(sim.port, 2309, 620)  # the owner's curve: 62 °C at −15 °C outside
        owner = _points(sim.port)
        assert owner[0] == 620
        new = (58.0, (owner[1] - 20) / 10.0)
        d, state, config, db = _start_with_curve(tmp_path, sim, new)
        try:
            wait_until(lambda: _points(sim.port) == (580, round(new[1] * 10)), 30,
                       "the curve set", proc=d.proc)
            assert {e.register: e.raw_value for e in _curve_journal(db)} == {
                "loop1_curve_cold": 620, "loop1_curve_mild": owner[1]}
            d.proc.send_signal(signal.SIGTERM)
            assert d.proc.wait(30) == 0
            assert _points(sim.port) == owner and not _curve_journal(db)
        finally:
            stop_process(d.proc)


def test_a_curve_raised_back_to_the_owners_is_not_set_again(tmp_path):
    """A curve the comfort watch had to raise all the way back proved too low for this house:
    the owner's points stay, and impctl sets no curve until asked again (it would otherwise
    set the same curve at the next look and leave the room short once more)."""
    with sim_process(tmp_path, EPOCH, 3600.0, house=default_house()) as sim:
        modbus_write(sim.port, 2309, 400)  # the owner's own curve: 40 °C at −15 °C outside,
        modbus_write(sim.port, 2314, 300)  # 30 °C at +15 °C (barely enough for this house)
        owner = _points(sim.port)
        d, state, config, db = _start_with_curve(tmp_path, sim, (37.0, 27.0), raise_k=2.0,
                                                 short_k=0.2, short_h=0.25)
        try:
            wait_until(lambda: "raised back to the owner's curve" in d.output(), 60,
                       "the curve raised back to the owner's", proc=d.proc)
            wait_until(lambda: _points(sim.port) == owner and not _curve_journal(db), 10,
                       "the owner's points back")
            looks = d.output().count("heating curve set to")
            wait_until(lambda: "sets no curve until asked again" in d.output(), 10,
                       "the stop said", proc=d.proc)
            assert json.loads((state / "curve-intent.json").read_text())["apply"] is False
            sim_time = sim.clock.now()
            wait_until(lambda: (sim.clock.now() - sim_time).total_seconds() > 3 * 3600, 30,
                       "three simulated hours")
            assert _points(sim.port) == owner and not _curve_journal(db)
            assert d.output().count("heating curve set to") == looks
        finally:
            stop_process(d.proc)


def test_a_room_short_on_average_is_raised_though_its_readings_cross_the_line(tmp_path):
    """A noisy room sensor (2 K SD) crosses the line every few looks: the room is short on
    the mean of two hours, and that is what the watch judges (look by look it never was)."""
    with sim_process(tmp_path, EPOCH, 3600.0, house=default_house(),
                     args=("--noise", "2.0", "--seed", "3")) as sim:
        modbus_write(sim.port, 2309, 400)
        modbus_write(sim.port, 2314, 300)
        # a little short: on the mean of an hour, not on every reading
        d, _, _, db = _start_with_curve(tmp_path, sim, (39.0, 29.0), short_k=0.2, short_h=2.0)
        try:
            wait_until(lambda: _points(sim.port) == (390, 290), 30, "the curve set",
                       proc=d.proc)
            wait_until(lambda: "the room stayed on average" in d.output(), 60,
                       "the comfort watch to act", proc=d.proc)
            # raised by its 1 K, the curve is the owner's again
            wait_until(lambda: _points(sim.port) == (400, 300), 10, "the owner's curve")
        finally:
            stop_process(d.proc)
