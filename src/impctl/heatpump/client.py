"""The heat-pump client: generation detection, decoded reads, snapshots, safe writes."""

from __future__ import annotations

import json
import logging
from datetime import datetime
from pathlib import Path

from ..atomic import replacing
from ..clock import VirtualClock
from ..errors import InputError
from ..kronoterm.decode import Reading, decode
from ..kronoterm.generation import GenerationReport, detect
from ..kronoterm.registers import Generation, Register, register
from ..kronoterm.snapshot import SNAPSHOT_REGISTERS, Snapshot, plan_blocks
from ..modbus import LinkConfig, ModbusDeviceError, ModbusLink, to_int16, uint32
from .attributed import TRIES, attributed, unattributable
from .budget import WriteBudget
from .config import ExternalRegister, HeatPumpConfig
from .errors import HeatPumpError, UnsupportedFeature, WriteRefused
from .writes import WriteResult, check_restore, safe_write

_LOG = logging.getLogger(__name__)

_NO_Q_HC = ("compact (TT3000) controller has no heat-power register (2329) and no heat meter "
            "is configured")
#: A room temperature an external sensor may report [°C] (a sensor's error code, e.g. −60.0
#: from a raw −600, is missing whatever its ``valid`` allows): the NIGHTS reader's range.
ROOM_PLAUSIBLE_C = (-40.0, 60.0)
#: A heat output an external meter may report [W] (negative while a defrost draws heat from
#: the water): the NIGHTS reader's range.
HEAT_PLAUSIBLE_W = (-25_000.0, 100_000.0)


