"""The owner records in a real SQLite store: the migration that admits them, their rows, their
retention, and that they never mix with the IMP nights the campaign and the fit count."""

from __future__ import annotations

import sqlite3
from datetime import UTC, datetime, timedelta

import pytest

from impctl.store import SCHEMA_VERSION, Sample, Store
from impctl.store.recording.house_inputs import HouseInputRow
from impctl.store.schema import MIGRATIONS

T0 = datetime(2026, 1, 12, 11, 0, tzinfo=UTC)  # noon in Ljubljana


def _store_at(path, version: int) -> None:
    """A store file at schema ``version``, as that impctl release left it."""
    db = sqlite3.connect(path, isolation_level=None)
    for target in range(1, version + 1):
        for statement in MIGRATIONS[target - 1].split(";"):
            if statement.strip():
                db.execute(statement)
    db.execute(f"PRAGMA user_version = {version}")
    db.close()


def test_migration_6_keeps_every_row_and_admits_owner_records(tmp_path):
    path = tmp_path / "impctl.db"
    _store_at(path, 5)
    db = sqlite3.connect(path, isolation_level=None)
    db.execute("PRAGMA foreign_keys=ON")
    night = ("constrained", 21.0, 19.5, 23.5, T0.isoformat(), (T0 + timedelta(hours=7))
             .isoformat(), "done", "schedule", 1, '["window ended"]', T0.isoformat(),
             (T0 + timedelta(hours=7)).isoformat())
    db.execute("INSERT INTO nights (id, kind, setpoint_c, t_min_c, t_max_c, window_start,"
               " window_end, state, source, valid, reasons, started, ended)"
               " VALUES (7, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)", night)
    db.execute("INSERT INTO samples (night_id, ts, t_air_c, q_hc_w) VALUES (7, ?, 21.5, 1500)",
               (T0.isoformat(),))
    db.execute("INSERT INTO journal (night_id, register, address, raw_value, recorded,"
               " restored) VALUES (7, 'loop1_setpoint', 2186, 210, ?, ?)",
               (T0.isoformat(), T0.isoformat()))
    db.execute("INSERT INTO campaign (seq, kind, setpoint_c, night_id) VALUES (0,"
               " 'constrained', 21.0, 7)")
    db.execute("INSERT INTO house_inputs (night_id, ts, t_rooms_c) VALUES (7, ?, 21.2)",
               (T0.isoformat(),))
    before = db.execute("SELECT * FROM nights").fetchall()
    db.close()

    with Store(path) as store:
        assert store.schema_version == SCHEMA_VERSION == 7
        assert store.integrity_check() == "ok"
        assert store._db.execute("PRAGMA foreign_key_check").fetchall() == []
        assert store._db.execute("PRAGMA foreign_keys").fetchone()[0] == 1  # on again
        after = [tuple(r) for r in store._db.execute("SELECT * FROM nights")]
        assert after == before
        assert store.samples(7)[0].q_hc_w == 1500 and store.campaign()[0][3] == 7
        assert store.house_inputs(7)[0].t_rooms_c == 21.2
        # the foreign keys point at the new table: a sample of no night is refused
        with pytest.raises(sqlite3.IntegrityError):
            store.add_sample(Sample(99, T0))
        rid = store.open_owner_record(T0, T0 + timedelta(days=1))
        assert store.night(rid).kind == "owner" and store.night(rid).setpoint_c is None
        store.add_sample(Sample(rid, T0, t_flow_target_c=38.5, dhw_share=0.2, system_on=1,
                                snapshots=5))
        row = store.samples(rid)[0]
        assert (row.t_flow_target_c, row.dhw_share, row.system_on, row.snapshots) == (
            38.5, 0.2, 1, 5)
        with pytest.raises(sqlite3.IntegrityError):  # still only the three kinds
            store._db.execute("UPDATE nights SET kind = 'other' WHERE id = ?", (rid,))


def test_owner_records_are_apart_from_the_imp_nights(tmp_path):
    """The campaign, the orphan sweep, the fit and status count IMP nights: an owner record,
    valid or open, is none of them."""
    with Store(tmp_path / "db") as store:
        nid = store.create_night("normal", 22.0, T0, T0 + timedelta(hours=7))
        store.assess_night(nid, True, [])
        rid = store.open_owner_record(T0, T0 + timedelta(days=1))
        store.close_owner_record(rid, [], 21.0, T0, T0 + timedelta(days=1))
        assert [n.id for n in store.nights()] == [nid]
        assert [n.id for n in store.nights(valid=True)] == [nid]
        assert [n.id for n in store.owner_records()] == [rid]
        assert store.night(rid).valid is True and store.night(rid).state == "done"
        # the same day's record is found again, not made twice
        assert store.open_owner_record(T0, T0 + timedelta(days=1)) == rid


