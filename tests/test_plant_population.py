"""The virtual population on the realistic plant: randomised realism, reproducible draws."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from impctl.imp.protocol import DEFAULT_BAND_K
from impctl.plant import RADIATORS, UNDERFLOOR
from impctl.plant.params import SECTIONS
from impctl.population import ImpSimConfig, generate_dataset, sample_households
from impctl.population.imp_run.realistic import simulate_imp_plant
from impctl.population.realism import params_from_table, params_table, sample_params


def test_sample_params_cover_documented_ranges_and_repeat():
    n = 400
    a, b, c = sample_params(n, 5), sample_params(n, 5), sample_params(n, 6)
    ta, tb, tc = (params_table(p, n) for p in (a, b, c))
    assert ta.equals(tb) and not ta.equals(tc)
    for name, cls in SECTIONS.items():
        for key, (lo, hi) in cls.RANGES.items():
            col = ta[f"{name}.{key}"]
            assert col.between(lo, hi).all(), (name, key)
    kind = ta["emitter.kind"]
    assert set(kind) == {RADIATORS, UNDERFLOOR} and 0.3 < (kind == UNDERFLOOR).mean() < 0.5
    assert set(ta["heat_pump.control"]) == {0, 1}                   # never the ideal control
    assert 0.2 < (ta["heat_pump.min_modulation"] == 1.0).mean() < 0.4
    assert set(ta["sensors.t_air_quantum_k"]) == {0.1, 0.5}
    assert ta["gains.night_w"].min() < 150 and ta["gains.night_w"].max() > 350
    assert params_table(params_from_table(ta), n).equals(ta)


def test_realistic_nights_differ_from_iso_as_real_houses_do():
    """Same households and weather days: on the realistic plant the constrained nights start
    without the ISO air-node jump and the normal-night heat reads as a meter's interval mean."""
    houses = sample_households(6, seed=2)
    cfg = ImpSimConfig(days=2, setpoints_c=(22.0,), constrained_setpoint_c=22.0)
    res = simulate_imp_plant(houses, sample_params(6, 2), config=cfg, seed=3)
    cons = (res.nights["kind"] == "constrained").to_numpy()
    t_air = res.t_air_c[:, cons]
    assert np.nanmax(np.abs(np.diff(t_air[:6], axis=0))) < 1.5
    q = res.q_hc_w[:, ~cons]
    assert (q >= 0).all() and (q[res.valid[:, ~cons]] > 0).mean() > 0.5
    assert np.isfinite(res.nights["decay_rate_per_h"][cons]).all()


def test_generate_dataset_realistic_is_reproducible():
    cfg = ImpSimConfig(days=2, setpoints_c=(22.0,), constrained_setpoint_c=22.0)
    a = generate_dataset(8, seed=4, imp=cfg, plant="realistic")
    b = generate_dataset(8, seed=4, imp=cfg, plant="realistic")
    assert a.manifest["plant"] == "realistic"
    assert a.households.equals(b.households) and a.nights.equals(b.nights)
    assert "emitter.kind" in a.households and "sensors.t_air_lag_s" in a.households
    iso = generate_dataset(8, seed=4, imp=cfg)
    assert iso.manifest["plant"] == "iso" and "emitter.kind" not in iso.households
    same = ["floor_area", "c_f", "u_walls"]
    assert iso.households[same].equals(a.households[same])
    assert not np.allclose(iso.nights["decay_rate_per_h"].fillna(0),
                           a.nights["decay_rate_per_h"].fillna(0))


