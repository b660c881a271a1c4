"""The project's client against the real simulator over loopback TCP; wire format checked with
uModbus, an independent Modbus implementation."""

from __future__ import annotations

import asyncio
import time

import pytest
from impctl_sim import SimConfig, constant_weather
from sim_fixtures import (
    budget,
    client,
    clock,
    free_port,
    hp_config,
    in_thread,
    link_config,
    run,
    simulator,
    umodbus_call,
    wait_for,
)
from umodbus.client import tcp

from impctl.errors import InputError
from impctl.heatpump import (
    ExternalRegister,
    Generation,
    HeatPumpClient,
    ModbusDeviceError,
    ModbusLinkError,
    UnsupportedFeature,
)


def test_snapshot_matches_the_simulated_plant():
    async def body():
        # Real-time clock: the model does not step during the few milliseconds of the test.
        # The ideal plant: its registers show the plant's own values (perfect sensors).
        async with simulator(SimConfig(clock=clock(1.0), plant_kind="iso")) as sim, \
                client(sim) as hp:
            assert hp.generation is Generation.EXTENDED
            snap = await hp.snapshot()
            plant = sim.plant
            assert snap.missing() == {}
            assert snap.t_air_c.value == pytest.approx(round(plant.t_air_c, 1))
            assert snap.t_out_c.value == pytest.approx(round(plant.t_out_c, 1))
            assert snap.t_supply_c.value == pytest.approx(round(plant.t_supply_c, 1))
            assert snap.t_return_c.value == pytest.approx(round(plant.t_return_c, 1))
            assert snap.q_hc_w.value == round(plant.p_th_w)
            assert snap.p_el_w.value == round(plant.p_el_w)
            assert snap.energy_thermal_kwh.value == pytest.approx(int(plant.e_th_kwh * 10) / 10)
            assert snap.loop1_setpoint_c.value == 21.0 and snap.loop1_mode.value == 1
            assert snap.q_hc_w.source == "register 2329"
            assert snap.t_air_c.timestamp.tzinfo is not None
            assert snap.timestamp <= snap.t_out_c.timestamp <= sim.clock.now()
    run(body())


def test_negative_outdoor_temperature_on_the_wire():
    async def body():
        config = SimConfig(clock=clock(1.0), weather=constant_weather(-7.3), plant_kind="iso")
        async with simulator(config) as sim, client(sim) as hp:
            snap = await hp.snapshot()
            assert snap.t_out_c.value == pytest.approx(-7.3) and snap.t_out_c.raw == -73
            # uModbus: FC 03 at PDU address 2102 (= documented 2103), raw unsigned word.
            words = await in_thread(umodbus_call, sim.port,
                                    tcp.read_holding_registers(20, 2102, 1))
            assert words == [0xFFB7]  # -73 as int16 two's complement
    run(body())


def test_ma_minus_one_rule_checked_with_umodbus():
    async def body():
        async with simulator(SimConfig(clock=clock(1.0))) as sim, client(sim) as hp:
            # uModbus reads MA 2101…2104 (return, DHW, outdoor, supply) at addresses 2100…2103.
            words = await in_thread(umodbus_call, sim.port,
                                    tcp.read_holding_registers(20, 2100, 4))
            ours = [await hp.read(ma) for ma in (2101, 2102, 2103, 2104)]
            assert [w - 0x10000 if w & 0x8000 else w for w in words] == [r.raw for r in ours]
            # Address 2103 is the supply (MA 2104), not the outdoor temperature.
            supply = await in_thread(umodbus_call, sim.port,
                                     tcp.read_holding_registers(20, 2103, 1))
            assert supply[0] == round(sim.plant.t_supply_c * 10)
    run(body())


def test_write_with_umodbus_is_seen_by_our_client_and_vice_versa(tmp_path):
    async def body():
        async with simulator(SimConfig(clock=clock(1.0))) as sim, \
                client(sim, budget=budget(tmp_path)) as hp:
            echo = await in_thread(umodbus_call, sim.port,
                                   tcp.write_single_register(20, 2186, 195))
            assert echo == 195
            assert (await hp.read("loop1_setpoint")).value == 19.5
            assert sim.plant.setpoint_c == 19.5
            result = await hp.set_loop1_setpoint(18.5)
            assert result.written and result.previous == 19.5 and result.read_back == 18.5
            words = await in_thread(umodbus_call, sim.port,
                                    tcp.read_holding_registers(20, 2186, 1))
            assert words == [185]
    run(body())


