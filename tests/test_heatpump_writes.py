"""Safe writes over loopback TCP: clamping, compare-before-write, read-back, budget, whitelist."""

from __future__ import annotations

import logging

import pytest
from impctl_sim import SimConfig
from sim_fixtures import (
    budget,
    client,
    clock,
    hp_config,
    in_thread,
    run,
    simulator,
    umodbus_call,
)
from umodbus.client import tcp

from impctl.clock import VirtualClock
from impctl.heatpump import (
    HeatPumpClient,
    ModbusDeviceError,
    WriteBudgetExceeded,
    WritePolicy,
    WriteRefused,
    WriteVerifyError,
)

POLICY = WritePolicy(loop1_setpoint_c=(16.0, 23.0), daily_budget=5, verify_delay_s=0.01,
                     verify_attempts=2)


def sim_config() -> SimConfig:
    return SimConfig(clock=clock(1.0))


def test_setpoint_is_clamped_to_the_configured_limits(tmp_path):
    async def body():
        async with simulator(sim_config()) as sim, \
                client(sim, budget=budget(tmp_path), writes=POLICY) as hp:
            low = await hp.set_loop1_setpoint(12.0)
            assert low.clamped and low.target == 16.0 and low.written
            assert sim.plant.setpoint_c == 16.0
            high = await hp.set_loop1_setpoint(35.0)
            assert high.clamped and high.target == 23.0 and sim.plant.setpoint_c == 23.0
            words = await in_thread(umodbus_call, sim.port,
                                    tcp.read_holding_registers(20, 2186, 1))
            assert words == [230]
    run(body())


def test_unchanged_value_is_not_written(tmp_path):
    async def body():
        wb = budget(tmp_path)
        async with simulator(sim_config()) as sim, client(sim, budget=wb, writes=POLICY) as hp:
            result = await hp.set_loop1_setpoint(21.0)  # the simulator starts at 21.0
            assert not result.written and result.read_back == 21.0
            again = await hp.set_loop1_mode(1)
            assert not again.written
            assert sim.stats.writes == {}  # no FC 06 reached the device
            day = hp.clock.now().date()
            assert wb.used(2187, day) == 0 and wb.used(2042, day) == 0
            assert (await hp.set_loop1_setpoint(21.04)).written is False  # same 0.1 °C word
    run(body())


def test_mode_write_switches_heating_off(tmp_path, caplog):
    async def body():
        async with simulator(sim_config()) as sim, \
                client(sim, budget=budget(tmp_path), writes=POLICY) as hp:
            assert sim.plant.heating_enabled
            with caplog.at_level(logging.WARNING, logger="impctl.heatpump.writes"):
                result = await hp.set_loop1_mode(0)
                await hp.set_loop1_setpoint(22.5)
            assert result.written and result.previous == 1 and result.read_back == 0
            assert not sim.plant.heating_enabled and sim.stats.writes[2042] == 1
    run(body())
    # Modes are codes, logged as people write them; setpoints keep their unit.
    assert "(loop1_mode): 1 → 0 written and verified" in caplog.text
    assert "(loop1_setpoint): 21.0 °C → 22.5 °C written and verified" in caplog.text


def test_read_back_mismatch_raises(tmp_path, caplog):
    async def body():
        wb = budget(tmp_path)
        async with simulator(sim_config()) as sim, client(sim, budget=wb, writes=POLICY) as hp:
            sim.faults.ignore_writes = True  # the device acknowledges but keeps 21.0
            with caplog.at_level(logging.ERROR), pytest.raises(WriteVerifyError) as info:
                await hp.set_loop1_setpoint(18.0)
            assert info.value.ma == 2187 and info.value.written == 180
            assert info.value.read_back == 210
            assert "read back 21.0" in caplog.text
            assert sim.plant.setpoint_c == 21.0
            # The echo carried the old value (not an answer to this write) and the read-back
            # shows the register unchanged: the write did not execute and is not counted.
            assert wb.used(2187, hp.clock.now().date()) == 0
            assert hp.link.stats.unattributable == 1
    run(body())


