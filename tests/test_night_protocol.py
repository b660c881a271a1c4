"""One night protocol: the gateway, the bench's nights and the classifiers' population run the same
setpoints (issue 14, branch h14q), and the default write clamp never cuts them."""

from __future__ import annotations

import dataclasses
from collections import Counter
from datetime import UTC, datetime, timedelta

import pytest

from impctl.config import CampaignConfig, Config, ConfigError, NightConfig, config_from_mapping
from impctl.controller import NightPolicy, NightRequest
from impctl.daemon.nights.schedule import campaign_plan
from impctl.daemon.service import policy_from_config
from impctl.heatpump import WritePolicy
from impctl.imp import imp_plans
from impctl.imp.protocol import (
    DEFAULT_BAND_K,
    DEFAULT_CONSTRAINED_SETPOINT_C,
    DEFAULT_PREHEAT_H,
    DEFAULT_SETPOINTS_C,
)
from impctl.population.imp_run.setup import ImpSimConfig
from impctl.population.imp_run.synth import imp_schedule


def _plan_setpoints(plans) -> Counter:
    return Counter((kind, float(sp)) for kind, sp in plans)


def test_gateway_bench_and_population_run_the_same_nights():
    camp, night = CampaignConfig(), NightConfig()
    assert (camp.constrained_setpoint_c, tuple(camp.normal_setpoints_c)) == (
        DEFAULT_CONSTRAINED_SETPOINT_C, DEFAULT_SETPOINTS_C)
    assert (night.comfort_band_k, night.preheat_h) == (DEFAULT_BAND_K, DEFAULT_PREHEAT_H)
    # The gateway's fixed plan: 2 constrained nights at the constrained T_set, one normal night
    # at each normal setpoint.
    gateway = _plan_setpoints(campaign_plan(Config()))
    assert gateway == Counter({("constrained", DEFAULT_CONSTRAINED_SETPOINT_C): 2}
                              | {("normal", sp): 1 for sp in DEFAULT_SETPOINTS_C})
    # The bench's and the calibration's 2 + 6 nights: the same setpoints, each normal setpoint
    # twice, the comfort band and pre-heat the gateway's.
    sched = imp_schedule(1, seed=1)
    bench = _plan_setpoints((kind, t_set) for _, kind, _, _, t_set in sched.windows)
    assert bench == Counter({("constrained", DEFAULT_CONSTRAINED_SETPOINT_C): 2}
                            | {("normal", sp): 2 for sp in DEFAULT_SETPOINTS_C})
    for _, kind, w0, _, t_set in sched.windows:
        held = sched.setpoint_c[w0 - 1, 0]
        assert held == (t_set + DEFAULT_BAND_K if kind == "constrained" else t_set), kind
    # The classifiers' virtual population: every plan it simulates is one the gateway runs
    # (the constrained one replayed constrained_per_day times a weather day).
    imp = ImpSimConfig()
    population = _plan_setpoints((p.kind, p.setpoint_c) for p in imp.plans())
    assert set(population) == set(gateway) and imp.constrained_jitter_k == 0
    assert population == Counter({("constrained", DEFAULT_CONSTRAINED_SETPOINT_C):
                                  imp.constrained_per_day}
                                 | {("normal", sp): 1 for sp in DEFAULT_SETPOINTS_C})
    assert all(p.band_k == DEFAULT_BAND_K and p.preheat_h == DEFAULT_PREHEAT_H
               for p in ImpSimConfig().plans())


def test_the_controller_defaults_are_the_protocol():
    """A night asked of the controller without a band or a policy (a caller that has no
    ``[night]`` section) runs the protocol's ΔT and pre-heat, as the gateway's config does: the
    controller's defaults were a literal 1.5 K band."""
    start = datetime(2026, 1, 12, 21, 0, tzinfo=UTC)
    req = NightRequest("constrained", DEFAULT_CONSTRAINED_SETPOINT_C, start,
                       start + timedelta(hours=7))
    assert req.comfort_band_k == NightConfig().comfort_band_k == DEFAULT_BAND_K
    assert (req.t_max_c, req.t_min_c) == (DEFAULT_CONSTRAINED_SETPOINT_C + DEFAULT_BAND_K,
                                          DEFAULT_CONSTRAINED_SETPOINT_C - DEFAULT_BAND_K)
    # Every rule of the controller's default policy is the config's default (preheat_h the
    # protocol's), so a night run with NightPolicy() is the gateway's night.
    assert dataclasses.asdict(NightPolicy()) == dataclasses.asdict(policy_from_config(Config()))
    assert NightPolicy().preheat_h == DEFAULT_PREHEAT_H


def test_the_default_clamp_never_cuts_the_default_protocol():
    lo, hi = WritePolicy().loop1_setpoint_c
    t_max = DEFAULT_CONSTRAINED_SETPOINT_C + DEFAULT_BAND_K
    assert lo <= DEFAULT_CONSTRAINED_SETPOINT_C - DEFAULT_BAND_K and t_max <= hi
    assert all(lo <= sp <= hi for sp in DEFAULT_SETPOINTS_C)
    # The config check agrees (it refuses a T_max above the clamp: the check is live).
    heatpump = {"heatpump": {"host": "127.0.0.1"}}
    config_from_mapping(heatpump, "defaults")
    with pytest.raises(ConfigError, match="campaign.constrained_setpoint_c.*exceeds"):
        config_from_mapping({**heatpump, "campaign": {"constrained_setpoint_c": hi}}, "t_max")
    with pytest.raises(ConfigError, match="campaign.normal_setpoints_c.*outside"):
        config_from_mapping({**heatpump, "campaign": {"normal_setpoints_c": [hi + 1.0]}}, "n")


def test_the_schedule_before_h14q_is_still_reproducible():
    """``constrained_setpoint_c=None``: night j of either kind at setpoints[j % 3], the
    schedule every figure before branch h14q was measured on."""
    old = imp_schedule(1, seed=1, setpoints_c=(22.0, 23.0, 24.0), constrained_setpoint_c=None)
    assert [(kind, t_set) for _, kind, _, _, t_set in old.windows] == [
        ("normal", 22.0), ("constrained", 23.0), ("normal", 24.0), ("normal", 22.0),
        ("normal", 23.0), ("constrained", 24.0), ("normal", 22.0), ("normal", 23.0)]
    every = imp_plans((22.0, 23.0), constrained_setpoint_c=None)
    assert _plan_setpoints((p.kind, p.setpoint_c) for p in every) == Counter(
        {(k, s): 1 for k in ("constrained", "normal") for s in (22.0, 23.0)})