class HeatPumpClient:
    """Reads and safely writes a Kronoterm heat pump over Modbus.

    Parameters
    ----------
    config : HeatPumpConfig
    clock : VirtualClock, optional
        Source of timestamps and of the budget's day; real time by default.
    budget : WriteBudget, optional
        Required for writes; without it every write is refused.

    Examples
    --------
    >>> async with HeatPumpClient(cfg, budget=WriteBudget(path, 12)) as hp:  # doctest: +SKIP
    ...     snap = await hp.snapshot()
    ...     await hp.set_loop1_setpoint(18.0)
    """

    def __init__(self, config: HeatPumpConfig, *, clock: VirtualClock | None = None,
                 budget: WriteBudget | None = None) -> None:
        self.config = config
        self.clock = clock or VirtualClock.real()
        self.budget = budget
        if budget is not None and budget.daily_limit != config.writes.daily_budget:
            _LOG.warning("write budget file allows %d writes/day but heatpump.writes."
                         "daily_budget is %d; the file's limit applies", budget.daily_limit,
                         config.writes.daily_budget)
        self.link = ModbusLink(config.link)
        self._ext_links: dict[LinkConfig, ModbusLink] = {}
        self._generation = (None if config.generation == "auto"
                            else Generation(config.generation))
        #: Evidence of the last detection (a configured generation needs none).
        self.generation_report: GenerationReport | None = (
            None if self._generation is None else
            GenerationReport(self._generation, {"config": "generation set in [heatpump]"},
                             source="configured"))
        #: Where :meth:`write_health` puts the status file (the daemon sets it).
        self.health_path: Path | None = None
        self._quirks_written: frozenset[str] = frozenset()

    async def __aenter__(self) -> HeatPumpClient:
        await self.connect()
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    async def connect(self, max_wait_s: float | None = None) -> None:
        """Connect (own retry loop, see :meth:`ModbusLink.connect`) and detect the generation
        if it is not configured."""
        await self.link.connect(max_wait_s)
        if self._generation is None:
            await self.detect_generation()

    def close(self) -> None:
        """Close all links."""
        self.link.close()
        for link in self._ext_links.values():
            link.close()

    @property
    def generation(self) -> Generation:
        """The controller generation (configured or detected)."""
        if self._generation is None:
            raise HeatPumpError("controller generation unknown: connect() or "
                                "detect_generation() first")
        return self._generation

    async def detect_generation(self) -> GenerationReport:
        """Probe the extended registers and cross-check them (:mod:`.generation`).

        In doubt the client uses the compact set and :meth:`require_heat_power` refuses
        2329 with one line naming the evidence.

        Raises
        ------
        ModbusDeviceError
            Any exception other than 2 on every try (e.g. busy): nothing can be concluded.
        ModbusLinkError
            No answer.
        """
        report = await detect(self.link)
        self._generation = report.generation
        self.generation_report = report
        _LOG.info("controller generation: %s (%s)", report.generation.value, report.evidence)
        if report.doubt:
            _LOG.warning("%s", report.doubt)
        elif report.generation is Generation.COMPACT and self.config.heat_meter is None:
            _LOG.warning("%s: Q_HC cannot be read; experiments that need it will refuse to run",
                         _NO_Q_HC)
        self.write_health()
        return report

    def health(self) -> dict:
        """Generation evidence and recognised link quirks (shown by ``impctl status``)."""
        report = self.generation_report
        return {"link": self.config.link.describe(),
                "generation": None if report is None else report.as_dict(),
                "quirks": self.link.quirks,
                "unattributable_answers": self.link.stats.unattributable}

    def write_health(self) -> None:
        """Write :meth:`health` to ``health_path`` (if set) for ``impctl status``."""
        if self.health_path is None:
            return
        self._quirks_written = frozenset(self.link.quirks)
        try:
            with replacing(self.health_path) as tmp:
                tmp.write_text(json.dumps(self.health(), indent=1))
        except OSError as exc:  # status is a convenience: never fail a read over it
            _LOG.debug("cannot write %s: %s", self.health_path, exc)

    def heat_power_source(self) -> str | None:
        """Where Q_HC comes from (``"heat meter …"``, ``"register 2329"``) or ``None``."""
        if self.config.heat_meter is not None:
            return f"heat meter {self.config.heat_meter.describe()}"
        if self.generation_report is not None and self.generation_report.doubt:
            return None
        return "register 2329" if self.generation is Generation.EXTENDED else None

    def require_heat_power(self) -> str:
        """The Q_HC source, or :class:`UnsupportedFeature` for an IMP that needs it."""
        source = self.heat_power_source()
        report = self.generation_report
        if source is None and report is not None and report.doubt:
            raise UnsupportedFeature(report.doubt)
        if source is None:
            raise UnsupportedFeature(f"{_NO_Q_HC}; configure [heatpump.heat_meter] or run only "
                                     "experiments that do not need the heat output")
        return source

    async def read(self, key: str | int) -> Reading:
        """Read and decode one register (missing if not on this controller)."""
        reg = register(key)
        now = self.clock.now()
        if not reg.in_generation(self.generation):
            return Reading.unavailable(reg.name, reg.unit, now,
                                       f"not on a {self.generation.value} controller",
                                       f"register {reg.ma}")
        words = await attributed(self.link, lambda: self.link.read(reg.address, reg.words))
        if words is None:
            return Reading.unavailable(reg.name, reg.unit, self.clock.now(),
                                       unattributable(self.link), f"register {reg.ma}")
        return decode(reg, words, self.clock.now())

    async def read_external(self, ext: ExternalRegister, name: str, unit: str,
                            plausible: tuple[float, float] = (-1e9, 1e9)) -> Reading:
        """Read a value from an external device (room sensor, heat meter): missing outside
        its configured ``valid`` range or the quantity's ``plausible`` one."""
        link = self._link_for(ext)
        source = f"external {ext.describe()}"
        try:
            words = await attributed(link, lambda: link.read(
                ext.address, ext.words, device_id=ext.device_id))
        except ModbusDeviceError as exc:
            return Reading.unavailable(name, unit, self.clock.now(), str(exc), source)
        if words is None:
            return Reading.unavailable(name, unit, self.clock.now(), unattributable(link),
                                       source)
        raw = to_int16(words[0]) if ext.datatype == "int16" else words[0]
        if ext.words == 2:
            raw = uint32(words)
            if ext.datatype == "int32" and raw & 0x80000000:
                raw -= 1 << 32
        value = raw * ext.scale
        stamp = self.clock.now()
        low, high = max(ext.valid[0], plausible[0]), min(ext.valid[1], plausible[1])
        if not low <= value <= high:
            return Reading(name, None, unit, stamp, True,
                           f"{value:g} {unit} outside the valid range {low:g}…{high:g}", raw,
                           source)
        return Reading(name, value, unit, stamp, raw=raw, source=source)

    def _link_for(self, ext: ExternalRegister) -> ModbusLink:
        if ext.link is None:
            return self.link
        if ext.link not in self._ext_links:
            self._ext_links[ext.link] = ModbusLink(ext.link)
        return self._ext_links[ext.link]

    async def snapshot(self) -> Snapshot:
        """Read everything one poll needs, in contiguous FC 03 blocks.

        A block answered with a Modbus exception marks its readings missing; a link failure
        raises :class:`ModbusLinkError` (nothing partial is returned then).
        """
        gen = self.generation
        start = self.clock.now()
        regs = [register(n) for n in SNAPSHOT_REGISTERS.values()]
        room = self.config.room_sensor
        if not isinstance(room, ExternalRegister):
            regs.append(register("room_" + room))
        if self.config.heat_meter is None:
            regs.append(register("power_thermal"))
        blocks = plan_blocks([r for r in regs if r.in_generation(gen)], gen)
        for _ in range(TRIES):
            before = self.link.anomalies
            words, failed = await self._read_blocks(blocks)
            await self.link.settle()
            if self.link.anomalies == before:
                break
            # Some answer in this poll may belong to another request: read it all again on
            # a fresh connection (TCP) or a flushed line (RTU); after the last try nothing of
            # it is used.
            self.link.reset()
        else:
            why = unattributable(self.link)
            words, failed = {}, {ma: why for first, count in blocks
                                 for ma in range(first, first + count)}
        def from_register(reg: Register) -> Reading:
            source = f"register {reg.ma}"
            if not reg.in_generation(gen):
                return Reading.unavailable(reg.name, reg.unit, start,
                                           f"not on a {gen.value} controller", source)
            if reg.ma in failed:
                return Reading.unavailable(reg.name, reg.unit, start, failed[reg.ma], source)
            got = [words[ma] for ma in range(reg.ma, reg.ma + reg.words)]
            return decode(reg, [w for w, _ in got], got[0][1])

        if frozenset(self.link.quirks) != self._quirks_written:
            self.write_health()  # a newly recognised quirk shows in impctl status
        fields = {f: from_register(register(r)) for f, r in SNAPSHOT_REGISTERS.items()}
        if isinstance(room, ExternalRegister):
            fields["t_air_c"] = await self.read_external(room, "t_air", "°C",
                                                         ROOM_PLAUSIBLE_C)
        else:
            fields["t_air_c"] = from_register(register("room_" + room))
        if self.config.heat_meter is not None:
            fields["q_hc_w"] = await self.read_external(self.config.heat_meter, "q_hc", "W",
                                                        HEAT_PLAUSIBLE_W)
        elif gen is Generation.EXTENDED:
            fields["q_hc_w"] = from_register(register("power_thermal"))
        else:
            fields["q_hc_w"] = Reading.unavailable("q_hc", "W", start, _NO_Q_HC)
        return Snapshot(timestamp=start, generation=gen, **fields)

    async def _read_blocks(self, blocks: list[tuple[int, int]]
                           ) -> tuple[dict[int, tuple[int, datetime]], dict[int, str]]:
        words: dict[int, tuple[int, datetime]] = {}
        failed: dict[int, str] = {}
        for first, count in blocks:
            try:
                block = await self.link.read(first - 1, count)
            except ModbusDeviceError as exc:
                for ma in range(first, first + count):
                    failed[ma] = f"Modbus exception {exc.exception_code}"
                continue
            stamp = self.clock.now()
            for i, word in enumerate(block):
                words[first + i] = (word, stamp)
        return words, failed

    async def write(self, key: str | int, value: float) -> WriteResult:
        """Safely write one whitelisted register (see :mod:`impctl.heatpump.writes`)."""
        reg = register(key)
        if not reg.in_generation(self.generation):
            raise WriteRefused(f"register {reg.ma} is not on a {self.generation.value} "
                               "controller")
        return await safe_write(self.link, reg, value, self.config.writes, self.budget,
                                self.clock)

    async def restore(self, key: str | int, value: float) -> WriteResult:
        """Put an owner's value back (physical unit): whitelisted and plausibility-checked but
        not clamped to the experiment limits; may use the budget's restore reserve."""
        reg = register(key)
        if not reg.in_generation(self.generation):
            raise WriteRefused(f"register {reg.ma} is not on a {self.generation.value} "
                               "controller")
        return await safe_write(self.link, reg, value, self.config.writes, self.budget,
                                self.clock, restore=True)

    async def restore_raw(self, key: str | int, raw: int) -> WriteResult:
        """:meth:`restore` from a journaled raw (signed int16) register value."""
        reg = register(key)
        return await self.restore(reg, raw * reg.scale)

    def unrestorable(self, key: str | int, raw: int) -> str | None:
        """Why :meth:`restore_raw` would refuse to put ``raw`` back into ``key`` (an
        undocumented mode code, a sentinel, a register off the whitelist); None when it
        would not."""
        reg = register(key)
        try:
            check_restore(reg, raw * reg.scale, self.config.writes)
        except (WriteRefused, InputError) as exc:
            return str(exc)
        return None

    async def set_loop1_setpoint(self, t_c: float) -> WriteResult:
        """Write the loop-1 desired temperature (2187) [°C], clamped to the configured limits."""
        return await self.write(2187, t_c)

    async def set_loop1_mode(self, mode: int) -> WriteResult:
        """Write the loop-1 mode (2042): 0 off, 1 on, 2 by schedule."""
        return await self.write(2042, mode)

