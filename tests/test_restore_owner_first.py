"""The owner comes first at the edges of a night: a change between two samples, a mode the
restore could not put back, a stop pressed as a night starts, a curve given back halfway.

Real parts as the rest of the suite: the project's simulator over loopback Modbus TCP, a real
SQLite store, the real controller and the in-process daemon on the virtual-time loop.
"""

from __future__ import annotations

import asyncio
from datetime import timedelta

from test_controller_aborts import Rig, _rig


def _switched_off(rig: Rig):
    def check() -> bool:
        nights = rig.store.nights()
        return bool(nights) and any(s.loop_mode == 0 for s in rig.store.samples(nights[-1].id))
    return check


async def _owner_writes(rig: Rig, ma: int, raw: int) -> None:
    """The owner's thermostat app writes ``ma`` over its own Modbus connection."""
    from daemon_fixtures import modbus_write
    await asyncio.to_thread(modbus_write, rig.sim.port, ma, raw)


def test_a_stop_right_after_an_owner_change_keeps_the_owners_new_value(tmp_path):
    """The owner, cold at night, raises the loop-1 setpoint to 23.5 °C on the controller; a
    stop (SIGTERM, the household's stop button, the hard deadline …) arrives before the next
    sample. The restore reads the register first: neither impctl's value nor the journaled
    one, so the owner's 23.5 °C stays and the entry is closed as theirs."""
    async def body(rig: Rig):
        req = rig.request("constrained")
        task = asyncio.create_task(rig.ctl.run(req))
        from sim_fixtures import wait_for
        await wait_for(_switched_off(rig), 10)
        await _owner_writes(rig, 2187, 235)          # the owner: 23.5 °C
        assert (await rig.sim.read_words(2187))[0] == 235
        rig.ctl.stop.set()                            # SIGTERM before the next sample
        night = await task
        assert night.state == "aborted"
        assert (await rig.sim.read_words(2187))[0] == 235, (
            f"owner's 23.5 °C overwritten by the restore: 2187 = "
            f"{(await rig.sim.read_words(2187))[0]}; journal: "
            f"{[tuple(r) for r in rig.store._db.execute('SELECT register, outcome FROM journal')]}")
    _rig(tmp_path, body)  # one sample every 2 min: the owner's change falls between two


def test_a_night_is_refused_on_an_owner_value_the_restore_could_not_put_back(tmp_path):
    """The owner's loop-1 mode reads as a code impctl does not know (3: a firmware's extra
    mode, or a bit-flag word). The restore would refuse to write 3 back, so a night that
    switched the heating off could not switch it on again: the night is refused before its
    first write, and loop 1 stays as the owner had it."""
    async def body(rig: Rig):
        rig.sim.plant.loop_mode = 3
        rig.sim.rw[2042] = 3
        while (await rig.sim.read_words(2042)) != [3]:
            await asyncio.sleep(0.01)
        night = await rig.ctl.run(rig.request("constrained", preheat_min=5, window_h=1.0))
        mode = (await rig.sim.read_words(2042))[0]
        assert night.state == "refused", (night.state, night.reasons)
        assert "could not put back" in night.reasons[0]
        assert mode == 3, f"2042 = {mode}: the owner's mode was written over"
        assert rig.store.journal_pending() == []
    _rig(tmp_path, body, restore_timeout_s=600.0)


def test_a_stop_pressed_as_a_manual_night_starts_ends_that_night(tmp_path):
    """Home Assistant: "start now" and then "stop" in the same second (or "stop" while the
    night waits for the heat-pump lock the owner recording holds). The stop stays queued until
    the night can take it, and ends it: the heating is never switched off."""
    from reliability_fixtures import daemon_rig, run_virtual

    async def scenario():
        async with daemon_rig(tmp_path, speed=600.0) as rig:
            await rig.sim_minutes(2)
            rig.store.add_request("constrained", 21.0, "now", forced=True)   # "start now" …
            rig.store.add_command("abort", "mqtt")              # … and "stop", same second
            await rig.until(lambda: not rig.store.pending_commands("abort")
                            and not rig.store.pending_requests(), 30)
            await rig.until(lambda: rig.store.nights(), 30)
            night_id = rig.store.nights()[-1].id
            await rig.sim_minutes(20)
            return rig.store.night(night_id), rig.switched_off(night_id), rig.owner_state()

    night, switched_off, owner_state = run_virtual(scenario(), 86400)
    assert not switched_off and night.state != "active", (
        f"the stop was taken but the night runs on: state {night.state}, heating switched "
        f"off {switched_off}, heat pump now {owner_state}")


