"""The SQLite store on a real file: migrations, WAL, durability across processes, journal rules."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
from datetime import UTC, datetime, timedelta

import pytest

from impctl.errors import InputError
from impctl.store import SCHEMA_VERSION, Sample, Store

T0 = datetime(2026, 1, 12, 21, 0, tzinfo=UTC)


def test_new_store_is_wal_and_at_current_schema(tmp_path):
    with Store(tmp_path / "state" / "impctl.db") as store:
        assert store.schema_version == SCHEMA_VERSION
        assert store.integrity_check() == "ok"
    con = sqlite3.connect(tmp_path / "state" / "impctl.db")
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_newer_schema_is_refused_clearly(tmp_path):
    path = tmp_path / "impctl.db"
    Store(path).close()
    con = sqlite3.connect(path)
    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    con.close()
    with pytest.raises(InputError, match="newer than this impctl"):
        Store(path)


def test_garbage_file_is_refused(tmp_path):
    path = tmp_path / "impctl.db"
    path.write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(InputError, match="not a usable impctl database"):
        Store(path)


def test_night_lifecycle_and_samples(tmp_path):
    with Store(tmp_path / "db") as store:
        nid = store.create_night("constrained", 22.0, T0, T0 + timedelta(hours=7),
                                 t_min_c=20.5, t_max_c=23.5)
        store.set_night_state(nid, "active", started=T0)
        for i in range(3):
            store.add_sample(Sample(nid, T0 + timedelta(minutes=i), t_air_c=23.0 - 0.1 * i,
                                    t_out_c=-2.5, q_hc_w=None, defrost=False))
        store.set_night_state(nid, "done", ended=T0 + timedelta(hours=1))
        store.assess_night(nid, False, ["coverage 14 % < 80 %"])
        night = store.night(nid)
        assert night.state == "done" and night.valid is False
        assert night.reasons == ("coverage 14 % < 80 %",)
        assert night.started == T0 and night.window_end == T0 + timedelta(hours=7)
        samples = store.samples(nid)
        assert [s.t_air_c for s in samples] == pytest.approx([23.0, 22.9, 22.8])
        assert samples[0].q_hc_w is None and samples[0].defrost is False
        assert store.nights(states=["done"], valid=False)[0].id == nid
        assert store.nights(states=["active"]) == []


def test_an_interrupted_night_is_never_seen_without_its_verdict(tmp_path):
    """The orphan sweep's two updates are one transaction: a second connection, which reads
    only committed data, sees either neither or both."""
    with Store(tmp_path / "db") as store, Store(tmp_path / "db") as reader:
        nid = store.create_night("normal", 22.0, T0, T0 + timedelta(hours=7))
        store.set_night_state(nid, "active", started=T0)
        seen = []
        real = store.assess_night

        def assess_and_look(*args, **kwargs):
            seen.append((reader.night(nid).state, reader.night(nid).valid))  # between the two
            return real(*args, **kwargs)

        store.assess_night = assess_and_look
        store.interrupt_night(nid, "interrupted: impctl stopped during the night")
        assert seen == [("active", None)]   # the state was not yet visible on its own
        night = reader.night(nid)
        assert (night.state, night.valid) == ("interrupted", False)
        assert night.reasons == ("interrupted: impctl stopped during the night",)


def test_samples_survive_a_killed_writer(tmp_path):
    """Every sample is committed as it is taken: SIGKILL right after the last insert."""
    path = tmp_path / "db"
    Store(path).close()
    code = f"""
import os, signal
from datetime import datetime, timedelta, UTC
from impctl.store import Store, Sample
s = Store({str(path)!r})
t0 = datetime(2026, 1, 12, 21, 0, tzinfo=UTC)
nid = s.create_night("normal", 23.0, t0, t0 + timedelta(hours=7))
for i in range(50):
    s.add_sample(Sample(nid, t0 + timedelta(minutes=i), t_air_c=23.0))
os.kill(os.getpid(), signal.SIGKILL)
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True)
    assert proc.returncode == -9
    with Store(path) as store:
        assert store.integrity_check() == "ok"
        night = store.nights()[0]
        assert store.sample_count(night.id) == 50