def test_compact_controller_has_no_heat_power():
    async def body():
        config = SimConfig(clock=clock(1.0), generation=Generation.COMPACT)
        async with simulator(config) as sim, client(sim) as hp:
            assert hp.generation is Generation.COMPACT  # detected, not configured
            snap = await hp.snapshot()
            assert snap.q_hc_w.missing and "no heat-power register (2329)" in snap.q_hc_w.reason
            assert snap.p_el_w.missing and "compact" in snap.p_el_w.reason
            assert not snap.t_out_c.missing and not snap.t_air_c.missing
            assert hp.heat_power_source() is None
            with pytest.raises(UnsupportedFeature, match="heat meter"):
                hp.require_heat_power()
            with pytest.raises(ModbusDeviceError) as info:
                await hp.link.read(2328, 1)  # PDU address of 2329
            assert info.value.exception_code == 2
    run(body())


def test_compact_controller_with_external_heat_meter():
    async def body():
        config = SimConfig(clock=clock(1.0), generation=Generation.COMPACT, heat_meter_id=30,
                           weather=constant_weather(-5.0))
        meter = ExternalRegister(device_id=30, address=0, datatype="uint32", valid=(0, 30000))
        async with simulator(config) as sim, client(sim, heat_meter=meter) as hp:
            assert hp.require_heat_power() == "heat meter device 30 address 0"
            snap = await hp.snapshot()
            assert snap.q_hc_w.value == round(sim.plant.p_th_w) and snap.q_hc_w.value > 0
            assert snap.q_hc_w.source.startswith("external")
    run(body())


def test_external_room_sensor_on_its_own_link():
    async def body():
        config = SimConfig(clock=clock(1.0), room_thermostat=False,
                           weather=constant_weather(-2.5), plant_kind="iso")
        async with simulator(config) as sim:
            # Stand-in for an external sensor: a signed ×0.1 register reached over a second
            # connection (its own link), here the simulator's outdoor register.
            sensor = ExternalRegister(device_id=20, address=2102, scale=0.1, valid=(-50, 60),
                                      link=link_config(sim.port))
            async with client(sim, room_sensor=sensor) as hp:
                snap = await hp.snapshot()
                assert snap.t_air_c.value == pytest.approx(-2.5)
                assert snap.t_air_c.source == "external device 20 address 2102"
                assert hp._ext_links[sensor.link].stats.connects == 1
                narrow = ExternalRegister(device_id=20, address=2102, scale=0.1, valid=(0, 40))
                reading = await hp.read_external(narrow, "t_air", "°C")
                assert reading.missing and "outside the valid range" in reading.reason
    run(body())


def test_detection_refuses_to_guess_when_the_device_is_busy():
    async def body():
        async with simulator(SimConfig(clock=clock(1.0))) as sim:
            sim.faults.exception_code = 6
            hp = HeatPumpClient(hp_config(sim.port), clock=sim.clock)
            with pytest.raises(ModbusDeviceError):
                await hp.connect(max_wait_s=2.0)  # busy is not "compact"
            with pytest.raises(Exception, match="generation unknown"):
                await hp.snapshot()
            hp.close()
    run(body())


def test_absent_room_thermostat_is_missing_not_minus_forty():
    async def body():
        config = SimConfig(clock=clock(1.0), room_thermostat=False)
        async with simulator(config) as sim, client(sim) as hp:
            snap = await hp.snapshot()
            assert snap.t_air_c.missing and snap.t_air_c.value is None
            assert snap.t_air_c.raw == -400 and "no room thermostat" in snap.t_air_c.reason
            with pytest.raises(InputError, match="register 2160"):
                snap.t_air_c.require()
    run(body())


def test_dhw_off_sentinel_written_by_another_master():
    async def body():
        async with simulator(SimConfig(clock=clock(600.0))) as sim, client(sim) as hp:
            assert (await hp.read("dhw_target")).value == 48.0
            await in_thread(umodbus_call, sim.port, tcp.write_single_register(20, 2025, 0))
            published = sim.stats.publishes
            await wait_for(lambda: sim.stats.publishes > published)  # the next image
            reading = await hp.read("dhw_target")
            assert reading.missing and reading.raw == 5000 and "DHW off" in reading.reason
    run(body())