def test_a_curve_give_back_cut_between_its_two_points_still_gives_both_back(tmp_path):
    """The daemon holds impctl's heating curve (the owner asked for it). A new fit says the
    curve no longer lowers the running one, so the owner's points go back, one register after
    the other: 2309 goes back, the write of 2314 fails (the controller answers exception 4
    once; a lost link alike). The point left pending is given back later, not taken for the
    owner's change of impctl's curve: both of the owner's points are on the heat pump at the
    end."""
    import json
    import struct

    from daemon_fixtures import daemon_mapping
    from impctl_sim import KronotermSimulator, SimConfig, constant_weather
    from reliability_fixtures import MORNING, ModbusProxy, loop_wall, run_virtual
    from sim_fixtures import wait_for

    from impctl.clock import VirtualClock
    from impctl.config import config_from_mapping
    from impctl.daemon.service import Daemon

    class OneRegisterFails(ModbusProxy):
        """Answers FC 06 to one PDU address with exception 4 while ``fail_addr`` is set."""
        fail_addr: int | None = None

        async def _upstream(self, client_r, client_w, server_w, state) -> None:
            while True:
                header = await client_r.readexactly(7)
                length = struct.unpack(">H", header[4:6])[0]
                body = await client_r.readexactly(max(length - 1, 0))
                if (body and body[0] == 6 and self.fail_addr is not None
                        and struct.unpack(">H", body[1:3])[0] == self.fail_addr):
                    client_w.write(header[:4] + struct.pack(">H", 3) + header[6:7]
                                   + bytes([0x86, 4]))
                    await client_w.drain()
                    continue
                server_w.write(header + body)
                await server_w.drain()

    def kept_curve(state, points, lowers=True):
        state.mkdir(parents=True, exist_ok=True)
        (state / "curve.json").write_text(json.dumps({
            "schema": "impctl-curve/1", "lowers": lowers, "advice": "x",
            "recommended": {"t_out_c": [-15.0, 15.0], "flow_c": list(points),
                            "flow_at_0_c": sum(points) / 2}}))

    async def scenario():
        from daemon_fixtures import HEAVY_HOUSE, OWNER_SETPOINT_C
        clock = VirtualClock(MORNING, 600.0, wall=loop_wall())
        sim = KronotermSimulator(SimConfig(clock=clock, house=HEAVY_HOUSE,
                                           weather=constant_weather(0.0),
                                           setpoint_c=OWNER_SETPOINT_C))
        await sim.start()
        proxy = OneRegisterFails(sim.port)
        await proxy.start()
        state = tmp_path / "state"
        owner = (sim.rw[2309], sim.rw[2314])
        want = (owner[0] - 40, owner[1] - 20)
        kept_curve(state, (want[0] / 10, want[1] / 10))
        daemon = Daemon(config_from_mapping(daemon_mapping(
            state, proxy.port, clock, curve={"apply": True},
            night={"sample_interval_s": 60})), clock=clock)
        task = asyncio.create_task(daemon.run())
        try:
            await wait_for(lambda: (sim.rw[2309], sim.rw[2314]) == want
                           and daemon.curve is not None and daemon.curve.held is not None
                           and daemon.curve._verify is None, 30)       # set and followed
            proxy.fail_addr = 2314 - 1
            kept_curve(state, (want[0] / 10, want[1] / 10), lowers=False)  # a new fit
            await wait_for(lambda: sim.rw[2309] == owner[0], 30)           # 2309 back
            end = clock.now() + timedelta(minutes=10)
            await wait_for(lambda: clock.now() >= end, 30)
            proxy.fail_addr = None                                         # all good again
            end = clock.now() + timedelta(minutes=10)
            await wait_for(lambda: clock.now() >= end, 30)
            daemon.stop.set()          # a clean stop gives every pending entry back
            await asyncio.wait_for(task, 30)
            from impctl.store import Store
            with Store(state / "impctl.db") as store:
                journal = [tuple(r) for r in store._db.execute(
                    "SELECT register, raw_value, outcome FROM journal")]
            return owner, want, (sim.rw[2309], sim.rw[2314]), journal
        finally:
            daemon.stop.set()
            await asyncio.wait_for(task, 30)
            await proxy.stop()
            await sim.stop()

    owner, want, points, journal = run_virtual(scenario(), 86400)
    assert points == owner, (f"owner's curve {owner}, impctl's {want}; after the daemon's "
                             f"stop the heat pump is left at {points}; journal {journal}")
