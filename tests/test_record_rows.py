"""An owner row from its snapshots and an owner record's labels: what is a mean, what stays
missing, and when a night is not the owner's ordinary night — on ordinary and on DST days."""

from __future__ import annotations

from dataclasses import fields
from datetime import UTC, date, datetime, timedelta
from zoneinfo import ZoneInfo

import pytest

from impctl.controller.recording.labels import (
    Span,
    judge,
    night_part,
    night_setpoint,
    record_day,
    record_window,
)
from impctl.controller.recording.rows import RowBuilder, row_start
from impctl.heatpump import Snapshot
from impctl.kronoterm.decode import Reading
from impctl.kronoterm.registers import Generation
from impctl.store import Sample

TZ = ZoneInfo("Europe/Ljubljana")
T0 = datetime(2026, 1, 12, 21, 0, tzinfo=UTC)
WINDOW = (22 * 60, 5 * 60)


def _snap(at: datetime, **values) -> Snapshot:
    """A real Snapshot; the fields not given are missing (as a sentinel reads)."""
    readings = {}
    for f in fields(Snapshot):
        if f.name in ("timestamp", "generation"):
            continue
        value = values.get(f.name)
        readings[f.name] = (Reading(f.name, float(value), "", at) if value is not None else
                            Reading.unavailable(f.name, "", at, "sentinel −600"))
    return Snapshot(timestamp=at, generation=Generation.EXTENDED, **readings)


def _row(snaps, expected=5, min_coverage=0.8) -> Sample:
    b = RowBuilder(T0, 300.0, expected, min_coverage)
    for s in snaps:
        b.add(s)
    return b.sample(1)


def test_a_row_is_the_mean_of_its_snapshots_and_missing_stays_missing():
    cycle = [3000, 0, 3000, 0, 3000]  # a cycling heat pump: 2329 is an instant
    snaps = [_snap(T0 + timedelta(seconds=60 * i), t_air_c=21.0 + 0.1 * i, t_out_c=-2.0,
                   q_hc_w=q, p_el_w=q / 3, t_supply_c=35.0, t_return_c=30.0,
                   loop1_target_c=36.5, working_function=1 if i == 4 else 0, defrost=0,
                   loop1_setpoint_c=21.0 if i < 4 else 20.0, loop1_mode=1, system_on=1,
                   errors_1=4 if i == 2 else 0, errors_2=0)
             for i, q in enumerate(cycle)]
    s = _row(snaps)
    assert s.ts == T0 and s.snapshots == 5
    assert s.t_air_c == pytest.approx(21.2) and s.q_hc_w == pytest.approx(1800.0)
    assert s.p_el_w == pytest.approx(600.0) and s.t_flow_target_c == pytest.approx(36.5)
    assert (s.t_supply_c, s.t_return_c) == (35.0, 30.0)
    assert s.dhw_share == pytest.approx(0.2) and s.dhw_active is True
    assert s.defrost is False and s.error_bits == 4
    assert s.setpoint_c == 20.0 and s.loop_mode == 1 and s.system_on == 1  # the last read


def test_a_column_with_too_few_snapshots_is_missing_not_a_number():
    # T_air read in 3 of 5 snapshots (a sentinel in the others): under 80 % → missing; T_out
    # in 4 of 5 → its mean. The flow target never read (a compact controller's sentinel).
    snaps = [_snap(T0 + timedelta(seconds=60 * i), t_air_c=21.0 if i < 3 else None,
                   t_out_c=-1.0 if i else None, q_hc_w=1000.0, defrost=1 if i == 1 else None)
             for i in range(5)]
    s = _row(snaps)
    assert s.t_air_c is None and s.t_out_c == -1.0 and s.q_hc_w == 1000.0
    assert s.t_flow_target_c is None and s.dhw_share is None and s.error_bits is None
    assert s.defrost is True  # one defrost seen is a defrost
    # a row cut short (the night began after two snapshots): its columns are missing
    short = _row([_snap(T0 + timedelta(seconds=60 * i), t_air_c=21.0, t_out_c=0.0,
                        q_hc_w=900.0) for i in range(2)])
    assert (short.t_air_c, short.q_hc_w, short.snapshots) == (None, None, 2)


