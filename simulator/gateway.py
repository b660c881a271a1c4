"""What a faulty RS-485 gateway or a shared bus does to answers (issue 15 fault switches).

The server computes the true answer; :class:`GatewayFaults` decides how it reaches the client:
replaced by gateway exception 10/11, delayed past the client's timeout, sent twice (the copy
later), or preceded on an RTU line by a second master's answer of the same length. Random
choices come from their own seeded generator, so sensor noise does not change with them.
"""

from __future__ import annotations

import asyncio
import random

from pymodbus.constants import ExcCodes
from pymodbus.pdu import ExceptionResponse, ModbusPDU
from pymodbus.pdu.register_message import ReadHoldingRegistersResponse

from .faults import Faults

#: Exception codes a gateway sends when the RS-485 side did not answer.
GATEWAY_CODES = (ExcCodes.GATEWAY_PATH_UNAVIABLE, ExcCodes.GATEWAY_NO_RESPONSE)


class GatewayFaults:
    """Applies the gateway/bus faults of ``faults`` to each answer.

    Parameters
    ----------
    faults : Faults
        Consulted on every request (switchable at run time).
    seed : int
    """

    def __init__(self, faults: Faults, seed: int = 0) -> None:
        self.faults = faults
        self.rng = random.Random(seed)
        self.counts = {"gateway_exceptions": 0, "spikes": 0, "duplicates": 0, "foreign": 0}

    def _hit(self, rate: float) -> bool:
        return rate > 0 and self.rng.random() < rate

    def exception_instead(self, request: ModbusPDU) -> ModbusPDU | None:
        """Gateway exception 10 or 11 in place of the answer (the request never reached the
        controller), or None."""
        if not self._hit(self.faults.gateway_exception_rate):
            return None
        self.counts["gateway_exceptions"] += 1
        return ExceptionResponse(request.function_code, self.rng.choice(GATEWAY_CODES))

    def lose_write_answer(self, request: ModbusPDU) -> ModbusPDU | None:
        """After an executed FC 06: gateway exception 11 in place of the echo, or None."""
        if request.function_code != 6 or not self._hit(self.faults.write_answer_lost_rate):
            return None
        self.counts["gateway_exceptions"] += 1
        return ExceptionResponse(6, ExcCodes.GATEWAY_NO_RESPONSE)

    async def deliver(self, handler, request: ModbusPDU, response: ModbusPDU, addr,
                      rtu: bool) -> None:
        """Send ``response`` through the faulty gateway/bus."""
        faults = self.faults
        if self._hit(faults.spike_rate):
            self.counts["spikes"] += 1
            await asyncio.sleep(faults.spike_s)
        if not handler.transport:
            return  # the client hung up meanwhile: the late answer is lost with the socket
        if rtu and request.function_code == 3 and self._hit(faults.foreign_rate):
            self.counts["foreign"] += 1
            handler.server_send(self._foreign(request), addr)
            if faults.foreign_delay_s:  # the real answer comes late (a busy bus)
                await asyncio.sleep(faults.foreign_delay_s)
                if not handler.transport:
                    return
        handler.server_send(response, addr)
        if self._hit(faults.duplicate_rate):
            self.counts["duplicates"] += 1
            delay = self.rng.uniform(0.0, faults.duplicate_delay_s)

            def again() -> None:
                if handler.transport:
                    handler.server_send(response, addr)

            handler.loop.call_later(delay, again)

    def _foreign(self, request: ModbusPDU) -> ModbusPDU:
        # Another master's answer: same unit, same length, other content (plausible words).
        words = [self.rng.randrange(0, 600) for _ in range(request.count)]
        foreign = ReadHoldingRegistersResponse(registers=words, dev_id=request.dev_id)
        foreign.transaction_id = 0
        return foreign
