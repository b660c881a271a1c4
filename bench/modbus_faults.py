"""Snapshots through a faulty gateway / shared bus: is any wrong value stored? (issue 15)

Run:  .venv/bin/python bench/modbus_faults.py [--snapshots 1000] [--quick]

The simulator's registers are frozen after start (``freeze``), so every register has one true
value; a snapshot taken before any fault is switched on is the truth. Then faults are switched
on and ``--snapshots`` snapshots are read per scenario:

* ``tcp-fixed-tid``: TCP gateway answering with a fixed transaction id (impctl tolerating it),
  latency spikes past the timeout, late duplicate answers, gateway exceptions 10/11;
* ``tcp``: the same gateway with real transaction ids;
* ``rtu-shared-bus``: RTU (``socket://``) with a second master's answers crossing the line,
  late duplicates, latency spikes, gateway exceptions.

For each: snapshots read, fields that came back wrong (a value that differs from the truth),
fields missing, and the same faults read by a naive pymodbus client (pymodbus' own resends,
TID rewrite, count check only — what impctl did before issue 15) for comparison.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import platform
import sys
import time
from datetime import UTC, datetime

import pymodbus
from impctl_sim import KronotermSimulator, SimConfig, parse_faults
from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient
from pymodbus.framer import FramerType

from impctl.clock import VirtualClock
from impctl.heatpump import HeatPumpClient, HeatPumpConfig, LinkConfig
from impctl.kronoterm.registers import Generation, register
from impctl.kronoterm.snapshot import SNAPSHOT_REGISTERS, plan_blocks

EPOCH = datetime(2026, 1, 12, 23, tzinfo=UTC)
SCENARIOS = {
    "tcp-fixed-tid": "fixed-tid,spikes=0.03@0.3,duplicates=0.1@0.2,gateway-exceptions=0.03",
    "tcp": "spikes=0.03@0.3,duplicates=0.1@0.2,gateway-exceptions=0.03",
    "rtu-shared-bus": "foreign=0.03,spikes=0.02@0.3,duplicates=0.05@0.1,gateway-exceptions=0.03",
}


def _link(name: str, port: int) -> LinkConfig:
    common = dict(timeout_s=0.15, attempts=4, retry_delay_s=0.01, connect_backoff_s=(0.02, 0.1),
                  drain_s=0.01, settle_s=0.01)
    if name.startswith("rtu"):
        return LinkConfig(transport="rtu", serial_port=f"socket://127.0.0.1:{port}", **common)
    return LinkConfig(port=port, tolerate_fixed_tid=name == "tcp-fixed-tid", **common)


async def _impctl(name: str, sim: KronotermSimulator, port: int, n: int) -> dict[str, float]:
    hp = HeatPumpClient(HeatPumpConfig(link=_link(name, port), generation="extended"),
                        clock=sim.clock)
    await hp.connect(max_wait_s=5)
    truth = (await hp.snapshot()).values()
    sim.faults.update(parse_faults("freeze," + SCENARIOS[name]))
    wrong = missing = failed = fields = 0
    t0 = time.perf_counter()
    for i in range(n):
        try:
            snap = await hp.snapshot()
        except Exception:  # noqa: BLE001 - a whole poll lost is "missing", as in the daemon
            failed += 1
            continue
        for key, value in snap.values().items():
            if truth[key] is None:
                continue
            fields += 1
            if value is None:
                missing += 1
            elif value != truth[key]:
                wrong += 1
                print(f"  WRONG {name} #{i} {key}: {value} != {truth[key]}", file=sys.stderr)
    elapsed = time.perf_counter() - t0
    stats = hp.link.stats
    quirks = ",".join(hp.link.quirks) or "-"
    hp.close()
    sim.faults.update(parse_faults("freeze"))
    return dict(snapshots=n, fields=fields, wrong=wrong, missing=missing, failed_polls=failed,
                unattributable=stats.unattributable, transient=stats.transient_exceptions,
                connects=stats.connects, s_per_snapshot=elapsed / n, quirks=quirks)


async def _naive(name: str, sim: KronotermSimulator, port: int, n: int) -> dict[str, float]:
    """pymodbus alone, as impctl used it before: resends on, TID rewritten, count checked."""
    blocks = plan_blocks([register(r) for r in (*SNAPSHOT_REGISTERS.values(), "room_loop1",
                                                "power_thermal")], Generation.EXTENDED)
    truth = {b: await sim.read_words(*b) for b in blocks}
    holder: list = []

    def rewrite(sending: bool, data: bytes) -> bytes:
        if sending or not holder or len(data) < 2 or name != "tcp-fixed-tid":
            return data
        return holder[0].ctx.request_transaction_id.to_bytes(2, "big") + data[2:]

    if name.startswith("rtu"):
        client = AsyncModbusSerialClient(f"socket://127.0.0.1:{port}", framer=FramerType.RTU,
                                         timeout=0.15, retries=1, reconnect_delay=0.05)
    else:
        client = AsyncModbusTcpClient("127.0.0.1", port=port, timeout=0.15, retries=1,
                                      reconnect_delay=0.05, trace_packet=rewrite)
    holder.append(client)
    await client.connect()
    sim.faults.update(parse_faults("freeze," + SCENARIOS[name]))
    wrong = words = missing = 0
    for _ in range(n):
        for first, count in blocks:
            words += count
            try:
                rr = await client.read_holding_registers(first - 1, count=count, device_id=20)
            except Exception:  # noqa: BLE001
                missing += count
                await asyncio.sleep(0.05)
                if not client.connected:
                    await client.connect()
                continue
            if rr.isError() or len(rr.registers) != count:
                missing += count
                continue
            wrong += sum(a != b for a, b in zip(rr.registers, truth[(first, count)], strict=True))
    client.close()
    sim.faults.update(parse_faults("freeze"))
    return dict(words=words, wrong=wrong, missing=missing)


async def scenario(name: str, n: int, naive_n: int) -> tuple[dict, dict]:
    config = SimConfig(clock=VirtualClock(EPOCH, 1.0), faults=parse_faults("freeze"), seed=7)
    sim = KronotermSimulator(config)
    if name.startswith("rtu"):
        import socket
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        await sim.start(rtu=f"socket://127.0.0.1:{port}")
    else:
        port = await sim.start()
    try:
        await asyncio.sleep(0.2)  # one publish, then frozen
        ours = await _impctl(name, sim, port, n)
        naive = await _naive(name, sim, port, naive_n)
    finally:
        await sim.stop()
    return ours, naive


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--snapshots", type=int, default=1000, help="per scenario")
    parser.add_argument("--naive", type=int, default=100, help="naive polls per scenario")
    parser.add_argument("--quick", action="store_true", help="50 snapshots, 20 naive polls")
    parser.add_argument("--only", choices=sorted(SCENARIOS), help="one scenario")
    args = parser.parse_args()
    n, naive_n = (50, 20) if args.quick else (args.snapshots, args.naive)
    logging.basicConfig(level=logging.CRITICAL)
    print(f"# command: {' '.join([sys.executable.split('/')[-1], *sys.argv])}")
    print(f"# python {platform.python_version()}, pymodbus {pymodbus.__version__}, "
          f"{platform.machine()}")
    total_wrong = 0
    for name in [args.only] if args.only else SCENARIOS:
        t0 = time.perf_counter()
        ours, naive = asyncio.run(scenario(name, n, naive_n))
        total_wrong += ours["wrong"]
        print(f"{name:15s} faults: {SCENARIOS[name]}")
        print(f"  impctl : {ours['snapshots']} snapshots, {ours['fields']} fields, "
              f"WRONG {ours['wrong']}, missing {ours['missing']} "
              f"({ours['missing'] / max(ours['fields'], 1):.1%}), failed polls "
              f"{ours['failed_polls']}, unattributable answers caught "
              f"{ours['unattributable']}, transient exceptions retried {ours['transient']}, "
              f"connects {ours['connects']}, {ours['s_per_snapshot'] * 1000:.0f} ms/snapshot, "
              f"quirks named: {ours['quirks']}")
        print(f"  naive  : {naive['words']} words in {naive_n} polls, WRONG {naive['wrong']}, "
              f"missing {naive['missing']}   ({time.perf_counter() - t0:.0f} s)")
    print(f"TOTAL wrong values stored by impctl: {total_wrong}")


if __name__ == "__main__":
    main()
