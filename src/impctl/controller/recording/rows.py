"""One row of an owner record: the snapshots taken in [start, start + interval) reduced to means.

The heat meter (2329) reads the instantaneous output of a heat pump that cycles, so a single
reading says little; the mean of a row's readings says how much heat the interval got. A value
a snapshot did not have (a sentinel, a sensor not fitted, a failed read) is missing there, never
a number; a column that fewer than ``min_coverage`` of the row's expected snapshots had is
missing in the row. Pure functions of the snapshots: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta

from ...heatpump import Snapshot
from ...store import Sample
from ...store.recording.house_inputs import HouseInputRow
from ..poll import _error_bits

#: Snapshot field → sample column, for the columns that are a row's mean.
MEAN_FIELDS = {"t_air_c": "t_air_c", "t_out_c": "t_out_c", "q_hc_w": "q_hc_w",
               "p_el_w": "p_el_w", "t_supply_c": "t_supply_c", "t_return_c": "t_return_c",
               "loop1_target_c": "t_flow_target_c"}
#: House-input columns that are a row's mean (their ages: the oldest value used).
_INPUT_MEANS = {"house_power_w": "house_power_age_s", "p_house_w": "house_power_age_s",
                "t_rooms_c": "t_rooms_age_s", "t_out_ref_c": "t_out_ref_age_s",
                "occupants": "occupants_age_s", "t_out_c": None}
#: Working function (2001) while the heat pump charges hot water.
DHW_FUNCTION = 1


def row_start(ts: datetime, interval_s: float) -> datetime:
    """The start of the row holding ``ts``: rows lie on a grid of ``interval_s`` from the
    POSIX epoch (on the hour and at every local noon when ``interval_s`` divides an hour and
    the zone's offset is whole quarter hours)."""
    s = ts.timestamp()
    return datetime.fromtimestamp(math.floor(s / interval_s + 1e-6) * interval_s, UTC)


def _mean(values: list[float], need: int) -> float | None:
    return sum(values) / len(values) if values and len(values) >= need else None


@dataclass
class RowBuilder:
    """The snapshots of one row so far.

    Parameters
    ----------
    start : the row's start (UTC, on the grid of :func:`row_start`)
    interval_s : the row's length [s]
    expected : snapshots a complete row holds (``interval_s`` / the snapshot interval, at
        least 1)
    min_coverage : share of ``expected`` a column needs to have a value
    """

    start: datetime
    interval_s: float
    expected: float
    min_coverage: float
    snapshots: list[Snapshot] = field(default_factory=list)
    inputs: list[HouseInputRow] = field(default_factory=list)

    @property
    def end(self) -> datetime:
        """The instant the row ends (exclusive)."""
        return self.start + timedelta(seconds=self.interval_s)

    @property
    def need(self) -> int:
        """Snapshots a column needs to have a value in the row."""
        return max(1, math.ceil(self.min_coverage * self.expected - 1e-9))

    def add(self, snap: Snapshot, inputs: HouseInputRow | None = None) -> None:
        """One more snapshot of the row (and the house's own sensors at it)."""
        self.snapshots.append(snap)
        if inputs is not None:
            self.inputs.append(inputs)

    def sample(self, record_id: int) -> Sample:
        """The row as stored (:class:`~impctl.store.Sample`, ``snapshots`` set)."""
        need = self.need
        means = {}
        for name, column in MEAN_FIELDS.items():
            values = [getattr(s, name).value for s in self.snapshots]
            means[column] = _mean([v for v in values if v is not None], need)
        functions = [s.working_function.value for s in self.snapshots
                     if s.working_function.value is not None]
        dhw = (sum(f == DHW_FUNCTION for f in functions) / len(functions)
               if len(functions) >= need else None)
        defrosts = [bool(s.defrost.value) for s in self.snapshots if s.defrost.value is not None]
        # A defrost seen is a defrost, however few snapshots saw the row; none seen is "none"
        # only when enough of them looked.
        defrost = True if any(defrosts) else (False if len(defrosts) >= need else None)
        bits = [b for b in (_error_bits(s) for s in self.snapshots) if b is not None]
        error_bits = None
        if bits:
            error_bits = 0
            for b in bits:
                error_bits |= b

        def last(name: str) -> float | None:
            values = [getattr(s, name).value for s in self.snapshots]
            return next((v for v in reversed(values) if v is not None), None)

        mode, system, function = last("loop1_mode"), last("system_on"), last("working_function")
        return Sample(
            night_id=record_id, ts=self.start, **means,
            working_function=None if function is None else int(function),
            defrost=defrost, error_bits=error_bits,
            loop_mode=None if mode is None else int(mode),
            setpoint_c=last("loop1_setpoint_c"),
            dhw_active=None if dhw is None else dhw > 0,
            dhw_share=None if dhw is None else round(dhw, 4),
            system_on=None if system is None else int(system),
            snapshots=len(self.snapshots))

    def inputs_row(self, record_id: int) -> HouseInputRow | None:
        """The house's own sensors over the row (means; each age the oldest value's), or None
        when none were read."""
        if not self.inputs:
            return None
        need = self.need
        values: dict[str, float | None] = {}
        for name, age in _INPUT_MEANS.items():
            used = [r for r in self.inputs if getattr(r, name) is not None]
            values[name] = _mean([getattr(r, name) for r in used], need)
            if age is not None and age not in values:
                ages = [getattr(r, age) for r in used if getattr(r, age) is not None]
                values[age] = max(ages) if values[name] is not None and ages else None
        rooms = next((r.rooms for r in reversed(self.inputs) if r.rooms is not None), None)
        return HouseInputRow(night_id=record_id, ts=self.start, rooms=rooms, **values)
