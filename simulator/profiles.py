"""Controller profiles that differ from the documents: undocumented registers that answer.

Some real TT3000/WPG controllers do not refuse reads of registers their document does not list
(Favio25/Kronoterm-homeassistant issue #39): 2130 answers with a low number, and a read of
2329 on such a unit returned 1234. A generation probe that trusts any plausible answer takes
such a unit for an extended controller and reads Q_HC from a register that does not exist.
"""

from __future__ import annotations

from pymodbus.pdu import ModbusPDU
from pymodbus.pdu.register_message import ReadHoldingRegistersResponse

from impctl.kronoterm.registers import Generation
from impctl.modbus import to_word

from .image import in_layout

#: Undocumented registers of the compact profile and what they answer (raw, signed).
UNDOCUMENTED_RAW: dict[int, int] = {2130: 150, 2329: 1234, 2129: 0, 2327: 0, 2318: 0,
                                    2371: 0, 2372: 0}


async def tt3000_undocumented(sim, request: ModbusPDU) -> ModbusPDU:
    """Answer an FC 03 on a compact controller that does not refuse undocumented addresses."""
    words = []
    for pdu_address in range(request.address, request.address + request.count):
        ma = pdu_address + 1
        if in_layout(ma, Generation.COMPACT):
            words.extend(await sim.read_words(ma))
        else:
            words.append(to_word(UNDOCUMENTED_RAW.get(ma, 0)))
    return ReadHoldingRegistersResponse(registers=words, dev_id=request.dev_id)
