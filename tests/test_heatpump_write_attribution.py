"""A safe write's own reads on an RTU line shared with another master: the compare before
the write and the read-back after it take an answer only when it can be attributed to its
request, as every other read does; a read-back that cannot be is "not verified", never a
value claimed as written.

Real pymodbus on both sides, RTU framing over ``socket://``. The simulator's registers are
frozen, so each register has one true value. The other master's answer is scripted here: it
crosses impctl's FC 03 reads and carries the word impctl writes (the other master reads a
register that holds the same value), so a misattributed answer looks exactly right.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Callable

import pytest
from impctl_sim import KronotermSimulator, SimConfig, constant_weather, parse_faults
from pymodbus.pdu import ModbusPDU
from pymodbus.pdu.register_message import ReadHoldingRegistersResponse
from sim_fixtures import budget, client, clock, free_port, run
from sim_fixtures import simulator as started

from impctl.controller.held import Held
from impctl.heatpump import (
    HeatPumpClient,
    HeatPumpConfig,
    LinkConfig,
    ModbusLinkError,
    WritePolicy,
    WriteVerifyError,
)
from impctl.kronoterm.decode import encode
from impctl.kronoterm.registers import register

SETPOINT = 2187
#: The other master's answer comes first; the real one follows 0.08 s later — inside the
#: 2 × timeout a settle waits for, past the link's own 0.02 s settle_s.
LATE_S = 0.08


def _sim() -> KronotermSimulator:
    return KronotermSimulator(SimConfig(clock=clock(1.0), faults=parse_faults("freeze"),
                                        weather=constant_weather(-5.0), seed=3))


@contextlib.asynccontextmanager
async def _on_rtu(tmp_path) -> AsyncIterator[tuple[KronotermSimulator, HeatPumpClient]]:
    """A frozen simulator on RTU over ``socket://`` and a client connected to it; both
    stopped when done."""
    sim = _sim()
    try:
        hp = await _rtu(sim, tmp_path)
        try:
            yield sim, hp
        finally:
            hp.close()
    finally:
        await sim.stop()


async def _rtu(sim: KronotermSimulator, tmp_path) -> HeatPumpClient:
    port = free_port()
    await sim.start(rtu=f"socket://127.0.0.1:{port}")
    link = LinkConfig(transport="rtu", serial_port=f"socket://127.0.0.1:{port}",
                      timeout_s=0.1, attempts=4, retry_delay_s=0.01, drain_s=0.01,
                      connect_backoff_s=(0.02, 0.1), settle_s=0.02)
    hp = HeatPumpClient(HeatPumpConfig(link=link, writes=WritePolicy(verify_delay_s=0.01)),
                        clock=sim.clock, budget=budget(tmp_path))
    await hp.connect(max_wait_s=5)
    return hp


def _other_master(sim: KronotermSimulator, word: int,
                  crosses: Callable[[int, int], bool]) -> None:
    """Script the simulator's ``foreign`` fault: before the n-th FC 03 answer (counting from
    1; ``writes`` FC 06 requests seen so far) another master's answer carrying ``word``
    crosses the line when ``crosses(n, writes)``."""
    gateway, deliver = sim.gateway, sim.gateway.deliver
    seen = {"reads": 0, "writes": 0}
    sim.faults.foreign_delay_s = LATE_S

    async def scripted(handler, request: ModbusPDU, response: ModbusPDU, addr, rtu: bool
                       ) -> None:
        if request.function_code == 6:
            seen["writes"] += 1
        else:
            seen["reads"] += 1
        sim.faults.foreign_rate = float(request.function_code == 3
                                        and crosses(seen["reads"], seen["writes"]))
        await deliver(handler, request, response, addr, rtu)

    def foreign(request: ModbusPDU) -> ModbusPDU:
        return ReadHoldingRegistersResponse(registers=[word] * request.count,
                                            dev_id=request.dev_id)

    gateway.deliver = scripted  # type: ignore[method-assign]
    gateway._foreign = foreign  # type: ignore[method-assign]


def test_a_write_not_executed_is_not_verified_by_another_masters_answer(tmp_path):
    """The controller keeps its value (the simulator's ``ignore-writes``: its answer echoes
    the old value, so the write is unconfirmed and its read-back decides); every read-back is
    first answered by another master with the written word. Claiming the write verified would
    leave impctl holding a value the register never had: the read-back is not attributable,
    the write stays in doubt and a night's claim stays given up."""
    async def body():
        async with _on_rtu(tmp_path) as (sim, hp):
            owner = (await hp.read(SETPOINT)).value
            target = owner - 3.0
            sim.faults.ignore_writes = True
            _other_master(sim, encode(register(SETPOINT), target),
                          lambda _reads, writes: writes > 0)
            held = Held(values={SETPOINT: owner})
            with pytest.raises(ModbusLinkError, match="read back nothing attributable"):
                await held.write(SETPOINT, lambda: hp.set_loop1_setpoint(target))
            assert SETPOINT not in held  # the restore puts the owner's value back
            assert sim.plant.setpoint_c == owner and sim.stats.writes[SETPOINT] == 1
            assert sim.gateway.counts["foreign"] >= 3
            assert "second_master" in hp.link.quirks
    run(body(), 60)


