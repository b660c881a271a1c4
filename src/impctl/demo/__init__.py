"""``impctl demo``: the whole product on one machine, against a simulated heat pump.

1. the simulator (``impctl_sim``) serves a built-in demo house over real Modbus TCP on a free
   loopback port, on a clock of simulated time that advances only when the simulator and the
   daemon wait (a virtual-time event loop: the same nights however busy the machine);
2. the daemon (the same :class:`~impctl.daemon.service.Daemon` a gateway runs) schedules and
   runs the IMP campaign against it, nights starting at 22:00 local simulated time;
3. meanwhile the range classifiers are trained (or cached ones reused when their metadata
   matches);
4. the nights are exported and fitted (``impctl fit``), and the report is written.

The demo house is not drawn from any training population: its parameters are fixed in
``src/impctl/data/demo_house.toml`` and are the "truth" the summary compares against.

Modules: :mod:`.options` (what the demo runs: options, house, weather), :mod:`.campaign` (the
simulator and the daemon until the campaign is done), :mod:`.run` (the whole demo).
"""

from .campaign import campaign_summary
from .options import (
    DEFAULT_SPEED,
    TZ,
    DemoError,
    DemoOptions,
    demo_house,
    demo_weather,
    plant_summary,
)
from .run import run_demo

__all__ = ["DEFAULT_SPEED", "TZ", "DemoError", "DemoOptions", "campaign_summary", "demo_house",
           "demo_weather", "plant_summary", "run_demo"]
