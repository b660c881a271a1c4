"""The Modbus wire: FC 03 block reads and FC 06 single writes, serialised, with reconnects.

pymodbus (~=3.16) does the framing. This layer adds what the field needed (reference §1.7,
runtime notes §1.3, issue 15):

* its own connect loop with doubling back-off (pymodbus never retries a failed first connect);
  pymodbus' background reconnect is switched off so there is one owner of the connection;
* after every fresh connect, a short wait and then the receive buffer is discarded, so a
  gateway's unsolicited greeting (often its MAC) never lands in the middle of the first
  answer and desynchronises the framer;
* pymodbus' own resends are off (``retries=0``): a resend under the same transaction id lets a
  late answer to the first send complete the *next* request. The link retries itself, on a new
  connection after any timeout or unattributable answer, with doubling back-off;
* every answer is checked to be the answer to its own request (:mod:`.attribution`): by
  transaction id where the gateway has usable ones, otherwise by byte accounting and answer
  signatures; a failed check resets the connection and counts as a failed try;
* Modbus exceptions 5, 6, 10 and 11 (acknowledge, busy, gateway path unavailable, gateway
  target did not respond) are transient: reads retry them; every other exception is final;
* optional tolerance of a fixed MBAP transaction id (rewritten to the pending request's);
* one request at a time (an asyncio lock), an optional gap between requests;
* one log line per incident: the first failure after a good answer is logged (INFO), the
  retries, reconnects and further failures of the same outage only at DEBUG — the caller
  (the night controller) says what the incident means, once;
* only FC 03 and FC 06 exist here: there is no way to send FC 16.
"""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass

from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException
from pymodbus.framer import FramerType

from .attribution import Attribution
from .config import LinkConfig
from .errors import TRANSIENT_EXCEPTIONS, ModbusDeviceError, ModbusLinkError

_LOG = logging.getLogger(__name__)


def _loop_s() -> float:
    """The event loop's clock [s]: what its timeouts and sleeps run on (``time.monotonic`` on
    a standard loop); deadlines measured on it stay consistent with them on any loop."""
    return asyncio.get_running_loop().time()


def _honour_cancel() -> None:
    """Raise the cancellation that Python 3.11's ``wait_for`` (inside pymodbus' connect) drops
    when it arrives as a refused connection completes (CPython gh-86296): the task still
    counts the request, so a stop (SIGTERM) is not left waiting for the connect deadline."""
    task = asyncio.current_task()
    if task is not None and task.cancelling():
        raise asyncio.CancelledError("cancelled while connecting")


class _Unattributable(ModbusLinkError):
    """An answer that cannot be shown to be the answer to its own request."""


@dataclass
class LinkStats:
    """Counters of one link, for health metrics."""

    requests: int = 0
    failures: int = 0
    retries: int = 0
    connects: int = 0
    drained_bytes: int = 0
    unattributable: int = 0
    transient_exceptions: int = 0
    last_ok_monotonic: float | None = None