def test_an_acknowledged_write_whose_read_backs_are_all_crossed_is_in_doubt(tmp_path):
    """The write executes and is acknowledged, but every read-back is crossed by another
    master's answer: the value is not verified — the write raises with nothing read back and
    impctl claims nothing (the owner's value goes back at the restore)."""
    async def body():
        async with _on_rtu(tmp_path) as (sim, hp):
            owner = (await hp.read(SETPOINT)).value
            target = owner - 3.0
            _other_master(sim, encode(register(SETPOINT), target),
                          lambda _reads, writes: writes > 0)
            held = Held(values={SETPOINT: owner})
            with pytest.raises(WriteVerifyError, match="nothing attributable") as info:
                await held.write(SETPOINT, lambda: hp.set_loop1_setpoint(target))
            assert info.value.read_back is None
            assert SETPOINT not in held
            assert sim.plant.setpoint_c == target and sim.stats.writes[SETPOINT] == 1
    run(body(), 60)


def test_the_compare_before_a_write_takes_no_other_masters_answer(tmp_path):
    """The read before the write is answered by another master with the very word to be
    written: taken for the register's value, the write would be skipped as "already there"
    and the value claimed. Unattributable, nothing is written and nothing is claimed."""
    async def body():
        async with _on_rtu(tmp_path) as (sim, hp):
            owner = (await hp.read(SETPOINT)).value
            target = owner - 3.0
            _other_master(sim, encode(register(SETPOINT), target), lambda *_: True)
            held = Held(values={SETPOINT: owner})
            with pytest.raises(ModbusLinkError, match="nothing written"):
                await held.write(SETPOINT, lambda: hp.set_loop1_setpoint(target))
            assert SETPOINT not in held
            assert sim.plant.setpoint_c == owner and sim.stats.writes[SETPOINT] == 0
    run(body(), 60)


def test_a_read_back_crossed_once_is_read_again_and_verified(tmp_path):
    """One foreign answer on the first read-back (a word that is not the target): the read is
    made again and the write verified with the register's true value."""
    async def body():
        async with _on_rtu(tmp_path) as (sim, hp):
            owner = (await hp.read(SETPOINT)).value
            target = owner - 3.0
            first: list[int] = []

            def once(reads: int, writes: int) -> bool:
                if writes and not first:
                    first.append(reads)
                return bool(first) and reads == first[0]

            _other_master(sim, encode(register(SETPOINT), owner), once)
            result = await hp.set_loop1_setpoint(target)
            assert result.written and result.read_back == target
            assert sim.plant.setpoint_c == target and sim.stats.writes[SETPOINT] == 1
            assert sim.gateway.counts["foreign"] == 1
    run(body(), 60)


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_a_write_on_a_clean_line_costs_three_requests(tmp_path, transport):
    """Compare, write, read back: no re-read on a clean line (TCP waits for no settle)."""
    async def body():
        if transport == "rtu":
            async with _on_rtu(tmp_path) as (sim, hp):
                await _three_requests(hp, sim)
            return
        async with started(_sim().config) as sim:
            async with client(sim, budget=budget(tmp_path)) as hp:
                await _three_requests(hp, sim)
    run(body(), 60)


async def _three_requests(hp: HeatPumpClient, sim: KronotermSimulator) -> None:
    owner = (await hp.read(SETPOINT)).value
    before = hp.link.stats.requests
    result = await hp.set_loop1_setpoint(owner - 2.0)
    assert result.written and result.read_back == owner - 2.0
    assert hp.link.stats.requests - before == 3
    assert sim.plant.setpoint_c == owner - 2.0
    hp.close()