def test_owner_rows_in_order_with_their_inputs_and_retention(tmp_path):
    with Store(tmp_path / "db") as store:
        nid = store.create_night("constrained", 21.0, T0, T0 + timedelta(hours=7))
        ids = []
        for day in range(3):
            start = T0 + timedelta(days=day)
            rid = store.open_owner_record(start, start + timedelta(days=1))
            ids.append(rid)
            for i in range(3):
                ts = start + timedelta(minutes=5 * i)
                store.add_owner_row(Sample(rid, ts, t_air_c=21.0 + i, snapshots=5),
                                    HouseInputRow(rid, ts, t_rooms_c=20.5))
            store.close_owner_record(rid, ["data missing: 3 % …"] if day else [], None,
                                     start, start + timedelta(minutes=15))
        assert store.last_owner_row() == T0 + timedelta(days=2, minutes=10)
        summary = store.owner_summary()
        assert (summary.count, summary.rows, summary.labelled) == (3, 9, {"data missing": 2})
        # records whose day ended before the cutoff go, with their rows and inputs
        gone = store.purge_owner_records(T0 + timedelta(days=2, hours=1))
        assert gone == 2
        assert [n.id for n in store.owner_records()] == [ids[2]]
        assert store.samples(ids[0]) == [] and store.house_inputs(ids[0]) == []
        assert len(store.samples(ids[2])) == 3 and len(store.house_inputs(ids[2])) == 3
        assert [n.id for n in store.nights()] == [nid]  # never an IMP night
        assert store.integrity_check() == "ok"
        # owner rows are committed without fsync; the store's own setting stays FULL
        assert store._db.execute("PRAGMA synchronous").fetchone()[0] == 2


def test_export_writes_owner_records_in_time_order_with_their_labels(tmp_path):
    """``impctl export``: the valid IMP nights and every owner record, sorted by time; an
    owner row's own setpoint, heating and hot-water share; ``--no-owner`` leaves them out;
    the file reads back."""
    import pandas as pd
    from cli_fixtures import run_impctl

    from impctl.imp.files.nights_csv import read_nights

    db = tmp_path / "impctl.db"
    night_start = T0 + timedelta(hours=10)  # 22:00 local, between the two records' rows
    with Store(db) as store:
        for day, labels in ((1, ["owner changed the setpoint: 2187 21.0 → 19.0 °C at 23:05"]),
                            (0, [])):
            start = T0 + timedelta(days=day)
            rid = store.open_owner_record(start, start + timedelta(days=1))
            for i in range(6):
                store.add_owner_row(Sample(
                    rid, start + timedelta(minutes=5 * i), t_air_c=21.0, t_out_c=-1.0,
                    q_hc_w=2000.0 + i, p_el_w=600.0, t_supply_c=35.0, t_return_c=30.0,
                    t_flow_target_c=36.0, setpoint_c=21.0 if i < 3 else 19.0,
                    loop_mode=0 if i == 5 else 1, system_on=1, dhw_share=0.4 if i == 2 else 0.0,
                    defrost=False, snapshots=5))
            # an unread row: missing values are not exported as numbers
            store.add_owner_row(Sample(rid, start + timedelta(minutes=30), snapshots=1))
            store.close_owner_record(rid, labels, 21.0, start, start + timedelta(minutes=35))
        nid = store.create_night("normal", 22.0, night_start, night_start + timedelta(hours=7))
        for i in range(4):
            store.add_sample(Sample(nid, night_start + timedelta(minutes=5 * i), t_air_c=22.0,
                                    t_out_c=-1.0, q_hc_w=2500.0, t_supply_c=38.0,
                                    t_return_c=32.0, t_flow_target_c=38.5, p_el_w=700.0,
                                    dhw_active=i == 1, defrost=False))
        store.end_night(nid, "done", night_start + timedelta(hours=7), True, ["window ended"])

    def export(*extra: str) -> pd.DataFrame:
        out = tmp_path / f"n{len(extra)}.csv"
        res = run_impctl("export", "--db", str(db), "--out", str(out), *extra)
        assert res.returncode == 0, res.stderr
        return pd.read_csv(out, keep_default_na=False)

    df = export()
    for col in ("p_el_w", "t_flow_c", "t_return_c", "t_flow_target_c", "dhw", "label"):
        assert col in df.columns
    assert list(df["kind"]) == ["owner"] * 6 + ["normal"] * 4 + ["owner"] * 6
    stamps = pd.to_datetime(df["timestamp"], format="ISO8601")
    assert stamps.is_monotonic_increasing
    first = df[df["kind"] == "owner"].iloc[:6]
    assert list(first["setpoint"]) == [21.0] * 3 + [19.0] * 3
    assert list(first["heating"]) == [1] * 5 + [0]
    assert list(first["dhw"]) == [0.0, 0.0, 0.4, 0.0, 0.0, 0.0]
    assert set(first["label"]) == {""}
    assert set(df[df["kind"] == "owner"].iloc[6:]["label"]) == {
        "owner changed the setpoint: 2187 21.0 → 19.0 °C at 23:05"}
    imp = df[df["kind"] == "normal"]
    assert list(imp["dhw"]) == [0, 1, 0, 0] and set(imp["t_flow_target_c"]) == {38.5}
    assert set(imp["setpoint"]) == {22.0} and set(imp["label"]) == {""}
    nights = read_nights(tmp_path / "n0.csv", "Europe/Ljubljana")
    assert [n.kind for n in nights] == ["owner", "normal", "owner"]
    assert set(export("--no-owner")["kind"]) == {"normal"}
