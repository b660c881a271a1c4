"""The simulated Kronoterm behind a real pymodbus server (TCP, or RTU over a serial port/URL).

Usage from a test::

    async with KronotermSimulator(SimConfig(clock=VirtualClock(epoch, 600))) as sim:
        port = sim.port            # bound on 127.0.0.1, port 0 = a free port
        sim.faults.delay_s = 2.0   # switch faults at run time

Only FC 03 and FC 06 are served; every other function code gets exception 1 (illegal
function). Writes to read-only or undocumented registers get exception 2, out-of-range values
exception 3; an FC 03 asking for 0 or more than 125 registers gets FC 0x83 exception 3, as the
Modbus specification says. Requests for other unit ids are not answered (as on an RS-485
line). Gateway and bus faults (issue 15) are applied by :mod:`.gateway`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.framer import FramerType
from pymodbus.pdu import ExceptionResponse, ModbusPDU
from pymodbus.server.requesthandler import ServerRequestHandler
from pymodbus.simulator import DataType, SimData, SimDevice

from impctl.clock import VirtualClock
from impctl.clock.loop import on_virtual_time
from impctl.errors import InputError
from impctl.kronoterm.registers import Generation
from impctl.modbus import to_int16

from .config import SimConfig
from .faults import parse_faults
from .gateway import GatewayFaults
from .image import (
    LAYOUT,
    PLANT_INPUTS,
    WRITE_RANGES,
    heat_meter_words,
    initial_rw,
    kronoterm_values,
    register_words,
    writable,
)
from .profiles import tt3000_undocumented
from .wire import BadCount, Fc3Fc6Decoder, SerialServer, TcpServer, require_loopback

_LOG = logging.getLogger(__name__)
_MAX_STEPS_PER_TICK = 2000
_MAX_TICK_S = 0.01


@dataclass
class SimStats:
    """Counters of a running simulator."""

    steps: int = 0
    publishes: int = 0
    requests: int = 0
    connections: int = 0
    dropped: int = 0
    writes: Counter = field(default_factory=Counter)  # documented number → accepted FC 06
    lag_s: float = 0.0  # simulated time the model is behind the clock


def _make_handler(sim: KronotermSimulator) -> type[ServerRequestHandler]:
    class _Handler(ServerRequestHandler):
        def callback_connected(self) -> None:
            super().callback_connected()
            sim.stats.connections += 1
            if sim.faults.greeting:
                # Some gateways greet only after a moment, i.e. possibly mid-request.
                self.loop.call_later(sim.faults.greeting_delay_s, self._greet)

        def _greet(self) -> None:
            if self.transport and sim.faults.greeting:
                self.transport.write(sim.faults.greeting)

        async def handle_request(self) -> None:
            pdu, addr = self.last_pdu, self.last_addr
            if pdu is None:
                return
            response = await sim._respond(self, pdu)
            if response is not None and self.transport:
                response.transaction_id = pdu.transaction_id
                response.dev_id = pdu.dev_id
                await sim.gateway.deliver(self, pdu, response, addr, not sim._framer_socket)

    return _Handler


class KronotermSimulator:
    """A simulated Kronoterm heat pump on a real Modbus server.

    Parameters
    ----------
    config : SimConfig
    faults_file : Path, optional
        Re-read (fault syntax of :mod:`impctl_sim.faults`) whenever it changes, so another
        process can switch faults at run time.
    """

    def __init__(self, config: SimConfig | None = None, *, faults_file: Path | None = None):
        self.config = config = config or SimConfig()
        self.clock = config.clock or VirtualClock.real()
        self.faults = config.faults
        self.stats = SimStats()
        self._weather = config.weather_feed(self.clock)
        warm_from = self.clock.now_s() - config.warmup_s
        self.plant = config.make_plant(self.clock, self._weather.t_out_c(warm_from))
        self.rw = initial_rw(config.setpoint_c, self.plant.installer_curve_c())
        #: The curve points the controller started with (raw): writing them back is the
        #: controller's own curve again.
        self._own_curve = (self.rw[2309], self.rw[2314])
        self._rng = np.random.default_rng(config.seed)
        self._faults_file = faults_file
        self._faults_mtime: float | None = None
        self.gateway = GatewayFaults(self.faults, config.seed)
        self._server: TcpServer | SerialServer | None = None
        self._task: asyncio.Task | None = None
        self._internal = False
        self._framer_socket = True
        self.host = ""
        self.port = 0

    # ---- lifecycle -------------------------------------------------------------------------
    async def start(self, host: str = "127.0.0.1", port: int = 0, *, rtu: str | None = None,
                    baudrate: int = 19200, allow_remote: bool = False) -> int:
        """Warm the model up, start serving and stepping; return the bound TCP port.

        Parameters
        ----------
        host, port : TCP address; port 0 picks a free port.
        rtu : serve Modbus RTU instead, on this serial device or pyserial URL (a
            ``socket://127.0.0.1:PORT`` URL makes it RTU over a TCP listener).
        allow_remote : required to listen on anything but a loopback address.

        Raises
        ------
        InputError
            Non-loopback address without ``allow_remote``.
        """
        if rtu and rtu.startswith("socket://"):
            host, _, port_text = rtu[len("socket://"):].rpartition(":")
            port = int(port_text)
        if (rtu is None or rtu.startswith("socket://")) and not allow_remote:
            require_loopback(host)
        self._warm_up()
        self._update_faults_from_file()
        device = SimDevice(self.config.unit_id, _blocks(self.config), action=self._action)
        devices = [device]
        if self.config.heat_meter_id is not None:
            devices.append(SimDevice(self.config.heat_meter_id,
                                     [SimData(0, count=2, datatype=DataType.REGISTERS)],
                                     action=self._meter_action))
        common = dict(trace_packet=self._trace_packet)
        if rtu is None:
            server = TcpServer(devices, address=(host, port), **common)
        else:
            server = SerialServer(devices, framer=FramerType.RTU, port=rtu, baudrate=baudrate,
                                   **common)
        server.handler_class = _make_handler(self)
        server.decoder = Fc3Fc6Decoder(True)
        self._server = server
        self._framer_socket = rtu is None
        await self._publish()
        await server.serve_forever(background=True)
        sockets = getattr(server.transport, "sockets", None)
        self.host, self.port = (host, sockets[0].getsockname()[1]) if sockets else (host, 0)
        self._task = asyncio.create_task(self._run(), name="impctl-sim model")
        self._task.add_done_callback(_log_crash)
        _LOG.info("simulator serving %s on %s:%s (%s, unit %d), clock %s", "RTU" if rtu else
                  "TCP", self.host, self.port, self.config.generation.value,
                  self.config.unit_id, self.clock)
        return self.port

    async def stop(self) -> None:
        """Stop stepping and serving (idempotent)."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        if self._server is not None:
            await self._server.shutdown()
            self._server = None

    async def __aenter__(self) -> KronotermSimulator:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    def drop_connections(self) -> int:
        """Close every open client connection now; return how many were closed."""
        if self._server is None:
            return 0
        handlers = list(self._server.active_connections.values())
        for handler in handlers:
            handler.close()
        self.stats.dropped += len(handlers)
        return len(handlers)

    async def read_words(self, ma: int, count: int = 1) -> list[int]:
        """The words the server would answer for documented number ``ma`` (bypasses faults)."""
        assert self._server is not None
        return list(await self._server.async_getValues(self.config.unit_id, 3, ma - 1, count))

    # ---- model -----------------------------------------------------------------------------
    def _warm_up(self) -> None:
        start = self.clock.now_s()
        # The realistic plant starts steady and costs more per step: coarser warm-up steps.
        dt = 300.0 if self.plant.kind == "iso" else 900.0
        self.plant.time_s = start - self.config.warmup_s
        while self.plant.time_s + dt <= start:
            self.plant.step(dt, self._weather.t_out_c(self.plant.time_s + dt / 2))
        self.plant.time_s = start

    def advance(self, *, bounded: bool = True) -> int:
        """Step the model up to the clock; return steps. ``bounded``: at most a bounded number
        of steps and ~10 ms of wall time (on the wall clock a catch-up of the realistic plant,
        ≈ 0.3 ms a step, must not hold the event loop and the clients polling through it);
        unbounded on virtual time, where computing takes no simulated time and a model left
        behind the clock would answer requests with a load-dependent lag."""
        target = self.clock.now_s()
        step = self.config.step_s
        n = 0
        limit = _MAX_STEPS_PER_TICK if bounded else float("inf")
        give_up = time.perf_counter() + (_MAX_TICK_S if bounded else float("inf"))
        while (self.plant.time_s + step <= target and n < limit
               and (n % 16 or time.perf_counter() < give_up)):
            self.plant.step(step, self._weather.t_out_c(self.plant.time_s + step / 2))
            n += 1
        self.stats.steps += n
        self.stats.lag_s = max(0.0, target - self.plant.time_s)
        return n

    async def _run(self) -> None:
        tick = min(0.1, max(0.01, self.config.step_s / self.clock.factor))
        bounded = not on_virtual_time()
        while True:
            self.advance(bounded=bounded)
            self._update_faults_from_file()
            if not self.faults.freeze:
                await self._publish()
            await asyncio.sleep(tick if self.stats.lag_s < self.config.step_s else 0)

    def _sensor(self, value_c: float) -> float:
        sd = self.config.noise_sd_k
        return value_c + (float(self._rng.normal(0.0, sd)) if sd > 0 else 0.0)

    async def _publish(self) -> None:
        assert self._server is not None
        cfg = self.config
        values = kronoterm_values(self.plant, self.rw, room_thermostat=cfg.room_thermostat,
                                  t_air_c=self._sensor(self.plant.t_air_sensor_c),
                                  t_out_c=self._sensor(self.plant.t_out_sensor_c))
        if self.faults.cop_3_decimals:  # some controllers: 5413 = 5.413 (issue 15)
            values.update({ma: values[ma] * 10 for ma in (2371, 2372) if ma in values})
        self._internal = True  # lets the action tell model updates from client writes
        try:
            for address, words in register_words(values, cfg.generation,
                                                 self.faults.missing_sensors):
                await self._server.async_setValues(cfg.unit_id, 16, address, words)
            if cfg.heat_meter_id is not None:
                await self._server.async_setValues(cfg.heat_meter_id, 16, 0,
                                                   heat_meter_words(self.plant))
        finally:
            self._internal = False
        self.stats.publishes += 1

    # ---- Modbus side -----------------------------------------------------------------------
    async def _respond(self, handler: ServerRequestHandler, pdu: ModbusPDU) -> ModbusPDU | None:
        self.stats.requests += 1
        faults = self.faults
        if pdu.dev_id not in (self.config.unit_id, self.config.heat_meter_id):
            return None  # nobody on the line answers to this id
        if faults.drop:
            self.stats.dropped += 1
            handler.close()
            return None
        if faults.delay_s:
            await asyncio.sleep(faults.delay_s)
        if isinstance(pdu, BadCount):
            return ExceptionResponse(3, ExcCodes.ILLEGAL_VALUE)
        if pdu.function_code not in (3, 6):
            return ExceptionResponse(pdu.function_code, ExcCodes.ILLEGAL_FUNCTION)
        if faults.exception_code:
            return ExceptionResponse(pdu.function_code, faults.exception_code)
        if (gateway_exc := self.gateway.exception_instead(pdu)) is not None:
            return gateway_exc
        assert self._server is not None
        if (faults.tt3000_undocumented and pdu.function_code == 3
                and self.config.generation is Generation.COMPACT):
            return await tt3000_undocumented(self, pdu)
        try:
            response = await pdu.datastore_update(self._server.context, pdu.dev_id)
            lost = None if response.isError() else self.gateway.lose_write_answer(pdu)
            return lost or response
        except Exception:  # a bug in the simulator must not look like silence on the wire
            _LOG.exception("simulator failed on %s", pdu)
            return ExceptionResponse(pdu.function_code, ExcCodes.DEVICE_FAILURE)

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], set_values: list[int] | None) -> ExcCodes | None:
        if self._internal or set_values is None:
            return None
        if function_code != 6 or count != 1:
            return ExcCodes.ILLEGAL_FUNCTION
        ma = address + 1
        if not writable(ma, self.config.generation):
            return ExcCodes.ILLEGAL_ADDRESS
        raw = to_int16(int(set_values[0]))
        low, high = WRITE_RANGES.get(ma, (-0x8000, 0x7FFF))
        if not low <= raw <= high:
            return ExcCodes.ILLEGAL_VALUE
        self.stats.writes[ma] += 1
        if self.faults.ignore_writes:
            set_values[0] = registers[address - start_address]
            return None
        self.rw[ma] = raw
        which = PLANT_INPUTS.get(ma)
        if which == "setpoint":
            self.plant.setpoint_c = raw / 10.0
        elif which == "loop_mode":
            self.plant.loop_mode = raw
        elif which == "system_on":
            self.plant.system_on = raw
        elif which == "correction":
            self.plant.correction_k = raw
        elif which == "curve":
            points = (self.rw[2309], self.rw[2314])
            self.plant.set_curve(None if points == self._own_curve
                                 else (points[0] / 10.0, points[1] / 10.0))
        return None

    async def _meter_action(self, function_code: int, start_address: int, address: int,
                            count: int, registers: list[int],
                            set_values: list[int] | None) -> ExcCodes | None:
        if self._internal or set_values is None:
            return None
        return ExcCodes.ILLEGAL_ADDRESS

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        tid = self.faults.fixed_tid
        if sending and tid is not None and self._framer_socket and len(data) >= 2:
            return tid.to_bytes(2, "big") + data[2:]
        return data

    def _update_faults_from_file(self) -> None:
        path = self._faults_file
        if path is None:
            return
        try:
            mtime = os.stat(path).st_mtime
        except FileNotFoundError:
            return
        if mtime == self._faults_mtime:
            return
        self._faults_mtime = mtime
        try:
            self.faults.update(parse_faults(path.read_text(), str(path)))
        except InputError as exc:
            _LOG.error("ignoring fault file: %s", exc)
            return
        _LOG.warning("faults now: %s", self.faults.describe())


def _log_crash(task: asyncio.Task) -> None:
    # A dead model task would leave the registers frozen without a word: say so loudly.
    if not task.cancelled() and task.exception() is not None:
        _LOG.error("simulator model task died; registers are frozen",
                   exc_info=task.exception())


def _blocks(config: SimConfig) -> list[SimData]:
    return [SimData(first - 1, count=n, datatype=DataType.REGISTERS)
            for first, n in LAYOUT[config.generation]]
