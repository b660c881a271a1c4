"""Each simulator fault, seen through the project's client over loopback TCP."""

from __future__ import annotations

import asyncio
import struct

import pytest
from impctl_sim import SimConfig, parse_faults
from impctl_sim.faults import DEFAULT_GREETING
from sim_fixtures import client, clock, link_config, raw_exchange, run, simulator, wait_for
from umodbus.client import tcp

from impctl.heatpump import ModbusDeviceError, ModbusLinkError


def test_drop_fault_then_recovery():
    async def body():
        async with simulator() as sim, client(sim) as hp:
            assert not (await hp.read("t_outdoor")).missing
            sim.faults.drop = True
            with pytest.raises(ModbusLinkError):
                await hp.read("t_outdoor")
            assert sim.stats.dropped >= 2  # every attempt was dropped
            sim.faults.drop = False
            assert not (await hp.read("t_outdoor")).missing  # reconnected by the client
            assert hp.link.stats.connects >= 2
    run(body())


def test_connections_dropped_between_polls_are_reestablished():
    async def body():
        async with simulator() as sim, client(sim) as hp:
            await hp.snapshot()
            assert sim.drop_connections() == 1
            await asyncio.sleep(0.05)
            snap = await hp.snapshot()
            assert snap.missing() == {} and hp.link.stats.connects == 2
    run(body())


def test_delay_longer_than_timeout_fails_shorter_succeeds():
    async def body():
        async with simulator() as sim:
            link = link_config(sim.port, timeout_s=0.2, attempts=1)
            async with client(sim, link=link) as hp:
                sim.faults.delay_s = 0.5
                with pytest.raises(ModbusLinkError, match="failed"):
                    await hp.read("t_outdoor")
                sim.faults.delay_s = 0.05
                await asyncio.sleep(0.5)  # let the abandoned answer arrive and be discarded
                reading = await hp.read("t_outdoor")
                assert not reading.missing
    run(body())


def test_timed_out_write_is_not_resent():
    async def body():
        async with simulator() as sim:
            link = link_config(sim.port, timeout_s=0.2, retries=2, attempts=1)
            async with client(sim, link=link, generation="extended") as hp:
                sim.faults.delay_s = 0.3
                with pytest.raises(ModbusLinkError):
                    await hp.link.write(2186, 190)  # PDU address of 2187
                await asyncio.sleep(0.5)  # the delayed request is processed meanwhile
                assert sim.stats.writes[2187] == 1  # pymodbus alone would have sent it 3×
                sim.faults.delay_s = 0.0
                assert (await hp.read(2187)).value == 19.0
    run(body())


def test_exception_code_fault():
    async def body():
        async with simulator() as sim, client(sim) as hp:
            sim.faults.exception_code = 6  # device busy
            with pytest.raises(ModbusDeviceError) as info:
                await hp.read("t_outdoor")
            assert info.value.exception_code == 6 and info.value.address == 2102
            snap = await hp.snapshot()  # exception blocks become missing, not an exception
            assert set(snap.missing().values()) == {"Modbus exception 6"}
            assert snap.t_air_c.value is None and snap.q_hc_w.value is None
            # busy is transient: every block was tried `attempts` (2) times
            assert hp.link.stats.transient_exceptions == 2 * hp.link.stats.failures
            sim.faults.exception_code = 2  # illegal address is final: never retried
            retries = hp.link.stats.retries
            with pytest.raises(ModbusDeviceError) as info:
                await hp.read("t_outdoor")
            assert info.value.exception_code == 2 and hp.link.stats.retries == retries
    run(body())


def test_greeting_bytes_are_sent_and_drained():
    async def body():
        config = SimConfig(clock=clock(), faults=parse_faults("greeting"))
        async with simulator(config) as sim:
            adu = tcp.read_holding_registers(20, 2102, 1)
            raw = await raw_exchange(sim.port, adu)
            assert raw.startswith(DEFAULT_GREETING)  # the gateway greets before answering
            async with client(sim) as hp:
                assert hp.link.stats.drained_bytes == len(DEFAULT_GREETING)
                snap = await hp.snapshot()
                assert snap.missing() == {} and hp.link.stats.retries == 0
    run(body())


def test_late_greeting_desynchronises_a_client_without_drain():
    async def body():
        # The gateway greets 50 ms after connect, while the first answer is still 200 ms away.
        faults = parse_faults("greeting,greeting-delay=0.05,delay=0.2")
        async with simulator(SimConfig(clock=clock(), faults=faults)) as sim:
            naive = link_config(sim.port, drain_s=0.0, timeout_s=0.5, attempts=1)
            async with client(sim, link=naive, generation="extended") as hp:
                with pytest.raises(ModbusLinkError):
                    await hp.read("t_outdoor")
            drained = link_config(sim.port, drain_s=0.1, timeout_s=0.5, attempts=1)
            async with client(sim, link=drained, generation="extended") as hp:
                assert not (await hp.read("t_outdoor")).missing
                assert hp.link.stats.drained_bytes == len(DEFAULT_GREETING)
    run(body())


def test_fixed_transaction_id_needs_tolerance():
    async def body():
        async with simulator(SimConfig(clock=clock(), plant_kind="iso")) as sim:
            sim.faults.fixed_tid = 20
            adu = bytearray(tcp.read_holding_registers(20, 2102, 1))
            adu[0:2] = (0x1234).to_bytes(2, "big")
            raw = await raw_exchange(sim.port, bytes(adu))
            assert struct.unpack(">H", raw[:2])[0] == 20  # the quirk, on the wire
            strict = link_config(sim.port, timeout_s=0.2, attempts=1)
            async with client(sim, link=strict, generation="extended") as hp:
                with pytest.raises(ModbusLinkError):
                    await hp.read("t_outdoor")
            tolerant = link_config(sim.port, tolerate_fixed_tid=True)
            async with client(sim, link=tolerant) as hp:
                for _ in range(3):  # not only the first response
                    snap = await hp.snapshot()
                    assert snap.missing() == {}
                assert snap.t_out_c.value == pytest.approx(round(sim.plant.t_out_c, 1), abs=0.2)
    run(body())


def test_freeze_keeps_registers_stale_while_the_model_runs():
    async def body():
        async with simulator() as sim, client(sim) as hp:
            sim.faults.freeze = True
            before = await hp.snapshot()
            energy = sim.plant.e_th_kwh
            await wait_for(lambda: sim.plant.e_th_kwh > energy + 0.5)
            during = await hp.snapshot()
            assert during.energy_thermal_kwh.value == before.energy_thermal_kwh.value
            assert during.t_air_c.raw == before.t_air_c.raw
            assert during.timestamp > before.timestamp
            published = sim.stats.publishes
            sim.faults.freeze = False
            await wait_for(lambda: sim.stats.publishes > published)
            after = await hp.snapshot()
            assert after.energy_thermal_kwh.value >= before.energy_thermal_kwh.value + 0.4
    run(body())


def test_fault_syntax_round_trip():
    text = ("drop,delay=2.5,exception=6,greeting=0102,greeting-delay=0.1,fixed-tid=20,freeze,"
            "missing=2103:2160,ignore-writes")
    faults = parse_faults(text)
    assert faults.missing_sensors == {2103, 2160} and faults.greeting == b"\x01\x02"
    assert parse_faults(faults.describe()) == faults
    assert parse_faults("none").describe() == "none"
    for bad in ("delay=x", "exception=99", "explode", "missing=abc"):
        with pytest.raises(Exception, match="bad fault"):
            parse_faults(bad)
