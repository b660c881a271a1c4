"""Writes whose outcome impctl cannot know, and the owner's values put back from outside.

Real parts: the in-process daemon, the ``impctl_sim`` simulator, the tests' TCP proxy on
loopback, a real SQLite store; one accelerated clock on the event loop (:func:`run_virtual`).

What is promised:

* a write that may have landed but was never read back (the link dropped right after it) is
  not taken for the owner's: when the link is back the owner's values go back on, and the
  experiment's value is never "kept as the owner's change";
* ``impctl restore`` run while a constrained night preheats puts the owner's values back, and
  the night then does not switch the heating off: it ends without a write;
* a store that can no longer be read mid-night (the card returns garbage) does not keep the
  heating off: the night restores from the copy of the owner's values kept beside it.
"""

from __future__ import annotations

import os
from datetime import timedelta

from reliability_fixtures import OWNER_SETPOINT_C, QUICK_LINK, daemon_rig, run_virtual

from impctl.controller import restore_all
from impctl.daemon.configured import open_client
from impctl.store import Store
from impctl.store.restore.owner_file import read_owner_values

SPEED = 600.0
LINK = {**QUICK_LINK, "writes": {"verify_delay_s": 0.0}}
OWNER = (OWNER_SETPOINT_C, 1)


def test_a_switch_off_that_landed_without_a_read_back_is_restored(tmp_path):
    async def body():
        async with daemon_rig(tmp_path, speed=SPEED, heatpump=LINK) as rig:
            nid = await rig.trigger("constrained")
            await rig.until(lambda: rig.sim.plant.setpoint_c == 22.5)  # preheat at T_max
            rig.proxy.set("down-after-write")   # the next write is the switch-off
            await rig.until(lambda: rig.proxy.mode == "down", 30)
            assert rig.sim.plant.loop_mode == 0  # the heat pump took it
            await rig.sim_minutes(30)             # the link stays down half an hour
            rig.proxy.set("pass")
            await rig.until(lambda: rig.night(nid).valid is not None, 30)
            night = rig.night(nid)
            assert night.state == "aborted"
            assert "read back nothing" in night.reasons[0], night.reasons
            assert rig.owner_state() == OWNER
            assert rig.store.journal_pending() == []
            assert not any("owner's value kept" in line for line in rig.logs.lines())
    run_virtual(body(), 120)


def test_impctl_restore_during_the_preheat_leaves_the_heating_on(tmp_path):
    async def body():
        async with daemon_rig(tmp_path, speed=SPEED, heatpump=LINK,
                              night={"sample_interval_s": 300}) as rig:
            nid = await rig.trigger("constrained")
            req = rig.night(nid)
            await rig.until(lambda: rig.sim.plant.setpoint_c == 22.5)
            # after the last preheat sample, before the switch-off's tick
            await rig.until(lambda: rig.clock.now() >= req.window_start + timedelta(seconds=30))
            assert rig.sim.plant.loop_mode == 1
            writes = sum(rig.sim.stats.writes.values())
            # what `impctl restore` does: its own store connection and heat-pump client
            cfg = rig.daemon.cfg
            hp = open_client(cfg, rig.clock)
            await hp.connect(max_wait_s=5.0)
            try:
                with Store(cfg.db_path, create=False) as other:
                    assert await restore_all(hp, other, clock=rig.clock, timeout_s=60.0,
                                             retry_s=1.0) == []
            finally:
                hp.close()
            assert rig.owner_state() == OWNER
            restored = sum(rig.sim.stats.writes.values())
            assert restored == writes + 1  # the setpoint back; the mode was never changed
            await rig.until(lambda: rig.night(nid).valid is not None, 30)
            night = rig.night(nid)
            assert night.state == "aborted"
            assert "put back from outside" in night.reasons[0], night.reasons
            assert rig.owner_state() == OWNER
            assert sum(rig.sim.stats.writes.values()) == restored  # no switch-off, no more
    run_virtual(body(), 120)


def test_a_store_that_cannot_be_read_mid_night_restores_from_its_copy(tmp_path):
    async def body():
        async with daemon_rig(tmp_path, speed=SPEED, heatpump=LINK) as rig:
            nid = await rig.trigger("constrained")
            await rig.until(lambda: rig.sim.plant.loop_mode == 0)
            await rig.until(lambda: rig.store.sample_count(nid) >= 3)
            copy = rig.daemon.store.owner_file
            assert copy.exists()
            # The card returns garbage: every page of the database, its WAL and index.
            db = rig.daemon.cfg.db_path
            for path in (db, db.with_name(db.name + "-wal"), db.with_name(db.name + "-shm")):
                if path.exists():
                    with open(path, "r+b") as f:
                        f.write(b"\0" * os.path.getsize(path))
            await rig.until(lambda: rig.owner_state() == OWNER, 30)
            assert read_owner_values(copy)[0] == []  # every entry back and verified
            assert any("restoring from" in line for line in rig.logs.lines())
    run_virtual(body(), 120)