def test_rows_lie_on_the_grid_and_records_run_noon_to_noon():
    assert row_start(datetime(2026, 1, 12, 21, 4, 59, tzinfo=UTC), 300) == datetime(
        2026, 1, 12, 21, 0, tzinfo=UTC)
    # 11:59 local belongs to yesterday's record, 12:00 to today's
    assert record_day(datetime(2026, 1, 12, 11, 59, tzinfo=TZ), TZ) == date(2026, 1, 11)
    assert record_day(datetime(2026, 1, 12, 12, 0, tzinfo=TZ), TZ) == date(2026, 1, 12)


@pytest.mark.parametrize("day, record_h, night_h", [
    (date(2026, 1, 12), 24, 7), (date(2026, 3, 28), 23, 6), (date(2026, 10, 24), 25, 8)],
    ids=["winter", "spring-23h", "autumn-25h"])
def test_a_full_record_is_usable_on_any_day_and_its_night_is_the_local_window(
        day, record_h, night_h):
    start, end = record_window(day, TZ)
    assert (end - start) == timedelta(hours=record_h)
    part = night_part(day, TZ, WINDOW)
    assert part[1] - part[0] == timedelta(hours=night_h)
    assert part[0].astimezone(TZ).hour == 22 and part[1].astimezone(TZ).hour == 5
    rows = [Sample(1, start + timedelta(minutes=5 * i), t_air_c=21.0, t_out_c=0.0,
                   q_hc_w=2000.0, setpoint_c=21.0, loop_mode=1, system_on=1, dhw_share=0.0)
            for i in range(record_h * 12)]
    assert judge(rows, part, interval_s=300, min_coverage=0.8, imp_spans=[], tz=TZ) == []
    # 90 minutes of the night missing: 5.5 of 7 h or 4.5 of 6 h is under 80 %, 6.5 of 8 h is
    # not — only when the night is measured in absolute time (a wall-clock difference makes
    # every 22:00–05:00 night 7 h long)
    gap = [r for r in rows if not part[0] <= r.ts < part[0] + timedelta(minutes=90)]
    labels = judge(gap, part, interval_s=300, min_coverage=0.8, imp_spans=[], tz=TZ)
    kept = (night_h - 1.5) / night_h
    assert (labels != []) == (kept < 0.8), (labels, kept)
    if labels:
        assert labels[0].startswith(f"data missing: {100 * kept:.0f} % of the night's rows "
                                    "(22:00–05:00)")


def _night_rows(day=date(2026, 1, 12), **changes):
    part = night_part(day, TZ, WINDOW)
    rows = []
    for i in range(7 * 12):
        ts = part[0] + timedelta(minutes=5 * i)
        kw = dict(t_air_c=21.0, t_out_c=0.0, q_hc_w=2000.0, setpoint_c=21.0, loop_mode=1,
                  system_on=1, dhw_share=0.0)
        for at, values in changes.items():
            if i >= int(at[1:]):
                kw.update(values)
        rows.append(Sample(1, ts, **kw))
    return rows, part


@pytest.mark.parametrize("changes, key, detail", [
    ({"i24": {"setpoint_c": 19.0}}, "owner changed the setpoint",
     "2187 21.0 → 19.0 °C at 00:00"),
    ({"i36": {"loop_mode": 2}}, "owner changed the setpoint", "loop-1 mode (2042) 1 → 2 at 01:00"),
    ({"i12": {"loop_mode": 0}}, "heating off", "loop 1 off (2042 = 0) at 23:00"),
    ({"i60": {"system_on": 0}}, "heating off", "heating system off (2012 = 0) at 03:00"),
    ({"i0": {"dhw_share": 0.4}}, "hot water dominated",
     "40 % of the night charging hot water (more than 25 %)"),
], ids=["setpoint", "mode", "loop-off", "system-off", "dhw"])
def test_each_label_names_its_reason(changes, key, detail):
    rows, part = _night_rows(**changes)
    labels = judge(rows, part, interval_s=300, min_coverage=0.8, imp_spans=[], tz=TZ)
    assert f"{key}: {detail}" in labels, labels


def test_a_night_taken_by_an_imp_night_is_labelled_and_not_missing_data():
    rows, part = _night_rows()
    span = Span(4, part[0] - timedelta(hours=2), part[1] + timedelta(minutes=20))
    inside = [r for r in rows if not span.start <= r.ts < span.end]
    labels = judge(inside, part, interval_s=300, min_coverage=0.8, imp_spans=[span], tz=TZ)
    assert labels == ["IMP night: night 4 ran 20:00–05:20"]
    assert night_setpoint(rows, part) == 21.0 and night_setpoint([], part) is None