def test_daily_budget_refuses_loudly_and_sends_nothing(tmp_path, caplog):
    class Wall:
        now = 1_800_000_000.0

        def __call__(self):
            return self.now

    async def body():
        wall = Wall()
        wb = budget(tmp_path, daily=2)
        async with simulator(sim_config()) as sim, client(sim, budget=wb, writes=POLICY) as hp:
            # The client counts days on its own clock; this one is moved by hand.
            hp.clock = VirtualClock(hp.clock.now(), 1.0, wall.now, wall=wall)
            await hp.set_loop1_setpoint(18.0)
            await hp.set_loop1_setpoint(19.0)
            requests = sim.stats.requests
            with caplog.at_level(logging.ERROR), pytest.raises(WriteBudgetExceeded):
                await hp.set_loop1_setpoint(20.0)
            assert "write budget exhausted for register 2187" in caplog.text
            assert sim.stats.writes[2187] == 2 and sim.plant.setpoint_c == 19.0
            assert sim.stats.requests == requests + 1  # only the compare-before-write read
            await hp.set_loop1_mode(0)  # another register has its own budget
            wall.now += 86400.0
            assert (await hp.set_loop1_setpoint(20.0)).written
            assert wb.lifetime(2187) == 3
    run(body())


def test_writes_outside_the_whitelist_send_nothing(tmp_path):
    async def body():
        async with simulator(sim_config()) as sim, \
                client(sim, budget=budget(tmp_path), writes=POLICY) as hp:
            requests = sim.stats.requests
            for ma, value in ((2018, 1), (2113, 0), (2017, 1), (2197, 1), (2049, 20.0),
                              (2014, 1), (2012, 0), (2103, 5.0)):
                with pytest.raises(WriteRefused):
                    await hp.write(ma, value)
            with pytest.raises(WriteRefused, match="only"):
                await hp.set_loop1_mode(3)
            assert sim.stats.requests == requests and sim.stats.writes == {}
    run(body())


def test_loop2_and_correction_when_configured(tmp_path):
    policy = WritePolicy(loop2_setpoint_c=(16.0, 22.0), correction_k=(-2, 2),
                         verify_delay_s=0.01)

    async def body():
        async with simulator(sim_config()) as sim, \
                client(sim, budget=budget(tmp_path), writes=policy) as hp:
            assert (await hp.write(2049, 25.0)).target == 22.0
            corr = await hp.write("temp_correction", -4)
            assert corr.clamped and corr.target == -2.0 and sim.plant.correction_k == -2
            assert sim.plant.room_setpoint_c == 19.0
            words = await in_thread(umodbus_call, sim.port,
                                    tcp.read_holding_registers(20, 2013, 1))
            assert words == [0xFFFE]  # −2 as int16 on the wire
    run(body())


def test_without_budget_writes_are_refused():
    async def body():
        async with simulator(sim_config()) as sim, client(sim, writes=POLICY) as hp:
            with pytest.raises(WriteRefused, match="no write budget"):
                await hp.set_loop1_setpoint(18.0)
            assert sim.stats.writes == {}
    run(body())


def test_device_exception_on_write_is_not_retried(tmp_path):
    async def body():
        async with simulator(sim_config()) as sim, \
                client(sim, budget=budget(tmp_path), writes=POLICY) as hp:
            await hp.read(2187)
            sim.faults.exception_code = 4
            with pytest.raises(ModbusDeviceError) as info:
                await hp.set_loop1_setpoint(18.0)  # fails already at the compare read
            assert info.value.exception_code == 4
            assert sim.stats.writes == {}
    run(body())


def test_simulator_rejects_what_the_controller_would(tmp_path):
    from umodbus.exceptions import IllegalDataAddressError, IllegalDataValueError

    async def body():
        async with simulator(sim_config()) as sim:
            with pytest.raises(IllegalDataAddressError):  # outdoor temperature is read-only
                await in_thread(umodbus_call, sim.port, tcp.write_single_register(20, 2102, 1))
            with pytest.raises(IllegalDataValueError):  # loop mode 7 does not exist
                await in_thread(umodbus_call, sim.port, tcp.write_single_register(20, 2041, 7))
            assert sim.stats.writes == {} and sim.plant.loop_mode == 1
    run(body())


def test_client_can_be_used_without_context_manager(tmp_path):
    async def body():
        async with simulator(sim_config()) as sim:
            hp = HeatPumpClient(hp_config(sim.port, writes=POLICY, generation="extended"),
                                clock=sim.clock, budget=budget(tmp_path))
            result = await hp.set_loop1_setpoint(17.0)  # connects lazily on first request
            assert result.written and hp.link.stats.connects == 1
            hp.close()
    run(body())


