"""The simulated constrained nights end as the gateway ends them, and are kept or repeated as
the gateway keeps or repeats them (issue 14, branch h14w): the bench's and the calibration's
nights are the gateway's nights."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from types import SimpleNamespace

import numpy as np
import pytest

from impctl.controller.plan import NightPolicy, NightRequest, anticipated_end, preheat_short
from impctl.fit.nights.data import prepare_nights
from impctl.imp.protocol import MIN_NIGHT_H
from impctl.population.households import sample_households
from impctl.population.imp_run.gateway import gateway_constrained_nights, gateway_end
from impctl.population.imp_run.synth import (
    imp_schedule,
    run_schedule,
    run_schedule_plant,
    sample_nights,
)
from impctl.population.realism import sample_params


def _controller_end(readings, t_start_c, req: NightRequest, lag: int, dt_s: float) -> int:
    """First reading at which the gateway's own rules (controller.plan) end the night, the T_min
    test from ``lag`` on as the bench's (the 5R1C's massless air node); len(readings) if none."""
    policy = NightPolicy()
    snap = SimpleNamespace(t_air_c=SimpleNamespace(value=float(t_start_c)))
    if preheat_short(snap, req, policy):
        return 0
    trend = []
    for k, v in enumerate(readings):
        trend.append((k * dt_s, float(v)))
        ended = v <= req.t_min_c or anticipated_end(trend, policy, req.t_min_c) is not None
        if ended and k >= lag:
            return k
    return len(readings)


def test_the_bench_ends_a_constrained_night_where_the_gateways_rules_end_it():
    n, seed = 8, 20260
    houses = sample_households(n, seed=seed)
    sched = imp_schedule(n, seed=seed, n_constrained=2, n_normal=0, spinup_days=1)
    logged, _ = run_schedule_plant(houses, sched, sample_params(n, seed), seed=seed)
    lag = int(round(3600 / sched.dt_s))
    start = datetime(2026, 1, 5, 22, tzinfo=UTC)
    why = []
    for _, kind, w0, w1, t_set in sched.windows:
        req = NightRequest(kind, t_set, start, start + timedelta(hours=7),
                           comfort_band_k=sched.band_k)
        sensed = logged.t_air_c
        ends = gateway_end(sensed[w0:w1], sched.dt_s, req.t_min_c, lag,
                           t_start_c=sensed[w0 - 1])
        for h in range(n):
            k = _controller_end(sensed[w0:w1, h], sensed[w0 - 1, h], req, lag, sched.dt_s)
            assert ends[h] == k, (h, w0)
            if k < w1 - w0:
                why.append("T_min" if sensed[w0 + k, h] <= req.t_min_c else "anticipated")
    # Both ways of ending occur here, so the comparison covered the trend rule too.
    assert {"T_min", "anticipated"} <= set(why)


@pytest.mark.parametrize("path", ["annex_c", "plant"])
def test_the_schedule_carries_its_band_and_the_day_setpoint_follows_the_stop(path):
    n, seed, band = 8, 20260, 2.0
    houses = sample_households(n, seed=seed)
    sched = imp_schedule(n, seed=seed, n_constrained=1, n_normal=1, spinup_days=1, band_k=band)
    (_, _, w0, w1, t_set), = [w for w in sched.windows if w[1] == "constrained"]
    assert (sched.setpoint_c[w0 - 1] == t_set + band).all() and sched.band_k == band

    def run(**kw):
        if path == "annex_c":
            return run_schedule(houses, sched, **kw)
        return run_schedule_plant(houses, sched, sample_params(n, seed), seed=seed, **kw)

    with pytest.raises(ValueError, match="band_k 1.5 K differs"):
        run(band_k=1.5, stop_at_t_min=True)
    _, sp = run(stop_at_t_min=True, band_k=band)     # the same band given is accepted
    # What the gateway read when it ended the night: the open-loop night up to there (the
    # plant's room sensor, or the 5R1C's T_air, whose massless air node jumps at the restore).
    t_air = run()[0].t_air_c
    on = ~np.isnan(sp[w0:w1])
    assert on.any()
    for h in np.flatnonzero(on.any(axis=0)):
        k = int(on[:, h].argmax())
        # Ended at T_min = T_set − ΔT or within the anticipation's reach of it, then back at
        # the day setpoint (the owner's), never held at T_min.
        assert t_air[w0 + k, h] <= t_set - band + 1.0
        assert (sp[w0 + k:w1, h] == sched.t_m_init_c).all() and sched.t_m_init_c == 21.0


def test_a_campaign_repeats_invalid_constrained_nights_and_keeps_the_first_two_valid():
    n = 5
    sched = imp_schedule(n, seed=1, n_constrained=2, n_normal=1, spinup_days=1,
                         n_spare_constrained=3)
    assert sched.n_spare == 3
    cons = [w for w in sched.windows if w[1] == "constrained"]
    assert len(cons) == 5 and [w[1] for w in sched.windows[:3]].count("normal") == 1
    hour = int(round(3600 / sched.dt_s))
    # Usable hours after the 1 h lag per constrained night (rows) and house (columns): the
    # night ends (heating back on) 1 h + that after the switch-off; 6 = to the window's end.
    usable = np.array([[3.0, 2.9, 1.0, 4.0, -1.0],
                       [6.0, 4.0, 1.5, 0.5, -1.0],
                       [6.0, 5.0, 2.0, 0.2, -1.0],
                       [6.0, 6.0, 6.0, 1.0, 6.0],
                       [6.0, 6.0, 6.0, 6.0, 6.0]])
    sp = sched.setpoint_c.copy()
    for (_, _, w0, w1, _), row in zip(cons, usable, strict=True):
        for h, u in enumerate(row):
            sp[w0 + int(round((1.0 + u) * hour)):w1, h] = sched.t_m_init_c
    gate = gateway_constrained_nights(sp, sched)
    assert np.allclose(gate["usable_h"], usable)
    assert gate["run"].T.astype(int).tolist() == [
        [1, 1, 0, 0, 0],     # both valid (3.0 h exactly is valid)
        [1, 1, 1, 0, 0],     # the first repeated once
        [1, 1, 1, 0, 0],     # three invalid: the campaign stops, not identified
        [1, 1, 1, 1, 0],     # one valid, then three invalid: stops with one
        [1, 1, 1, 0, 0]]     # never switched off (pre-heat short): invalid
    assert gate["used"].sum(axis=0).tolist() == [2, 2, 0, 1, 0]
    assert gate["paid"].tolist() == [2, 3, 3, 4, 3]
    # The 2 h rule keeps house 1's 2.9 h night; the fit's own cut agrees with the rule.
    assert gateway_constrained_nights(sp, sched, need_h=2.0)["used"][:, 1].tolist() == [
        1, 1, 0, 0, 0]
    houses = sample_households(n, seed=1)
    sim, _ = run_schedule(houses, sched)
    nights = [x for x in sample_nights(sim, sp, sched, 4, sample_step_s=60.0)
              if x.kind == "constrained"]
    assert len(nights[0].time_s) == 0                  # no samples: never switched off
    kept, _, skipped = prepare_nights(nights[:3], min_hours=MIN_NIGHT_H)
    assert not kept and len(skipped) == 3


def test_a_schedule_in_a_campaign_s_own_order_keeps_each_date_s_weather():
    """``imp_schedule(order=...)``: the nights in the order given (a campaign's own, e.g. its
    constrained retries after normal nights), each date with the weather it has in any other
    order of the same length; an order that does not hold the counts is refused."""
    order = ["constrained", "normal", "constrained", "normal", "constrained"]
    alt = imp_schedule(3, seed=4, n_constrained=3, n_normal=2, order=order)
    every = imp_schedule(3, seed=4, n_constrained=5, n_normal=0, order=["constrained"] * 5)
    assert [w[1] for w in alt.windows] == order
    assert [w[4] for w in alt.windows if w[1] == "normal"] == [22.0, 23.0]
    assert np.array_equal(alt.t_out_c, every.t_out_c)
    assert [w[2:4] for w in alt.windows] == [w[2:4] for w in every.windows]
    with pytest.raises(ValueError, match="does not hold 2 constrained"):
        imp_schedule(3, seed=4, n_constrained=2, n_normal=2, order=order[:4] + ["normal"])