def test_default_population_records_nights_as_the_gateway_does():
    """Without an explicit config the population runs the nights the gateway records: on the
    realistic plant its constrained nights stop at T_min (and the manifest says so, so trained
    models carry it); on the ideal 5R1C they cool to the window's end (its massless air node
    would end them at the lag)."""
    assert ImpSimConfig.for_plant("realistic", days=3).stop_at_t_min
    assert not ImpSimConfig.for_plant("iso").stop_at_t_min
    assert ImpSimConfig.for_plant("realistic", stop_at_t_min=False).stop_at_t_min is False
    lag_h = ImpSimConfig().emitter_lag_h
    for plant, stops in (("realistic", True), ("iso", False)):
        data = generate_dataset(4, seed=6, plant=plant)
        assert data.manifest["imp"]["stop_at_t_min"] is stops
        assert data.manifest["imp"]["band_k"] == DEFAULT_BAND_K
        cons = data.nights[data.nights["kind"] == "constrained"]
        cooling = cons["cooling_time_h"]
        # a night cooling to 05:00 has its last sample one 10-min step before the end
        full = cons["duration_h"] - lag_h - 1 / 6
        if stops:
            # too short after the lag (< 3 h, the gateway's verdict): NaN, never classified
            assert cooling.isna().any() and (cooling.dropna() >= 3.0 - 1 / 6 - 1e-9).all()
            assert (cooling < full - 1e-6).any()        # valid nights that stopped at T_min
            assert cons.loc[cooling.isna(), "decay_rate_early_per_h"].isna().all()
        else:
            np.testing.assert_allclose(cooling, full)
        assert cons.loc[cooling.notna(), "decay_rate_early_per_h"].notna().all()


def test_constrained_nights_stop_at_t_min_on_the_realistic_plant():
    """With stop_at_t_min a constrained night ends as the gateway's controller ends it, polled
    every minute from the switch-off: at the first sensed T_air ≤ T_min (or, with anticipation,
    when its trend gets there within anticipate_s); the owner's setpoint is restored after it,
    and a night with less than min_usable_h after the lag is invalid (NaN features)."""
    houses = sample_households(6, seed=7)
    cfg = ImpSimConfig(days=2, setpoints_c=(22.0,), constrained_setpoint_c=22.0, band_k=0.5,
                       stop_at_t_min=True, anticipate_s=0.0)
    res = simulate_imp_plant(houses, sample_params(6, 7), config=cfg, seed=1)
    nights = res.nights
    cons = np.flatnonzero((nights["kind"] == "constrained").to_numpy())
    stopped = short = 0
    for i in cons:
        t_air, valid = res.t_air_c[:, i], res.valid[:, i]
        last = int(np.flatnonzero(valid)[-1])
        n_rows = int(round(nights["duration_h"].iloc[i] * 6))
        assert valid[:last + 1].all()
        assert (t_air[:last] > 22.0 - 0.5).all()           # every earlier poll above T_min
        if last < n_rows - 1:
            stopped += 1
            assert res.q_hc_w[last + 1:n_rows, i].max() > 0   # heating back after the stop
        usable_h = (last + 1) / 6 - cfg.emitter_lag_h        # the stop is within the next row
        if usable_h < cfg.min_usable_h - 1 / 6:
            short += 1
            assert np.isnan(nights["decay_rate_per_h"].iloc[i])
            assert np.isnan(nights["cooling_time_h"].iloc[i])
        elif usable_h >= cfg.min_usable_h:
            assert np.isfinite(nights["cooling_time_h"].iloc[i])
    assert stopped >= 1 and short >= 1
    # Anticipation ends nights earlier, never later.
    early = simulate_imp_plant(houses, sample_params(6, 7),
                               config=replace(cfg, anticipate_s=1800.0), seed=1)
    assert (early.valid[:, cons].sum(axis=0) <= res.valid[:, cons].sum(axis=0)).all()
    assert (early.valid[:, cons].sum(axis=0) < res.valid[:, cons].sum(axis=0)).any()


