"""The simulated IMP schedule runs the gateway's protocol: the same pre-heat before each window."""

import numpy as np
import pandas as pd

from impctl.config import NightConfig
from impctl.controller.plan import NightPolicy
from impctl.imp.plan import DEFAULT_PREHEAT_H
from impctl.population.imp_run.synth import imp_schedule


def _raised_from(sched, w0: int) -> pd.Timestamp:
    """First step of the run of setpoints above the day setpoint that ends at the window."""
    sp = np.nan_to_num(sched.setpoint_c[:w0, 0], nan=-1.0)
    first = w0
    while first > 0 and sp[first - 1] > sched.t_m_init_c:
        first -= 1
    return sched.index[first]


def test_default_preheat_is_the_gateways():
    assert NightPolicy().preheat_h == NightConfig().preheat_h == DEFAULT_PREHEAT_H
    sched = imp_schedule(1, seed=1)
    assert sched.band_k == NightConfig().comfort_band_k      # the gateway's ΔT
    kinds = {kind for _, kind, *_ in sched.windows}
    assert kinds == {"constrained", "normal"}
    for _, kind, w0, _, t_set in sched.windows:
        start = _raised_from(sched, w0)
        assert (sched.index[w0] - start) == pd.Timedelta(hours=DEFAULT_PREHEAT_H), kind
        want = t_set + sched.band_k if kind == "constrained" else t_set
        assert sched.setpoint_c[w0 - 1, 0] == want


def test_preheat_per_kind():
    sched = imp_schedule(1, seed=1, constrained_preheat_h=4.0, normal_preheat_h=0.0)
    for _, kind, w0, _, t_set in sched.windows:
        lead = sched.index[w0] - _raised_from(sched, w0)
        assert lead == pd.Timedelta(hours=4.0 if kind == "constrained" else 0.0), kind
        if kind == "normal":
            assert sched.setpoint_c[w0, 0] == t_set
            assert sched.setpoint_c[w0 - 1, 0] == sched.t_m_init_c
