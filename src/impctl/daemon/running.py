"""What the daemon's hooks see of the running daemon (:class:`~impctl.daemon.service.Daemon`),
as a typing protocol: the MQTT link reads and drives it without importing the service that
starts it."""

from __future__ import annotations

import asyncio
from typing import Any, Protocol

from ..clock import VirtualClock
from ..config import Config
from ..controller import NightController
from ..heatpump import HeatPumpClient
from ..store import Store
from .house_inputs import HouseInputs
from .locks.store import DaemonLock


class RunningDaemon(Protocol):
    """The parts of a running daemon its hooks use (typing only)."""

    cfg: Config
    clock: VirtualClock
    stop: asyncio.Event
    store: Store | None
    client: HeatPumpClient | None
    controller: NightController | None
    #: the MQTT link (:class:`~impctl.daemon.mqtt_link.MqttLink`) when ``[mqtt]`` is configured
    mqtt: Any
    #: the house's own sensors (:class:`~impctl.daemon.house_inputs.HouseInputs`) when
    #: ``[inputs]`` is configured
    house_inputs: HouseInputs | None
    #: set while the heat pump answers
    _connected: asyncio.Event
    #: held by whatever drives the heat pump (a night, a restore, an idle read)
    _heat_pump_lock: asyncio.Lock
    #: the store's one-process lock (``daemon.lock``), None before it is taken
    _lock: DaemonLock | None
    #: the running night's task (None or done between nights)
    _night_task: asyncio.Task | None

    def night_running(self) -> bool:
        """True from a night's first action (its pre-heat) to the end of its restore."""
        ...

    def want_season(self) -> None:
        """A new usable owner night: refresh the season model (the morning refit)."""
        ...

    def _status(self, text: str) -> None:
        """Tell systemd (STATUS=) and Home Assistant what the daemon does."""
        ...

    def _idle_status(self) -> str:
        """The status line between nights."""
        ...

    def _restorable(self) -> list:
        """Journal entries still to put back (the heating curve's left while the owner has it)."""
        ...
