"""The daemon records the house read-only between IMP nights: the real daemon against the
realistic simulator over loopback Modbus TCP (through a proxy that sees every request), a real
store, on the virtual-time loop (days in seconds, the same on a busy machine).

What is promised: not one write over days of recording (no FC 06 request crosses the wire,
the write budget file is untouched); rows every interval, in time order, their snapshots
averaged; one record per local day from noon to noon, closed and labelled after its day,
23 h and 25 h on the days the clocks change; an IMP night is left out of the owner record
(it keeps its own); old records are deleted by the daemon; ``[record] enabled = false``
records nothing.
"""

from __future__ import annotations

import os
from datetime import datetime, timedelta
from zoneinfo import ZoneInfo

import numpy as np
import pandas as pd
from reliability_fixtures import daemon_rig, run_virtual

from impctl.cli.device.status import collect_status, format_status
from impctl.clock import VirtualClock
from impctl.controller.recording.labels import record_day
from impctl.heatpump import WriteBudget
from impctl.imp.files.nights_csv import read_nights
from impctl.imp.night import SHORT_NOTE, split_owner
from impctl.imp.protocol import SHORT_NIGHT
from impctl.season import record_from_nights
from impctl.store.export import export_nights

TZ = ZoneInfo("Europe/Ljubljana")
SPEED = 600.0


def _stat(path) -> tuple:
    """(size, mtime) of the write-budget file and its WAL, as the kernel has them."""
    out = []
    for suffix in ("", "-wal"):
        try:
            st = os.stat(f"{path}{suffix}")
            out.append((st.st_size, st.st_mtime_ns))
        except FileNotFoundError:
            out.append(None)
    return tuple(out)


def _in_order(rows) -> bool:
    return all(a.ts < b.ts for a, b in zip(rows, rows[1:], strict=False))


def test_days_of_recording_write_nothing_and_keep_labelled_records(tmp_path):
    """Two days and a half (03:00 on day 0 to 15:00 on day 2): 120-s snapshots, 5-min rows,
    records kept for 1 day. Enough for every promise: the partial first record deleted, a
    whole day's record closed, the next one open."""
    async def scenario():
        async with daemon_rig(tmp_path, speed=SPEED, night={"sample_interval_s": 120},
                              record={"keep_days": 1}) as rig:
            cfg = rig.daemon.cfg
            await rig.sim_minutes(15)
            budget_before = _stat(cfg.budget_path)
            start = rig.clock.now()
            end = start + timedelta(days=2, hours=12)
            await rig.until(lambda: rig.clock.now() >= end, timeout_s=3 * 86400 / SPEED)
            st = collect_status(cfg)
            return dict(
                fc06=rig.proxy.stats.requests[6], sim_writes=dict(rig.sim.stats.writes),
                budget=(budget_before, _stat(cfg.budget_path)),
                records=rig.store.owner_records(),
                rows={n.id: rig.store.samples(n.id) for n in rig.store.owner_records()},
                nights=rig.store.nights(), pending=rig.store.journal_pending(),
                status=format_status(st, "Europe/Ljubljana"), st=st["record"],
                export=export_nights(rig.store, tmp_path / "nights.csv", "csv"),
                warnings=rig.logs.lines(), start=start)

    r = run_virtual(scenario(), 4 * 86400 / SPEED)
    # Read only: not one write request crossed the wire, none reached the heat pump, and the
    # write-budget file is as the daemon's start left it.
    assert r["fc06"] == 0 and r["sim_writes"] == {}
    assert r["budget"][0] == r["budget"][1], r["budget"]
    with WriteBudget(tmp_path / "state" / "writes.db", 12) as budget:
        assert budget.lifetime(2187) == budget.lifetime(2042) == 0
    assert r["nights"] == [] and r["pending"] == []
    assert r["warnings"] == [], r["warnings"]
    # Kept one day, deleted once a day (at 03:00 here, 24 h after the start): the records
    # that ended before 03:00 yesterday (11 Jan from 03:00 on the 12th) are gone; the records
    # of 12 and 13 Jan are closed, the one of 14 Jan recording.
    days = [record_day(n.window_start, TZ).isoformat() for n in r["records"]]
    assert days == ["2026-01-12", "2026-01-13", "2026-01-14"], days
    _, closed, current = r["records"]
    assert (closed.state, closed.valid, closed.reasons) == ("done", True, ()), closed
    assert current.state == "recording" and current.valid is None
    assert closed.setpoint_c == 21.0  # the owner's, as read at night
    rows = r["rows"][closed.id]
    assert len(rows) == 288 and _in_order(rows)  # 24 h of 5-min rows, every one
    assert rows[0].ts == closed.window_start and closed.started == closed.window_start
    assert closed.ended == closed.window_end
    assert all(s.snapshots in (2, 3) and s.ts.timestamp() % 300 == 0 for s in rows)
    assert all(None not in (s.t_air_c, s.t_out_c, s.q_hc_w, s.t_flow_target_c,
                            s.dhw_share, s.setpoint_c) for s in rows)
    assert any(0 < s.q_hc_w for s in rows) and all(-1 < s.t_out_c < 1 for s in rows)
    # The closed records exported whole, as kind owner, in time order (the open one waits
    # for its labels); read back as owner nights with the heat pump's curve and the hot
    # water per row.
    nights = read_nights(tmp_path / "nights.csv", "Europe/Ljubljana")
    assert [n.kind for n in nights] == ["owner", "owner"]
    first = nights[1]
    assert first.label == "" and len(first.time_s) == 288
    assert first.t_flow_target_c is not None and (first.t_flow_target_c > 20).all()
    assert first.dhw is not None and first.t_flow_c is not None
    assert r["export"] == sum(len(rows) for rid, rows in r["rows"].items()
                              if rid != current.id)
    # impctl status: recording now, the records kept, the store's size
    assert r["st"]["state"] == "recording" and r["st"]["records"] == 3
    assert "recording: on (a snapshot every 120 s, rows of 300 s)" in r["status"]
    assert "owner:     3 records kept (2026-01-12 … 2026-01-14, 1 open), 0 labelled" in (
        r["status"])
    assert "store:     " in r["status"]