def test_schedule_without_gains_keeps_every_other_draw():
    """``run_schedule_plant(gains=False)`` (the error budget's ideal limit of the gains): no
    gains reach the house, the heat pump makes up for them, the sensors read the same noise."""
    from impctl.population.imp_run.synth import imp_schedule, run_schedule_plant

    houses, params = sample_households(2, seed=4), sample_params(2, 4)
    # one night of each kind after a day's spin-up: days and nights, the gains of both
    sched = imp_schedule(2, seed=4, n_constrained=1, n_normal=1, spinup_days=1)
    keep = ("t_air_sensed_c", "t_out_sensed_c", "heat_meter_w", "heat_pump_w", "gains_w")
    on, _ = run_schedule_plant(houses, sched, params, seed=4, outputs=keep)
    off, _ = run_schedule_plant(houses, sched, params, seed=4, outputs=keep, gains=False)
    assert np.all(off.run["gains_w"] == 0.0) and np.all(on.run["gains_w"].mean(axis=0) > 100.0)
    assert np.array_equal(on.run["t_out_sensed_c"], off.run["t_out_sensed_c"])
    assert np.all(off.run["heat_pump_w"].sum(axis=0) > on.run["heat_pump_w"].sum(axis=0))


def test_constrained_replays_on_the_realistic_plant():
    houses = sample_households(3, seed=4)
    cfg = ImpSimConfig(days=1, setpoints_c=(22.0,), constrained_per_day=3,
                       constrained_jitter_k=1.0)
    res = simulate_imp_plant(houses, sample_params(3, 4), config=cfg, seed=2)
    n = res.nights
    cons = (n["kind"] == "constrained").to_numpy()
    assert cons.sum() == 9 and sorted(set(n["replay"][cons])) == [0, 1, 2]
    sp = n["setpoint_c"].to_numpy()
    assert np.all(np.abs(sp[cons] - 21.0) <= 1.0) and np.unique(sp[cons]).size == 9
    assert set(sp[~cons]) == {22.0}
    # Replays of one evening are different nights (own T_set, sensor noise, gains), and the
    # heating stays off in each of them after the emitter lag.
    for h in range(3):
        mine = np.flatnonzero(cons & (n["household"] == h).to_numpy())
        assert not np.allclose(res.t_air_c[:, mine[0]], res.t_air_c[:, mine[1]])
        assert (res.q_hc_w[6:, mine][res.valid[6:, mine]] < 1.0).all()


def test_plant_schedule_stops_constrained_nights_at_t_min_as_the_gateway():
    from impctl.population.imp_run.synth import imp_schedule, run_schedule_plant, sample_nights

    n, seed = 6, 20260
    houses = sample_households(n, seed=seed)
    sched = imp_schedule(n, seed=seed, n_constrained=1, n_normal=1, spinup_days=1)
    params = sample_params(n, seed)
    open_run, open_sp = run_schedule_plant(houses, sched, params, seed=seed)
    # At T_min itself (the gateway's anticipated end: tests/test_gateway_nights.py).
    stop_run, sp = run_schedule_plant(houses, sched, params, seed=seed, stop_at_t_min=True,
                                      anticipate=False)
    assert np.array_equal(open_sp, sched.setpoint_c, equal_nan=True)      # default unchanged
    (_, _, w0, w1, t_set), = [w for w in sched.windows if w[1] == "constrained"]
    lag = int(round(3600 / sched.dt_s))
    on = ~np.isnan(sp[w0:w1])
    stopped = on.any(axis=0)
    assert stopped.any() and not stopped.all()
    for h in range(n):
        if not stopped[h]:
            assert np.array_equal(stop_run.t_air_c[:, h], open_run.t_air_c[:, h])
            continue
        k = int(on[:, h].argmax())
        assert k >= lag and stop_run.t_air_c[w0 + k, h] <= t_set - sched.band_k   # sensor at T_min
        assert (open_run.t_air_c[w0 + lag:w0 + k, h] > t_set - sched.band_k).all()  # not before
        assert (sp[w0 + k:w1, h] == sched.t_m_init_c).all()                   # day setpoint
        # Causal: up to the stop the night is the open-loop one; the rows end there.
        assert np.array_equal(stop_run.t_air_c[:w0 + k, h], open_run.t_air_c[:w0 + k, h])
        night, = [x for x in sample_nights(stop_run, sp, sched, h, power_noise=0.0)
                  if x.kind == "constrained"]
        assert k * sched.dt_s - 300.0 <= night.time_s[-1] < k * sched.dt_s
