"""The virtual population: its prior and geometry, the vectorised IMP run, the dataset files."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from impctl.errors import InputError
from impctl.imp import DEFAULT_SETPOINTS_C, NIGHT_FEATURE_NAMES
from impctl.population import (
    DEFAULT_RANGES,
    ImpSimConfig,
    PopulationConfig,
    generate_dataset,
    sample_households,
    sample_population,
    simulate_imp,
)
from impctl.population.dataset import Dataset
from impctl.population.imp_run.setup import usable_nights
from impctl.weather import winter_weather

TZ = "Europe/Ljubljana"
QUIET = dict(noise_t_air_k=0.0, noise_q_rel=0.0, quantum_k=0.0)


def test_population_is_seeded_and_spans_the_range_hulls():
    a = sample_population(400, seed=4)
    assert a.equals(sample_population(400, seed=4))
    assert not a.equals(sample_population(400, seed=5))
    for name, ranges in DEFAULT_RANGES.items():
        assert a[name].between(ranges[0][0], ranges[-1][1]).all()
        assert a[name].min() < ranges[1][0] and a[name].max() > ranges[-2][1]
    assert (a["ach_vent"] == 0.0).all() and (a["ach_infl"] == 0.01).all()


def test_geometry_ties_walls_and_windows_to_the_floor_area():
    pop = sample_population(3000, seed=1)
    footprint = pop.floor_area / pop.storeys
    width = np.sqrt(footprint / pop.aspect_ratio)
    facade = 2 * (width + pop.aspect_ratio * width) * pop.storeys * pop.wall_height
    np.testing.assert_allclose(pop.walls_area + pop.windows_area, facade)
    np.testing.assert_allclose(pop.windows_area / facade, pop.window_wall_ratio)
    assert pop.window_wall_ratio.between(0.10, 0.30).all()
    # Walls grow with the floor area instead of being drawn on their own …
    assert np.corrcoef(pop.floor_area, pop.walls_area)[0, 1] > 0.7
    # … and large houses more often have two storeys.
    small, large = pop.floor_area < 120, pop.floor_area > 240
    assert (pop.storeys[large] == 2).mean() > (pop.storeys[small] == 2).mean() + 0.3
    # Every drawn house is a valid ISO 13790 house (eq. 63 and C.3 domains are checked there).
    houses = sample_households(3000, seed=1)
    assert houses.n_houses == 3000 and np.all(houses.tau_h > 0)


def test_config_for_ranges_and_bad_ranges():
    cfg = PopulationConfig.for_ranges({"floor_area": ((50, 80), (80, 120)),
                                       "c_f": ((1.0, 2.0), (2.0, 3.0))})
    assert cfg.floor_area_m2 == (50.0, 120.0) and cfg.c_f == (1.0, 3.0)
    assert cfg.u_walls == PopulationConfig().u_walls
    with pytest.raises(InputError, match="contiguous"):
        PopulationConfig.for_ranges({"c_f": ((0.8, 1.5), (1.65, 3.7))})
    with pytest.raises(InputError, match="cannot classify"):
        PopulationConfig.for_ranges({"colour": ((0, 1), (1, 2))})


@pytest.fixture(scope="module")
def quiet_run():
    pop = sample_population(12, seed=2)
    from impctl.population.households import households_from_table

    result = simulate_imp(households_from_table(pop), config=ImpSimConfig(days=3, **QUIET),
                          seed=2)
    return pop, result


def test_imp_run_layout_and_normal_nights_hold_the_setpoint(quiet_run):
    pop, r = quiet_run
    n = r.nights
    # The gateway's plans: constrained_per_day replays of its constrained night + 1 per normal
    # setpoint.
    plans = len(ImpSimConfig().plans())
    assert plans == ImpSimConfig().constrained_per_day + len(DEFAULT_SETPOINTS_C)
    assert len(n) == 12 * 3 * plans and r.t_air_c.shape == (r.time_s.size, len(n))
    assert (n.groupby("household").size() == 3 * plans).all()
    assert set(n.columns) >= set(NIGHT_FEATURE_NAMES) | {"household", "kind", "setpoint_c"}
    normal = (n["kind"] == "normal").to_numpy()
    valid = r.valid[:, normal]
    np.testing.assert_allclose(r.t_air_c[:, normal][valid],
                               np.broadcast_to(n["setpoint_c"][normal], valid.shape)[valid],
                               atol=1e-6)
    # Heat output ≈ HLC·(T_set − T_out), but above it: after the evening step from the day
    # setpoint (20–22 °C) to T_set the mass still charges (identifiability.md §11.1).
    hlc = pop["hlc_w_per_k"].to_numpy()[n["household"][normal]]
    ratio = n["q_per_k_w_per_k"][normal] / hlc
    assert ratio.between(0.9, 2.0).all() and 1.0 < ratio.median() < 1.5


def test_constrained_nights_heat_pump_off_and_cooling_at_the_house_time_constant(quiet_run):
    pop, r = quiet_run
    n = r.nights
    cons = (n["kind"] == "constrained").to_numpy()
    assert np.all(r.q_hc_w[:, cons][r.valid[:, cons]] == 0.0)
    assert (n["cooling_time_h"][cons] > 5.0).all()      # cooled to the window's end
    after = r.time_s >= 3600.0
    t_air = r.t_air_c[after][:, cons]
    assert np.all(np.diff(t_air, axis=0) < 0.02)          # falls (T_out drifts a little)
    k = n[cons].groupby("household")["decay_rate_per_h"].median()
    truth = 1.0 / pop["tau_h"].to_numpy()[k.index]
    np.testing.assert_allclose(k, truth, rtol=0.25)
    assert np.corrcoef(np.log(k), np.log(truth))[0, 1] > 0.9


def test_stop_at_t_min_ends_constrained_nights_after_the_lag():
    houses = sample_households(10, seed=3)
    cfg = ImpSimConfig(days=2, stop_at_t_min=True, **QUIET)
    r = simulate_imp(houses, config=cfg, seed=3)
    cons = (r.nights["kind"] == "constrained").to_numpy()
    t_min = r.nights["setpoint_c"].to_numpy() - cfg.band_k
    lengths = r.valid.sum(axis=0)
    assert np.all(lengths[cons] >= 6)                     # never ends inside the lag
    ended = cons & (lengths < r.nights["duration_h"].to_numpy() * 6)
    assert ended.any()
    # After the lag the house never drops below T_min without the heating stepping in.
    assert np.all(r.t_air_c[6:][:, cons][r.valid[6:, cons]] >= np.repeat(
        t_min[None, cons], r.time_s.size - 6, 0)[r.valid[6:, cons]] - 1e-6)


def test_quantisation_and_noise():
    r = simulate_imp(sample_households(3, seed=6), config=ImpSimConfig(days=2), seed=6)
    t = r.t_air_c[r.valid]
    np.testing.assert_allclose(t * 10, np.round(t * 10), atol=1e-6)
    normal = (r.nights["kind"] == "normal").to_numpy()
    q = r.q_hc_w[:, normal][r.valid[:, normal]]
    assert np.std(np.diff(q)) > 0.01 * np.mean(q)          # 5 % noise on the heat output


def test_weather_with_a_dst_change_gives_a_six_hour_night():
    weather = winter_weather("2026-03-10", days=25, step_s=600, seed=1)
    cfg = ImpSimConfig(days=3, max_t_out_c=40.0)
    nights = usable_nights(weather, cfg)
    dst = nights[nights["date"] == "2026-03-28"]
    assert dst["duration_s"].tolist() == [6 * 3600.0]
    r = simulate_imp(sample_households(2, seed=1), weather,
                     ImpSimConfig(days=len(nights), max_t_out_c=40.0), seed=1)
    short = r.nights["date"] == "2026-03-28"
    assert short.any() and (r.nights.loc[short, "duration_h"] == 6.0).all()
    assert (r.valid.sum(axis=0)[short.to_numpy() & (r.nights["kind"] == "normal").to_numpy()]
            == 36).all()


def test_too_little_weather_is_refused():
    weather = winter_weather("2026-01-05", days=3, step_s=3600, seed=1)
    with pytest.raises(InputError, match="usable nights"):
        simulate_imp(sample_households(2), weather, ImpSimConfig(days=15))


def test_dataset_is_reproducible_and_round_trips(tmp_path):
    cfg = ImpSimConfig(days=2)
    a = generate_dataset(130, seed=9, imp=cfg, workers=2)    # two vectorised blocks
    # one worker process per block, or the blocks one after the other: the same dataset
    b = generate_dataset(130, seed=9, imp=cfg, workers=1)
    pd.testing.assert_frame_equal(a.nights, b.nights)
    pd.testing.assert_frame_equal(a.households, b.households)
    assert len(a.nights) == 130 * 2 * len(cfg.plans()) and a.nights["household"].nunique() == 130
    m = a.manifest
    assert m["seed"] == 9 and m["n_households"] == 130 and m["imp"]["days"] == 2
    assert set(m["night_features"]) == set(NIGHT_FEATURE_NAMES)
    assert m["ranges"]["c_f"] == [[0.8, 1.65], [1.65, 3.7]]
    assert {"numpy", "pandas", "scikit-learn"} <= set(m["versions"])
    back = Dataset.load(a.save(tmp_path / "ds"))
    pd.testing.assert_frame_equal(back.nights, a.nights)
    pd.testing.assert_frame_equal(back.households, a.households)
    assert back.manifest == a.manifest


def test_campaign_picks_distinct_dates_of_one_household(quiet_run):
    _, r = quiet_run
    nights = r.campaign(4, n_constrained=1, n_normal=2, seed=1)
    assert [n.kind for n in nights].count("constrained") == 1 and len(nights) == 3
    assert len({n.start for n in nights}) == 3
    assert all(n.night_id.startswith("h4-") for n in nights)
    assert [n.start for n in nights] == sorted(n.start for n in nights)
    with pytest.raises(ValueError, match="3 dates"):
        r.campaign(4, n_constrained=2, n_normal=2)


def test_more_constrained_nights_a_day_each_at_its_drawn_setpoint():
    """``constrained_per_day`` constrained replays of every weather day, their T_set drawn within
    ``constrained_jitter_k`` of the gateway's; the normal nights keep their setpoints."""
    houses = sample_households(4, seed=5)
    cfg = ImpSimConfig(days=2, constrained_per_day=3, constrained_jitter_k=0.5, **QUIET)
    r = simulate_imp(houses, config=cfg, seed=5)
    n = r.nights
    assert len(cfg.plans()) == 3 + len(DEFAULT_SETPOINTS_C)
    assert (n.groupby(["household", "day"])["kind"].apply(
        lambda k: (k == "constrained").sum()) == 3).all()
    cons = (n["kind"] == "constrained").to_numpy()
    sp = n["setpoint_c"].to_numpy()
    assert np.all(np.abs(sp[cons] - 21.0) <= 0.5) and np.unique(sp[cons]).size == cons.sum()
    assert set(sp[~cons]) == set(DEFAULT_SETPOINTS_C)
    # Each replay cools from its own T_max = T_set + ΔT (held through the pre-heat).
    first = r.t_air_c[0, cons]
    assert np.corrcoef(first, sp[cons])[0, 1] > 0.5
    base = simulate_imp(houses, config=ImpSimConfig(days=2, constrained_per_day=1, **QUIET),
                        seed=5).nights
    assert (base["kind"] == "constrained").sum() * 3 == cons.sum()
    with pytest.raises(InputError, match="constrained_per_day"):
        ImpSimConfig(constrained_per_day=0)