def test_an_imp_night_is_its_own_record_not_the_owners(tmp_path):
    """A manual night at 21:30 (the rig's night window: 22:00–23:00): the owner's rows stop
    at its pre-heat and resume after its restore; the owner record of that night is labelled
    "IMP night"."""
    async def scenario():
        async with daemon_rig(tmp_path, speed=SPEED, record={"enabled": True},
                              epoch=datetime(2026, 1, 12, 21, 0, tzinfo=TZ)) as rig:
            await rig.sim_minutes(30)
            night_id = await rig.trigger("constrained")
            await rig.until(lambda: rig.finished(night_id), 600)
            # the record of that night closes at noon
            noon = datetime(2026, 1, 13, 13, 0, tzinfo=TZ)
            await rig.until(lambda: rig.clock.now() >= noon, 600)
            record = rig.store.owner_records()[0]
            export_nights(rig.store, tmp_path / "nights.csv", "csv", valid_only=False)
            return dict(night=rig.store.night(night_id), record=record,
                        rows=rig.store.samples(record.id),
                        fc06=rig.proxy.stats.requests[6])

    r = run_virtual(scenario(), 86400)
    night, record, rows = r["night"], r["record"], r["rows"]
    assert night.state == "done" and r["fc06"] > 0  # the night wrote; then restored
    assert record.state == "done" and record.valid is False
    assert record.reasons[0].startswith(f"IMP night: night {night.id} ran "), record.reasons
    assert _in_order(rows)
    inside = [s for s in rows if s.ts >= night.started
              and s.ts + timedelta(seconds=300) <= night.ended]
    assert inside == [], inside  # no owner row within the night
    before = [s for s in rows if s.ts < night.started]
    after = [s for s in rows if s.ts >= night.ended]
    assert before and after and after[0].ts < night.ended + timedelta(minutes=10)
    assert all(s.loop_mode == 1 for s in rows)  # the owner's own mode, before and after
    # Exported: the night's pre-heat as its first rows, read as a piece of the night that
    # only the season model takes; the night itself from its window — an hour of cooling,
    # too short for the IMP fit: labelled the season model's, which the IMP fit leaves out.
    read = read_nights(tmp_path / "nights.csv", "Europe/Ljubljana")
    mine = [n for n in read if n.night_id == str(night.id)]
    assert [(n.kind, n.phase) for n in mine] == [("constrained", "preheat"), ("constrained", "")]
    pre, window = mine
    pre_ts = pre.start + pd.to_timedelta(pre.time_s, unit="s")
    assert pre_ts[0] >= night.started and pre_ts[-1] < night.window_start <= window.start
    assert len(pre.time_s) >= 5 and pre.setpoint_c == 22.5  # T_max, as read
    imp, note = split_owner(read)
    assert window.label == pre.label == SHORT_NIGHT and SHORT_NIGHT in night.reasons
    assert str(night.id) not in [n.night_id for n in imp] and SHORT_NOTE in note
    # the season model's grid: no step missing from the owner's last row before the night
    # to the window's end
    rec = record_from_nights(read)
    t = rec.t0_s + np.arange(rec.n) * rec.step_s
    span = (t >= before[-1].ts.timestamp()) & (t < night.window_end.timestamp())
    assert span.sum() >= 12 and np.isfinite(rec.t_air_c[span]).all(), rec.kind[span]