def test_missing_sensor_switched_on_at_run_time():
    async def body():
        async with simulator(SimConfig(clock=clock(600.0))) as sim, client(sim) as hp:
            assert not (await hp.snapshot()).t_out_c.missing
            sim.faults.missing_sensors = {2103, 2104}
            published = sim.stats.publishes
            await wait_for(lambda: sim.stats.publishes > published)
            snap = await hp.snapshot()
            assert snap.t_out_c.missing and snap.t_out_c.raw == -600
            assert "sensor not connected" in snap.t_out_c.reason
            assert snap.t_supply_c.missing and not snap.t_return_c.missing
    run(body())


def test_connect_loop_waits_for_a_late_server():
    async def body():
        port = free_port()
        hp = HeatPumpClient(hp_config(port), clock=clock(600.0))
        connecting = asyncio.create_task(hp.connect(max_wait_s=10.0))
        await asyncio.sleep(0.3)  # several refused attempts; pymodbus alone would give up
        assert not connecting.done()
        async with simulator(port=port):
            await connecting
            assert hp.link.stats.connects == 1
            assert not (await hp.snapshot()).t_out_c.missing
        hp.close()
    run(body())


def test_connect_loop_gives_up_after_max_wait():
    async def body():
        hp = HeatPumpClient(hp_config(free_port()), clock=clock(600.0))
        started = time.monotonic()
        with pytest.raises(ModbusLinkError, match="cannot connect"):
            await hp.connect(max_wait_s=0.3)
        assert time.monotonic() - started < 5.0
    run(body())


def test_a_stop_while_connecting_is_honoured_at_once():
    """Cancelling a connect loop (the daemon's SIGTERM while the heat pump is unreachable)
    ends it at once, also when the cancellation meets a refused connection inside pymodbus'
    ``wait_for`` (Python 3.11 drops it there; the loop then ran on to its deadline)."""
    async def body():
        port = free_port()
        late = 0
        for i in range(200):
            hp = HeatPumpClient(hp_config(port, link=link_config(
                port, connect_backoff_s=(0.001, 0.002))), clock=clock(600.0))
            connecting = asyncio.ensure_future(hp.connect(max_wait_s=5.0))
            await asyncio.sleep(0.0005 * (i % 20))  # cancel at many points of the loop
            started = time.monotonic()
            connecting.cancel()
            await asyncio.gather(connecting, return_exceptions=True)
            late += time.monotonic() - started > 1.0
            hp.close()
        assert late == 0, f"{late} of 200 cancellations waited for the connect deadline"
    run(body(), 60)


def test_rtu_over_socket_url():
    async def body():
        port = free_port()
        config = SimConfig(clock=clock(1.0), weather=constant_weather(-3.4), plant_kind="iso")
        async with simulator(config, rtu=f"socket://127.0.0.1:{port}") as sim:
            link = link_config(port, transport="rtu", serial_port=f"socket://127.0.0.1:{port}",
                               baudrate=115200)
            async with client(sim, link=link) as hp:
                assert hp.generation is Generation.EXTENDED
                snap = await hp.snapshot()
                assert snap.t_out_c.value == pytest.approx(-3.4)
                assert snap.t_air_c.value == pytest.approx(round(sim.plant.t_air_c, 1))
    run(body())


def test_rtu_frame_checked_with_umodbus():
    import serial
    from umodbus.client.serial import rtu

    def umodbus_rtu(port: int) -> list[int]:
        ser = serial.serial_for_url(f"socket://127.0.0.1:{port}", timeout=2.0)
        try:
            return rtu.send_message(rtu.read_holding_registers(20, 2102, 2), ser)
        finally:
            ser.close()

    async def body():
        port = free_port()
        config = SimConfig(clock=clock(1.0), weather=constant_weather(-12.5), plant_kind="iso")
        async with simulator(config, rtu=f"socket://127.0.0.1:{port}") as sim:
            words = await in_thread(umodbus_rtu, port)
            assert words[0] == (-125) & 0xFFFF
            assert words[1] == round(sim.plant.t_supply_c * 10)
    run(body())
