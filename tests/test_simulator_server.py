"""The simulator's Modbus face, checked with uModbus and raw frames; and the impctl-sim CLI."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from impctl_sim import SimConfig
from impctl_sim.cli import main as sim_main
from sim_fixtures import (
    EPOCH,
    client,
    clock,
    hp_config,
    in_thread,
    raw_exchange,
    run,
    simulator,
    umodbus_call,
    wait_for,
)
from umodbus.client import tcp
from umodbus.exceptions import IllegalDataAddressError, IllegalFunctionError

from impctl.clock import VirtualClock
from impctl.heatpump import Generation, HeatPumpClient

SIM = Path(sys.executable).with_name("impctl-sim")


def test_only_fc3_and_fc6_are_served():
    async def body():
        async with simulator() as sim:
            calls = [tcp.write_multiple_registers(20, 2186, [200]),  # FC 16: undocumented
                     tcp.read_input_registers(20, 2102, 1),  # FC 04
                     tcp.read_coils(20, 0, 8),  # FC 01
                     tcp.write_single_coil(20, 0, 1)]  # FC 05
            for adu in calls:
                with pytest.raises(IllegalFunctionError):
                    await in_thread(umodbus_call, sim.port, adu)
            # A function code pymodbus does not even know still gets "illegal function".
            raw = await raw_exchange(sim.port, bytes.fromhex("0001000000021441"))
            assert raw[7:9] == bytes([0x41 | 0x80, 1])
            assert sim.stats.writes == {} and sim.plant.setpoint_c == 21.0
    run(body())


def test_compact_generation_has_holes_where_the_extended_set_has_registers():
    async def body():
        config = SimConfig(clock=clock(1.0), generation=Generation.COMPACT)
        async with simulator(config) as sim:
            for address in (2128, 2328, 2362):  # MA 2129, 2329, 2363
                with pytest.raises(IllegalDataAddressError):
                    await in_thread(umodbus_call, sim.port,
                                    tcp.read_holding_registers(20, address, 1))
            for address, count in ((1999, 100), (2099, 27)):  # MA 2000–2126, no holes
                words = await in_thread(umodbus_call, sim.port,
                                        tcp.read_holding_registers(20, address, count))
                assert len(words) == count
            with pytest.raises(IllegalDataAddressError):  # one past MA 2126
                await in_thread(umodbus_call, sim.port,
                                tcp.read_holding_registers(20, 2099, 28))
            assert await in_thread(umodbus_call, sim.port,
                                   tcp.read_holding_registers(20, 538, 1)) == [12]  # MA 539
    run(body())


def test_other_unit_ids_get_no_answer():
    async def body():
        async with simulator() as sim:
            raw = await raw_exchange(sim.port, tcp.read_holding_registers(1, 2102, 1),
                                     read_s=0.3)
            assert raw == b""
            answer = await raw_exchange(sim.port, tcp.read_holding_registers(20, 2102, 1))
            assert answer[6] == 20 and answer[7] == 3
    run(body())


def test_setpoint_write_changes_the_simulated_house():
    async def body():
        config = SimConfig(clock=clock(36000.0), step_s=60.0, plant_kind="iso")
        async with simulator(config) as sim, client(sim) as hp:
            start = sim.plant.time_s
            await in_thread(umodbus_call, sim.port, tcp.write_single_register(20, 2186, 180))
            assert sim.plant.setpoint_c == 18.0
            await wait_for(lambda: sim.plant.time_s > start + 6 * 3600)
            assert sim.plant.t_air_c < 19.0
            assert (await hp.read("room_loop1")).value < 19.2
            await in_thread(umodbus_call, sim.port, tcp.write_single_register(20, 2041, 0))
            await wait_for(lambda: sim.plant.time_s > start + 8 * 3600)
            assert sim.plant.p_th_w == 0 and (await hp.read("power_thermal")).value == 0
    run(body())


def test_sensor_noise_is_optional_and_quantised():
    async def body():
        quiet = SimConfig(clock=clock(1.0), plant_kind="iso")
        noisy = SimConfig(clock=clock(1.0), noise_sd_k=0.3, seed=4, plant_kind="iso")
        async with simulator(quiet) as a, simulator(noisy) as b:
            seen_a, seen_b = set(), set()
            for _ in range(20):
                await a._publish()
                await b._publish()
                seen_a.add((await a.read_words(2160))[0])
                seen_b.add((await b.read_words(2160))[0])
            assert seen_a == {round(a.plant.t_air_c * 10)}
            assert len(seen_b) > 3  # whole tenths of a degree, scattered by the noise
            assert all(abs(w / 10 - b.plant.t_air_c) < 2.0 for w in seen_b)
    run(body())


def test_binding_beyond_loopback_needs_a_flag(capsys):
    with pytest.raises(SystemExit) as info:
        sim_main(["--host", "192.0.2.10", "--port", "0"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "refusing to listen on '192.0.2.10'" in err and len(err.strip().splitlines()) == 1


def test_cli_rejects_bad_input(capsys):
    for argv in (["--faults", "explode"], ["--epoch", "2026-01-01T00:00"],
                 ["--house", "/nonexistent.toml"]):
        with pytest.raises(SystemExit) as info:
            sim_main(argv)
        assert info.value.code == 2
        assert capsys.readouterr().err.startswith("impctl-sim: ")


def test_cli_serves_and_shares_its_clock(tmp_path):
    faults_file = tmp_path / "faults"
    clock_file = tmp_path / "clock"
    proc = subprocess.Popen(
        [str(SIM), "--port", "0", "--speed", "600", "--epoch", EPOCH.isoformat(),
         "--generation", "compact", "--faults", "greeting", "--faults-file", str(faults_file),
         "--clock-file", str(clock_file)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        line = proc.stdout.readline()
        match = re.search(r"serving tcp 127\.0\.0\.1:(\d+) unit 20 compact; faults greeting=\w+;"
                          r" clock (\S+)", line)
        assert match, line + proc.stderr.read() if proc.poll() is not None else line
        port, spec = int(match.group(1)), match.group(2)
        assert clock_file.read_text().strip() == spec
        shared = VirtualClock.from_spec(spec)
        assert shared.factor == 600.0 and shared.epoch == EPOCH

        async def body():
            hp = HeatPumpClient(hp_config(port), clock=shared)
            await hp.connect(max_wait_s=5.0)
            assert hp.generation is Generation.COMPACT and hp.link.stats.drained_bytes > 0
            snap = await hp.snapshot()
            assert not snap.t_out_c.missing
            assert snap.timestamp > EPOCH  # the shared simulated time, not the wall time
            faults_file.write_text("missing=2103\n")  # switched from another process
            for _ in range(100):
                await asyncio.sleep(0.05)
                if (await hp.read("t_outdoor")).missing:
                    break
            assert (await hp.read("t_outdoor")).raw == -600
            hp.close()

        run(body())
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0


@pytest.mark.parametrize("source", ["--t-out", "--weather"])
def test_the_outdoor_temperature_held_constant_or_read_from_a_file(tmp_path, source):
    """``--t-out C`` holds the outdoor sensor at C (no weather file, no pandas in the process);
    a two-row ``--weather`` CSV of equal values does the same through the file reader."""
    from daemon_fixtures import weather_csv

    arg = "-7.5" if source == "--t-out" else str(weather_csv(tmp_path / "w.csv", -7.5))
    proc = subprocess.Popen(
        [sys.executable, "-c", "import sys; from impctl_sim.cli import main; main(); "
         "print('pandas' in sys.modules)", "--port", "0", "--speed", "600", "--epoch",
         EPOCH.isoformat(), "--plant", "iso", source, arg],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        line = proc.stdout.readline()
        match = re.search(r"serving tcp 127\.0\.0\.1:(\d+) .* clock (\S+)", line)
        assert match, line + proc.stderr.read() if proc.poll() is not None else line
        shared = VirtualClock.from_spec(match.group(2))

        async def body():
            hp = HeatPumpClient(hp_config(int(match.group(1))), clock=shared)
            await hp.connect(max_wait_s=5.0)
            first = (await hp.read("t_outdoor")).value
            await asyncio.sleep(0.5)  # five simulated minutes later
            second = (await hp.read("t_outdoor")).value
            hp.close()
            return first, second

        assert run(body()) == (-7.5, -7.5)
    finally:
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=10)
    assert proc.returncode == 0
    assert out.strip().splitlines()[-1] == str(source == "--weather")


def test_a_constant_outdoor_temperature_and_a_weather_file_are_not_both_taken(tmp_path, capsys):
    from daemon_fixtures import weather_csv

    for argv in (["--t-out", "-7.5", "--weather", str(weather_csv(tmp_path / "w.csv"))],
                 ["--t-out", "45"], ["--t-out", "nan"]):
        with pytest.raises(SystemExit) as info:
            sim_main(["--port", "0", *argv])
        assert info.value.code == 2
        err = capsys.readouterr().err
        assert err.startswith("impctl-sim: ") and "--t-out" in err, err
        assert len(err.strip().splitlines()) == 1