def _dst_record(tmp_path, day: str) -> tuple:
    """Record from 09:00 on ``day`` to 13:00 the day after: the record of ``day``."""
    epoch = datetime.fromisoformat(f"{day}T09:00").replace(tzinfo=TZ)

    async def scenario():
        async with daemon_rig(tmp_path, speed=SPEED, epoch=epoch,
                              record={"sample_interval_s": 300}) as rig:
            await rig.until(lambda: rig.clock.now() >= epoch + timedelta(hours=28), 600)
            records = rig.store.owner_records()
            return records, {n.id: rig.store.samples(n.id) for n in records}
    return run_virtual(scenario(), 86400)


def test_the_days_the_clocks_change_are_23_and_25_hours(tmp_path):
    for day, hours in (("2026-03-28", 23), ("2026-10-24", 25)):
        records, rows = _dst_record(tmp_path / day, day)
        record = next(n for n in records if record_day(n.window_start, TZ).isoformat() == day)
        assert record.window_end - record.window_start == timedelta(hours=hours)
        assert (record.state, record.valid, record.reasons) == ("done", True, ()), record
        mine = rows[record.id]
        # from 12:00 on the day (rows start at 09:00 in the record of the day before)
        assert len(mine) == hours * 12 and _in_order(mine), (day, len(mine))
        assert mine[-1].ts + timedelta(seconds=300) == record.window_end


def test_recording_off_records_nothing(tmp_path):
    async def scenario():
        async with daemon_rig(tmp_path, speed=SPEED, record={"enabled": False}) as rig:
            await rig.sim_minutes(90)
            st = collect_status(rig.daemon.cfg)
            return rig.store.owner_records(), format_status(st, "Europe/Ljubljana")
    records, status = run_virtual(scenario(), 86400)
    assert records == []
    assert "recording: off (record.enabled = false)" in status
    assert "owner:     no owner record yet" in status


class _LaggingWall:
    """The daemon's wall-clock source: the loop's, ``lag_s`` behind once set [s of the loop]."""

    def __init__(self, base) -> None:
        self.base = base
        self.lag_s = 0.0

    def __call__(self) -> float:
        return self.base() - self.lag_s


def test_recording_goes_on_when_the_clock_lands_milliseconds_short_of_each_snapshot(tmp_path):
    """The daemon's wall clock steps back 5 ms (far below a step the recorder notes, 120 s):
    every bounded wait (one snapshot interval) then lands 5 ms short of its snapshot instant —
    as on a long run of the virtual-time loop, whose float time drifts that far from the grid
    after ~50 simulated days. The recorder waits the 5 ms and goes on: a row every 5 min."""
    walls: list[_LaggingWall] = []

    def lagging(house: VirtualClock) -> VirtualClock:
        walls.append(_LaggingWall(house._wall))
        return VirtualClock(house.epoch, house.factor, house.wall_epoch_s, wall=walls[0],
                            monotonic=house._wall)

    async def scenario():
        async with daemon_rig(tmp_path, speed=SPEED, daemon_clock=lagging,
                              record={"enabled": True}) as rig:
            await rig.sim_minutes(20)
            walls[0].lag_s = 0.005 / SPEED  # 5 simulated ms
            stepped = rig.clock.now()
            await rig.sim_minutes(120)
            records = rig.store.owner_records()
            return stepped, [s for n in records for s in rig.store.samples(n.id)]

    stepped, rows = run_virtual(scenario(), 86400)
    after = [s for s in rows if s.ts > stepped]
    assert len(after) >= 22, [s.ts.isoformat() for s in rows]  # 2 h of 5-min rows
    assert _in_order(rows) and all(s.snapshots == 5 for s in after[:-1]), after
