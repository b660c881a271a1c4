"""The daemon's side of ``[inputs]``: the latest value of each of the house's own sensors, and a
row of them stored with every sample.

The MQTT bridge hands every message on an input topic to :meth:`HouseInputs.receive` (no I/O);
the night controller calls :meth:`HouseInputs.record` after it stored a sample, the idle reads
between nights too (the outdoor-sensor check). Ages are on the daemon's clock (the simulated
one in a demo), on its monotonic scale. A value older than ``max_age_s`` at the sample, a
malformed payload and Home Assistant's ``unavailable`` are missing; a malformed payload is
logged once per topic until the topic sends a good value again.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import datetime

from ..clock import VirtualClock
from ..heatpump import Snapshot
from ..mqtt.inputs import InputsConfig, parse_payload
from ..store import Store
from ..store.recording.house_inputs import HouseInputRow

_LOG = logging.getLogger("impctl.inputs")
#: How often the outdoor-sensor offset is re-evaluated [s, daemon's clock].
OFFSET_CHECK_S = 3600.0


@dataclass(frozen=True)
class _Latest:
    value: float | None
    received_s: float   # on the clock's monotonic scale: a wall-clock step moves no age
    payload: bytes


class HouseInputs:
    """The latest value per input topic, and the rows stored with the samples.

    Parameters
    ----------
    cfg : InputsConfig
    clock : VirtualClock (ages are measured on it)
    store : Store, or None until the daemon opened it
    """

    def __init__(self, cfg: InputsConfig, clock: VirtualClock, store: Store | None = None):
        self.cfg, self.clock, self.store = cfg, clock, store
        self.names = cfg.topics()  # topic → input name
        self._latest: dict[str, _Latest] = {}
        self._problem: dict[str, str] = {}  # topic → the problem last logged
        self._no_p_el_logged = False
        self._offset_checked: datetime | None = None
        self._offset_warned = False

    @property
    def topics(self) -> list[str]:
        """The topics to subscribe to."""
        return list(self.names)

    def receive(self, topic: str, payload: bytes, retained: bool = False) -> None:
        """A message on an input topic: parse it, keep it as the latest.

        ``retained``: delivered from the broker's retained store (at a (re)subscription), not
        published now. The same payload again that way is no news: its age runs on from when
        it first arrived (a Home Assistant gone quiet does not look fresh after a reconnect).
        """
        name = self.names.get(topic)
        if name is None:
            return
        latest = self._latest.get(topic)
        if retained and latest is not None and latest.payload == payload:
            return
        value, problem = parse_payload(name, payload)
        if problem is not None:
            if self._problem.get(topic) != problem:
                _LOG.warning("input %s (%s) ignored: %s; missing until a plain number "
                             "arrives", name.split(":")[0], topic, problem)
                self._problem[topic] = problem
        elif value is not None and topic in self._problem:
            _LOG.info("input %s (%s) back: %g", name.split(":")[0], topic, value)
            del self._problem[topic]
        self._latest[topic] = _Latest(value, self.clock.monotonic_s(), payload)

    def _fresh(self, topic: str, at: datetime, max_age_s: float) -> tuple[float | None,
                                                                         float | None]:
        """(value, age s) of ``topic`` now (the sample at ``at`` was just taken); (None, None)
        when missing or stale. Ages run on the monotonic clock: after a wall-clock step back
        a value heard hours ago is not fresh again."""
        latest = self._latest.get(topic)
        if latest is None or latest.value is None:
            return None, None
        age = max(0.0, self.clock.monotonic_s() - latest.received_s)
        if age > max_age_s:
            return None, None
        return latest.value, age

    def row(self, night_id: int | None, snap: Snapshot) -> HouseInputRow:
        """The inputs as they stand at ``snap``'s instant."""
        cfg, at = self.cfg, snap.timestamp
        age_limit = cfg.max_age_s
        house, house_age = (self._fresh(cfg.house_power_w, at, age_limit)
                            if cfg.house_power_w else (None, None))
        p_house = house
        if house is not None and cfg.house_power_includes_heat_pump:
            p_el = snap.p_el_w.value
            if p_el is None:
                p_house = None
                if not self._no_p_el_logged:
                    _LOG.error("inputs.house_power_includes_heat_pump: the heat pump reports "
                               "no electrical power (%s; register 2129 exists on extended "
                               "controllers only), so p_house_w stays missing",
                               snap.p_el_w.reason or "missing")
                    self._no_p_el_logged = True
            else:
                # Never a negative heat: a meter lagging the heat pump's start is no reading.
                p_house = house - p_el if house - p_el >= 0 else None
        rooms = [self._fresh(t, at, age_limit) for t in cfg.room_temperature_c]
        # The mean of every room, or nothing: a mean over whichever sensors reported would
        # jump by the rooms' difference when one goes quiet, and look like the house cooling.
        have_rooms = bool(rooms) and all(v is not None for v, _ in rooms)
        t_rooms = sum(v for v, _ in rooms) / len(rooms) if have_rooms else None
        rooms_age = max(a for _, a in rooms) if have_rooms else None
        t_ref, t_ref_age = (self._fresh(cfg.outdoor_temperature_c, at, age_limit)
                            if cfg.outdoor_temperature_c else (None, None))
        occ, occ_age = (self._fresh(cfg.occupants, at, cfg.occupants_max_age_s)
                        if cfg.occupants else (None, None))
        return HouseInputRow(
            night_id=night_id, ts=at, house_power_w=house, house_power_age_s=house_age,
            p_house_w=p_house, t_rooms_c=t_rooms, t_rooms_age_s=rooms_age,
            rooms=len(rooms) if have_rooms else None, t_out_ref_c=t_ref,
            t_out_ref_age_s=t_ref_age, occupants=occ, occupants_age_s=occ_age,
            t_out_c=snap.t_out_c.value)

    def record(self, night_id: int | None, snap: Snapshot) -> None:
        """Store the inputs at ``snap`` (a night's sample, or ``night_id`` None between nights).

        Between nights only when there is something to compare (the reference outdoor
        temperature); never raises: a store error loses this row, not the night's sample.
        """
        if self.store is None:
            return
        row = self.row(night_id, snap)
        if night_id is None and (row.t_out_ref_c is None or row.t_out_c is None):
            return
        try:
            self.store.add_house_inputs(row)
            if row.t_out_ref_c is not None and row.t_out_c is not None:
                self._check_outdoor(row.ts)
        except Exception as exc:  # noqa: BLE001 - the night goes on without this row
            _LOG.error("could not store the house's inputs at %s: %s", row.ts, exc)

    def _check_outdoor(self, at: datetime) -> None:
        """Once an hour (daemon's clock): a persistent offset of the heat pump's outdoor
        sensor against the reference is logged and kept as an event, once until it clears."""
        if self._offset_checked is not None and (
                at - self._offset_checked).total_seconds() < OFFSET_CHECK_S:
            return
        self._offset_checked = at
        offset = self.store.outdoor_offset()
        persistent = offset is not None and offset.persistent
        if persistent and not self._offset_warned:
            _LOG.warning("%s", offset.describe())
            self.store.add_event("warning", offset.describe())
        self._offset_warned = persistent
