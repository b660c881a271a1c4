"""The clock, the night rules and the heat-pump client as the configuration asks for them:
what the daemon and the device commands (``impctl night``, ``status``, ``check-config``)
build alike, without the daemon's scheduler."""

from __future__ import annotations

from datetime import datetime

from ..clock import VirtualClock
from ..config import Config
from ..controller import NightPolicy
from ..heatpump import HeatPumpClient, WriteBudget


def clock_from_config(cfg: Config) -> VirtualClock:
    """Real time, or the accelerated wall clock shared with a simulator process (``[clock]``,
    a dry run on a field gateway; load-sensitive: simulated time runs on while the daemon
    waits for the CPU)."""
    if not cfg.clock.epoch:
        return VirtualClock.real()
    epoch = datetime.fromisoformat(cfg.clock.epoch)
    return VirtualClock(epoch, cfg.clock.speed, cfg.clock.wall_epoch_s or None)


def policy_from_config(cfg: Config) -> NightPolicy:
    """The controller's rules from the ``[night]`` section."""
    n = cfg.night
    return NightPolicy(
        sample_interval_s=n.sample_interval_s, abort_margin_k=n.abort_margin_k,
        link_lost_limit_s=n.link_lost_limit_s, t_out_min_c=n.t_out_min_c,
        t_out_max_c=n.t_out_max_c, constrained_action=n.constrained_action,
        setpoint_floor_c=n.setpoint_floor_c, preheat_h=n.preheat_h,
        min_coverage=n.min_coverage, emission_lag_h=n.emission_lag_h)


def open_client(cfg: Config, clock: VirtualClock) -> HeatPumpClient:
    """The safe heat-pump client with the persistent write budget of the state directory."""
    budget = WriteBudget(cfg.budget_path, cfg.heatpump.writes.daily_budget)
    return HeatPumpClient(cfg.heatpump, clock=clock, budget=budget)