def test_journal_keeps_the_owners_value_until_restored(tmp_path):
    with Store(tmp_path / "db") as store:
        first = store.journal_record(None, "loop1_setpoint", 2186, 215)
        # A second night before the restore was confirmed must not overwrite the owner's value
        # with impctl's own write.
        again = store.journal_record(None, "loop1_setpoint", 2186, 235)
        assert again.id == first.id and again.raw_value == 215
        assert [e.register for e in store.journal_pending()] == ["loop1_setpoint"]
        store.journal_mark_restored(first.id)
        assert store.journal_pending() == []
        fresh = store.journal_record(None, "loop1_setpoint", 2186, 220)
        assert fresh.id != first.id and fresh.raw_value == 220


def test_what_impctl_holds_is_kept_beside_the_entry_and_its_copy(tmp_path):
    """What impctl last wrote and read back is kept beside the pending entry, in the store
    and in owner-values.json alike; given up before a write (the copy follows: a copy that
    still claimed it would keep a value impctl wrote unseen as the owner's); a new night's
    journal says what the register holds now."""
    from impctl.store.restore.owner_file import read_owner_values

    def copied() -> dict[str, int | None]:
        return {e.register: e.confirmed_raw for e in read_owner_values(store.owner_file)[0]}

    with Store(tmp_path / "db") as store, Store(tmp_path / "db") as other:
        entry = store.journal_record(None, "loop1_setpoint", 2186, 210, confirmed_raw=210)
        assert entry.confirmed_raw == 210 and copied() == {"loop1_setpoint": 210}
        store.journal_confirm(entry.id, None)                 # before a write
        assert other.journal_confirmed(entry.id) is None and copied() == {"loop1_setpoint": None}
        store.journal_confirm(entry.id, 225)                  # read back
        assert other.journal_pending()[0].confirmed_raw == 225
        assert copied() == {"loop1_setpoint": 225}
        again = store.journal_record(None, "loop1_setpoint", 2186, 230, confirmed_raw=230)
        assert (again.id, again.raw_value, again.confirmed_raw) == (entry.id, 210, 230)
        store.journal_mark_restored(entry.id)
        store.journal_confirm(entry.id, 240)                  # a closed entry claims nothing
        assert other.journal_confirmed(entry.id) == 230 and copied() == {}
        curve = store.journal_record(None, "loop1_curve_cold", 2308, 400)
        assert curve.confirmed_raw is None and copied() == {"loop1_curve_cold": None}


def test_trigger_requests_are_taken_once(tmp_path):
    with Store(tmp_path / "db") as a, Store(tmp_path / "db") as b:
        rid = a.add_request("normal", 23.0, "now")
        pending = b.pending_requests()
        assert [(r.id, r.kind, r.setpoint_c, r.when) for r in pending] == [
            (rid, "normal", 23.0, "now")]
        assert b.take_request(rid) is True
        assert a.take_request(rid) is False
        assert a.pending_requests() == []


def test_campaign_plan_links_and_keeps_links(tmp_path):
    with Store(tmp_path / "db") as store:
        plan = [("constrained", 22.0), ("normal", 22.0), ("normal", 23.0)]
        store.set_campaign(plan)
        nid = store.create_night("constrained", 22.0, T0, T0 + timedelta(hours=7))
        store.assess_night(nid, True, [])
        store.link_campaign(0, nid)
        store.set_campaign(plan + [("normal", 24.0)])
        rows = store.campaign()
        assert rows[0] == (0, "constrained", 22.0, nid, True)
        assert [r[3] for r in rows[1:]] == [None, None, None]


def test_fits_and_events(tmp_path):
    with Store(tmp_path / "db") as store:
        assert store.last_fit() is None
        store.add_fit([1, 2], {"lumped": {"hlc": {"value": 180.0}}})
        created, nights, result = store.last_fit()
        assert nights == [1, 2] and result["lumped"]["hlc"]["value"] == 180.0
        store.add_event("warning", "link lost")
        assert store.events()[0][1:] == ("warning", "link lost")