class ModbusLink:
    """One Modbus master connection (TCP or RTU), used only through :meth:`read`/:meth:`write`.

    Parameters
    ----------
    config : LinkConfig
    """

    def __init__(self, config: LinkConfig) -> None:
        self.config = config
        self.stats = LinkStats()
        self.attribution = Attribution(config.transport, not config.tolerate_fixed_tid)
        self._client: AsyncModbusTcpClient | AsyncModbusSerialClient | None = None
        self._lock = asyncio.Lock()
        self._last_request = 0.0
        # True from a failure until the next good answer: one log line per incident.
        self._trouble = False
        #: Registers whose last safe write failed (their repeated failures log at DEBUG); kept
        #: by the writer (:mod:`impctl.heatpump.writes`), per link.
        self.failed_writes: set[int] = set()

    def _incident(self, msg: str, *args: object) -> None:
        """Log a failure: the first of an incident at INFO, the rest at DEBUG."""
        _LOG.log(logging.DEBUG if self._trouble else logging.INFO, msg, *args)
        self._trouble = True

    @property
    def connected(self) -> bool:
        """Whether the underlying transport is up."""
        return self._client is not None and self._client.connected

    @property
    def quirks(self) -> dict[str, str]:
        """Recognised gateway/bus quirks: name → description with the fix."""
        return dict(self.attribution.quirks)

    @property
    def anomalies(self) -> int:
        """Counter of events that may have misattributed an answer (see :mod:`.attribution`)."""
        return self.attribution.anomalies

    @property
    def strict(self) -> bool:
        """No usable transaction ids: answers are attributed by the link's own checks."""
        return not self.attribution.tids_usable

    def _make_client(self) -> AsyncModbusTcpClient | AsyncModbusSerialClient:
        cfg = self.config
        # retries=0: a resend under the same TID is how late answers get misrouted (issue 15).
        common = dict(timeout=cfg.timeout_s, retries=0, reconnect_delay=0,
                      trace_packet=self._trace_packet if cfg.tolerate_fixed_tid else None)
        if cfg.transport == "tcp":
            client = AsyncModbusTcpClient(cfg.host, port=cfg.port, **common)
        else:
            client = AsyncModbusSerialClient(cfg.serial_port, framer=FramerType.RTU,
                                             baudrate=cfg.baudrate, bytesize=8, parity="N",
                                             stopbits=1, **common)
        # Count every received byte before pymodbus parses it (asyncio looks the method up on
        # the protocol instance, so an instance attribute is what the transport calls).
        ctx = client.ctx
        original = ctx.datagram_received

        def received(data: bytes, addr: tuple | None) -> None:
            if self._client is client:
                self.attribution.received(data)
            original(data, addr)

        ctx.datagram_received = received
        return client

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        # Gateways answering with a fixed MBAP transaction id: give the response the id of the
        # one pending request (requests are serialised, so there is exactly one).
        client = self._client
        if sending or client is None or self.config.transport != "tcp" or len(data) < 2:
            return data
        tid = client.ctx.request_transaction_id
        return tid.to_bytes(2, "big") + data[2:]

    async def connect(self, max_wait_s: float | None = None) -> None:
        """Connect, retrying with doubling back-off, then drain unsolicited bytes.

        Parameters
        ----------
        max_wait_s : float, optional
            Give up after this long [s]; ``None`` = keep trying forever.

        Raises
        ------
        ModbusLinkError
            When ``max_wait_s`` passed without a connection.
        """
        first, most = self.config.connect_backoff_s
        delay = first
        deadline = None if max_wait_s is None else _loop_s() + max_wait_s
        while True:
            self.close()
            self._client = self._make_client()
            self.attribution.draining = True
            if await self._client.connect():
                break
            _honour_cancel()
            left = None if deadline is None else deadline - _loop_s()
            if left is not None and left <= 0:
                self.close()
                raise ModbusLinkError(f"cannot connect to {self.config.describe()} "
                                      f"within {max_wait_s:g} s")
            self._incident("cannot connect to %s; retrying in %.1f s",
                           self.config.describe(), delay)
            await asyncio.sleep(delay if left is None else min(delay, left))
            delay = min(2 * delay, most)
        self.stats.connects += 1
        await self._drain()
        self.attribution.connected()
        _LOG.log(logging.DEBUG if self._trouble or self.stats.connects > 1 else logging.INFO,
                 "connected to %s", self.config.describe())

    async def _drain(self) -> None:
        try:
            if not self.config.drain_s or self._client is None:
                return
            await asyncio.sleep(self.config.drain_s)
            ctx = self._client.ctx
            if ctx.recv_buffer:
                self.stats.drained_bytes += len(ctx.recv_buffer)
                _LOG.info("discarded %d unsolicited byte(s) after connect: %s",
                          len(ctx.recv_buffer), ctx.recv_buffer[:32].hex())
                ctx.recv_buffer = b""
        finally:
            self.attribution.draining = False

    def close(self) -> None:
        """Close the connection (a later request reconnects); anything pending is void."""
        self.attribution.abandon()
        if self._client is not None:
            self._client.close()
            self._client = None

    def reset(self, exc: BaseException | None = None) -> None:
        """After a timeout or an unattributable answer: on TCP a new connection (late answers
        die with the old one); on RTU the line is the line — reopening the port changes
        nothing on the bus, so the receive buffer is discarded and the byte accounting
        reports whatever still arrives."""
        client = self._client
        if (self.config.transport == "rtu" and client is not None and client.connected
                and not isinstance(exc, OSError)):
            client.ctx.recv_buffer = b""
            return
        self.close()

    async def settle(self) -> None:
        """On RTU, before a group of answers is used: wait until the last answer is twice
        ``timeout_s`` old, so that a real answer that an impostor frame overtook has arrived
        and been counted — also one delayed past the timeout by up to the timeout again (a
        gateway's latency spike). Later answers are beyond what RTU can attribute; the
        bench (``bench/modbus_faults.py``) states the delays it tested. (TCP needs no wait:
        transaction ids, or without them one connection per set of distinguishable
        requests.)"""
        if self.config.transport == "rtu":
            left = 2 * self.config.timeout_s - (_loop_s() - self._last_request)
            await asyncio.sleep(max(left, self.config.settle_s))

    async def read(self, address: int, count: int, device_id: int | None = None) -> list[int]:
        """FC 03: read ``count`` holding registers from zero-based ``address``.

        Timeouts, unattributable answers and transient exceptions (5, 6, 10, 11) are retried,
        ``attempts`` tries in all, with doubling back-off and a new connection after a timeout
        or an unattributable answer.

        Returns
        -------
        list of int
            The unsigned 16-bit words, exactly ``count`` of them.

        Raises
        ------
        ModbusDeviceError
            Exception response (final, or transient on every try).
        ModbusLinkError
            No valid answer after ``attempts`` tries with reconnects.
        """
        if not 1 <= count <= 125:
            raise ValueError(f"FC 03 reads 1–125 registers, not {count}")
        unit = self.config.device_id if device_id is None else device_id
        last: Exception | None = None
        delay = self.config.retry_delay_s
        for attempt in range(self.config.attempts):
            if attempt:
                self.stats.retries += 1
                await asyncio.sleep(delay)
                delay *= 2
            try:
                rr = await self._request(3, address, count, unit)
            except ModbusDeviceError as exc:
                if exc.exception_code not in TRANSIENT_EXCEPTIONS:
                    raise
                self.stats.transient_exceptions += 1
                last = exc
                # Absorbed by the retry in the normal case: not an incident of its own (the
                # caller reports the read if every try fails).
                _LOG.debug("read %d×%d from unit %d: transient Modbus exception %d "
                           "(try %d/%d)", address, count, unit, exc.exception_code,
                           attempt + 1, self.config.attempts)
                continue
            except ModbusLinkError as exc:
                last = exc
                self._incident("read %d×%d from unit %d failed (try %d/%d): %s", address,
                               count, unit, attempt + 1, self.config.attempts, exc)
                continue  # _request has reset the connection (TCP) or flushed the line (RTU)
            return list(rr.registers)
        self.stats.failures += 1
        if isinstance(last, ModbusDeviceError):
            raise last
        hint = "".join(f"; {text}" for name, text in self.attribution.quirks.items()
                       if name == "fixed_tid")
        raise ModbusLinkError(f"read of {count} register(s) at address {address} from "
                              f"{self.config.describe()} failed: {last}{hint}")

    async def write(self, address: int, word: int, device_id: int | None = None) -> None:
        """FC 06: write one holding register, sent exactly once (no retry, no resend).

        Raises
        ------
        ModbusDeviceError
            Exception response.
        ModbusLinkError
            No answer, or an answer that cannot be attributed to this write.
        """
        if not 0 <= word <= 0xFFFF:
            raise ValueError(f"register word {word} is not in 0…65535")
        unit = self.config.device_id if device_id is None else device_id
        try:
            await self._request(6, address, word, unit)
        except ModbusLinkError:
            self.stats.failures += 1
            self._trouble = True
            raise

    async def _request(self, fc: int, address: int, arg: int, unit: int):
        async with self._lock:
            if self.connected and self.attribution.needs_new_connection(fc, address, arg):
                # Same-looking answers to two requests on one connection cannot be told
                # apart without transaction ids: start a fresh connection.
                self.close()
            if not self.connected:
                await self.connect(max_wait_s=self.config.timeout_s)
            gap = self.config.request_gap_s - (_loop_s() - self._last_request)
            if gap > 0:
                await asyncio.sleep(gap)
            client = self._client
            assert client is not None
            self.stats.requests += 1
            self.attribution.begin(fc, address, arg, client.ctx.next_tid + 1
                                   if self.config.transport == "tcp" else 0)
            try:
                if fc == 3:
                    rr = await client.read_holding_registers(address, count=arg, device_id=unit)
                else:
                    rr = await client.write_register(address, arg, device_id=unit)
            except (ModbusException, OSError) as exc:
                self.attribution.end(fc, arg, None)
                self.reset(exc)  # a late answer must never reach a later request
                raise ModbusLinkError(str(exc)) from exc
            finally:
                self._last_request = _loop_s()
            error = rr.isError()
            if self.config.transport == "rtu" and self.config.settle_s:
                await asyncio.sleep(self.config.settle_s)
            problem = self.attribution.end(fc, arg, error)
            problem = problem or _mismatch(rr, fc, address, arg, error)
            if problem:
                self.stats.unattributable += 1
                self.reset(None)
                raise _Unattributable(f"unattributable answer to FC {fc} at {address}: "
                                      f"{problem}")
            if error:
                code = getattr(rr, "exception_code", 0)
                raise ModbusDeviceError(
                    f"unit {unit} answered FC {fc} at address {address} "
                    f"with Modbus exception {code}", code, address)
            self.stats.last_ok_monotonic = time.monotonic()
            if self._trouble:
                _LOG.debug("link to %s answers again", self.config.describe())
                self._trouble = False
            return rr


def _mismatch(rr, fc: int, address: int, arg: int, error: bool) -> str | None:
    """What makes ``rr`` not an answer to (fc, address, arg), or None."""
    if (rr.function_code & 0x7F) != fc:
        return f"function code {rr.function_code} answers FC {fc}"
    if error:
        return None
    if fc == 3 and len(rr.registers) != arg:
        return f"asked for {arg} registers, got {len(rr.registers)}"
    if fc == 6 and (rr.address != address or list(rr.registers[:1]) != [arg]):
        return f"write echo {rr.address}/{list(rr.registers)} for {address}/{arg}"
    return None
