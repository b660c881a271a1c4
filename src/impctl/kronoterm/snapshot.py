"""The snapshot: what one poll of the heat pump returns, and how its reads are grouped."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, fields
from datetime import datetime

from .decode import Reading
from .registers import REGISTERS, Generation, Register

#: Snapshot field → register name, for the fields read from the Kronoterm itself.
#: ``t_air_c`` and ``q_hc_w`` may come from external devices instead (see the client).
SNAPSHOT_REGISTERS: Mapping[str, str] = {
    "t_out_c": "t_outdoor",
    "t_supply_c": "t_supply",
    "t_return_c": "t_return",
    "t_dhw_c": "t_dhw",
    "p_el_w": "power_electrical",
    "working_function": "working_function",
    "defrost": "defrost",
    "system_running": "system_running",
    "system_on": "system_on",
    "error_summary": "error_summary",
    "error_active": "error_active",
    "errors_1": "errors_1",
    "errors_2": "errors_2",
    "sensor_errors": "sensor_errors",
    "warnings_1": "warnings_1",
    "additional_bits": "additional_bits",
    "remote_off_input": "remote_off_input",
    "loop1_mode": "loop1_mode",
    "loop1_pump": "loop1_pump",
    "loop1_setpoint_c": "loop1_setpoint",
    "loop1_target_c": "loop1_target",
    "energy_electrical_kwh": "energy_electrical",
    "energy_thermal_kwh": "energy_thermal",
}


@dataclass(frozen=True)
class Snapshot:
    """One poll: every value with its own timestamp and missing flag.

    Temperatures are °C, powers W, energies kWh; enums and bitmasks are their raw codes as
    floats. A value that is a sentinel, implausible, not on this controller or unreadable is a
    :class:`Reading` with ``missing=True`` and a reason, never a number.
    """

    timestamp: datetime
    generation: Generation
    t_air_c: Reading
    t_out_c: Reading
    q_hc_w: Reading
    p_el_w: Reading
    t_supply_c: Reading
    t_return_c: Reading
    t_dhw_c: Reading
    working_function: Reading
    defrost: Reading
    system_running: Reading
    system_on: Reading
    error_summary: Reading
    error_active: Reading
    errors_1: Reading
    errors_2: Reading
    sensor_errors: Reading
    warnings_1: Reading
    additional_bits: Reading
    remote_off_input: Reading
    loop1_mode: Reading
    loop1_pump: Reading
    loop1_setpoint_c: Reading
    loop1_target_c: Reading
    energy_electrical_kwh: Reading
    energy_thermal_kwh: Reading

    def readings(self) -> dict[str, Reading]:
        """All readings by snapshot field name."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if isinstance(getattr(self, f.name), Reading)}

    def values(self) -> dict[str, float | None]:
        """Field → value (``None`` when missing), e.g. for logging a row."""
        return {name: r.value for name, r in self.readings().items()}

    def missing(self) -> dict[str, str]:
        """Field → reason, for the missing readings only."""
        return {name: r.reason for name, r in self.readings().items() if r.missing}


def _documented(ma: int, generation: Generation) -> bool:
    reg = REGISTERS.get(ma)
    if reg is None:  # the low word of a uint32 counter
        prev = REGISTERS.get(ma - 1)
        return prev is not None and prev.words == 2 and prev.in_generation(generation)
    return reg.in_generation(generation)


def plan_blocks(regs: Iterable[Register], generation: Generation,
                max_count: int = 60) -> list[tuple[int, int]]:
    """Group registers into contiguous FC 03 reads with pairwise different lengths.

    A block spans only documented registers of ``generation`` (no undocumented gaps: some
    controllers answer those with an exception), at most ``max_count`` words. Blocks that would
    have the same length are widened over documented neighbours where possible: without
    transaction ids an answer is told from the answer to another block by its length (see
    :mod:`impctl.modbus.attribution`).

    Returns
    -------
    list of (first MA, number of words)
    """
    def documented(ma: int) -> bool:
        return _documented(ma, generation)

    wanted = sorted({ma for r in regs for ma in range(r.ma, r.ma + r.words)})
    blocks: list[tuple[int, int]] = []
    for ma in wanted:
        if blocks:
            start, count = blocks[-1]
            end = start + count
            if ma - start < max_count and all(documented(m) for m in range(end, ma + 1)):
                blocks[-1] = (start, ma - start + 1)
                continue
        blocks.append((ma, 1))
    return _distinct_lengths(blocks, generation, max_count)


def _distinct_lengths(blocks: list[tuple[int, int]], generation: Generation,
                      max_count: int) -> list[tuple[int, int]]:
    # The blocks with the least room to grow choose first; the others widen around them.
    def room(block: tuple[int, int]) -> tuple[int, int]:
        lo, hi = block[0], block[0] + block[1]
        while hi - lo < max_count and _documented(hi, generation):
            hi += 1
        while hi - lo < max_count and _documented(lo - 1, generation):
            lo -= 1
        return lo, hi

    used: set[int] = set()
    chosen: dict[int, tuple[int, int]] = {}
    for i in sorted(range(len(blocks)), key=lambda i: (lambda r: r[1] - r[0])(room(blocks[i]))):
        start, count = blocks[i]
        lo, hi = room(blocks[i])
        size = next((n for n in range(count, hi - lo + 1) if n not in used), count)
        end = min(start + size, hi)
        chosen[i] = (end - size, size)
        used.add(size)
    return [chosen[i] for i in range(len(blocks))]