def test_restore_puts_back_the_owners_value_unclamped(tmp_path):
    async def body():
        async with simulator(SimConfig(clock=clock(1.0), setpoint_c=24.5)) as sim, \
                client(sim, budget=budget(tmp_path), writes=POLICY) as hp:
            owner = await hp.read(2187)  # what a journal would hold: raw 245
            assert owner.raw == 245
            assert (await hp.set_loop1_setpoint(18.0)).target == 18.0
            result = await hp.restore_raw(2187, owner.raw)
            assert result.written and not result.clamped and result.read_back == 24.5
            assert sim.plant.setpoint_c == 24.5  # outside the 16–23 °C experiment limits
            for ma, raw in ((2018, 0), (2113, 0), (2187, -600), (2187, 2000), (2042, 5)):
                with pytest.raises(WriteRefused):
                    await hp.restore_raw(ma, raw)
            assert sim.stats.writes[2187] == 2 and sim.stats.writes[2018] == 0
    run(body())


def test_restore_may_use_a_small_reserve_beyond_the_budget(tmp_path, caplog):
    policy = WritePolicy(daily_budget=1, restore_reserve=1, verify_delay_s=0.01)

    async def body():
        async with simulator(sim_config()) as sim, \
                client(sim, budget=budget(tmp_path, daily=1), writes=policy) as hp:
            await hp.set_loop1_setpoint(18.0)
            with pytest.raises(WriteBudgetExceeded):
                await hp.set_loop1_setpoint(19.0)
            with caplog.at_level(logging.ERROR):
                assert (await hp.restore_raw(2187, 210)).written  # heating back to the owner's
            assert "restore reserve" in caplog.text and sim.plant.setpoint_c == 21.0
            await hp.set_loop1_mode(0)
            with pytest.raises(WriteBudgetExceeded, match=r"\+1 reserve"):
                await hp.restore_raw(2187, 200)  # the reserve is bounded too
    run(body())


def test_the_curve_points_are_written_only_when_allowed_and_always_restorable(tmp_path):
    """2309/2314 are no register impctl writes by default; while the owner has impctl's
    curve set (``loop1_curve_c``) they are clamped to 20–55 °C — up to the owner's own point
    where that is higher — and read back, and the owner's points go back whatever the
    configuration; the adaptive-curve switch 2320 is never
    written. The simulated controller runs the points it is given."""
    from dataclasses import replace

    from impctl_sim import SimConfig as Sim

    async def body():
        wb = budget(tmp_path)
        async with simulator(Sim(clock=clock(1.0), plant_kind="realistic")) as sim, \
                client(sim, budget=wb, writes=POLICY) as hp:
            owner = (await hp.read(2309)).value
            owner_mild = (await hp.read(2314)).value
            with pytest.raises(WriteRefused, match="not in the write whitelist"):
                await hp.write(2309, 40.0)
            with pytest.raises(WriteRefused):
                await hp.write(2320, 0)
            hp.config = replace(hp.config, writes=replace(POLICY, loop1_curve_c=(20.0, 55.0)))
            high = await hp.write(2309, 70.0)
            assert high.clamped and high.target == 55.0 and high.read_back == 55.0
            low = await hp.write(2314, 10.0)
            assert low.clamped and low.target == 20.0
            assert sim.plant.core.core.controller.flow_curve_set[0]  # the controller runs them
            with pytest.raises(WriteRefused):
                await hp.write(2320, 1)
            # the owner's own point above 55 °C raises that point's ceiling, and only its
            hp.config = replace(hp.config, writes=replace(
                POLICY, loop1_curve_c=(20.0, 55.0), loop1_curve_owner_c=(62.0, 30.0)))
            own = await hp.write(2309, 60.0)
            assert not own.clamped and own.read_back == 60.0
            assert (await hp.write(2309, 64.0)).target == 62.0
            assert (await hp.write(2314, 58.0)).target == 55.0
            hp.config = replace(hp.config, writes=POLICY)  # the owner took the curve back
            back = await hp.restore(2309, owner)
            assert back.written and back.read_back == owner
            await hp.restore(2314, owner_mild)
            assert not sim.plant.core.core.controller.flow_curve_set[0]  # its own curve
    run(body())
