"""Heat-pump control, sensors, the step-wise API and the house-TOML sections of the plant."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from impctl.errors import InputError
from impctl.model import HouseParameters, default_house
from impctl.plant import (
    Emitter,
    Gains,
    HeatPump,
    HouseGains,
    Plant,
    PlantParams,
    Sensors,
    load_plant,
    periodic,
    simulate_plant,
)
from impctl.plant.building.gains import solar_gains_w, sun_shape


def _runs(flags: np.ndarray) -> list[tuple[bool, int, int]]:
    """(value, first index, length) of each run of equal values."""
    edges = np.flatnonzero(np.diff(flags.astype(int))) + 1
    starts = np.r_[0, edges]
    ends = np.r_[edges, len(flags)]
    return [(bool(flags[s]), int(s), int(e - s)) for s, e in zip(starts, ends, strict=True)]


@pytest.mark.parametrize("control", [0, 1], ids=["curve", "thermostat"])
def test_cycling_honours_min_times_and_hysteresis(control):
    """An on/off unit in mild weather cycles; every complete run lasts ≥ min_on, every pause
    ≥ min_off, and (curve control) each stop comes with the water above target + hysteresis."""
    houses = HouseParameters.stack([default_house()] * 3)
    # A flat capacity curve and no defrost: nominal = sizing × design load (a unit sized for a
    # cold design point would be several times the load at +8 °C and overshoot by design).
    hp = HeatPump(control=control, min_modulation=1.0, min_on_s=np.array([300.0, 600.0, 1200.0]),
                  min_off_s=np.array([1200.0, 600.0, 300.0]), water_hysteresis_k=2.0,
                  capacity_per_k=0.0, defrost=0)
    dt = 60.0
    n_steps = 2 * 1440
    run = simulate_plant(houses, PlantParams(heat_pump=hp), np.full(n_steps, 8.0), dt,
                         setpoint_c=np.full(n_steps, 21.0), t_init_c=21.0)
    on = run["compressor_on"]
    for j in range(3):
        runs = _runs(on[:, j])[1:-1]          # the first and last runs are cut by the window
        assert sum(1 for v, _, _ in runs if v) >= 5, "no cycling"
        for value, first, length in runs:
            need = hp.min_on_s[j] if value else hp.min_off_s[j]
            assert length * dt >= need
            if value and control == 0:
                stop = first + length                        # first step with the unit off
                assert run["t_water_c"][stop - 1, j] > run["t_water_target_c"][stop, j] + 2.0
        if control == 1:
            # The room thermostat calls below T_set − band/2 and stops above T_set + band/2
            # (sensed values of the step before the decision).
            calls = _runs(run["heat_demand"][:, j])[1:]
            assert len(calls) >= 4
            for value, first, _ in calls:
                seen = run["t_air_sensed_c"][first - 1, j]
                assert seen < 21.0 - 0.25 if value else seen >= 21.0 + 0.25
    # Cycling units hold the room near the setpoint on average, with a visible swing.
    air = run["t_air_c"][1440:]
    assert np.all(np.abs(air.mean(axis=0) - 21.0) < 1.0)
    assert np.all(air.max(axis=0) - air.min(axis=0) > 0.2)


def test_modulation_ramp_capacity_and_defrost():
    """A modulating unit starts on its ramp, never exceeds the capacity at T_out, and defrosts
    (negative heat) after its run-time interval in the frost band."""
    hp = HeatPump(ramp_s=600.0, defrost_interval_s=2400.0, defrost_duration_s=360.0,
                  capacity_per_k=0.03)
    house = default_house()
    dt = 60.0
    n = 600
    run = simulate_plant(house, PlantParams(heat_pump=hp), np.full(n, -2.0), dt,
                         setpoint_c=np.full(n, 23.0), t_init_c=19.0)
    q = run["heat_pump_w"][:, 0]
    p = Plant(house, PlantParams(heat_pump=hp))
    nominal = p.nominal_w
    assert q[0] == pytest.approx(nominal * dt / 600.0)               # the start ramp
    assert q.max() <= nominal * (1 + 0.03 * (-2.0 - 7.0)) + 1e-9     # capacity at −2 °C
    defrost = run["defrost"][:, 0]
    blocks = [r for r in _runs(defrost) if r[0]]
    assert len(blocks) >= 3
    assert all(length * dt == pytest.approx(360.0) for _, _, length in blocks[:-1])
    assert (q[defrost] < 0).all() and (run["heat_meter_w"][defrost] == 0).all()


def test_defrost_waits_for_min_run_after_a_start():
    """Run time before a stop still counts towards the next defrost, but a restarted unit does
    not defrost before ``defrost_min_run_s`` of run since its start (RH §3: ≥ ~35 min)."""
    hp = HeatPump(defrost_interval_s=5400.0, defrost_min_run_s=2100.0, min_modulation=0.3,
                  min_off_s=300.0)
    house = default_house()
    dt = 60.0
    # 80 min heating at 27 °C setpoint (runs flat out), 60 min loop off, then heating again.
    sp = np.r_[np.full(80, 27.0), np.full(60, np.nan), np.full(150, 27.0)]
    run = simulate_plant(house, PlantParams(heat_pump=hp), np.full(len(sp), -2.0), dt,
                         setpoint_c=sp, t_init_c=21.0)
    on, defrost = run["compressor_on"][:, 0], run["defrost"][:, 0]
    assert on[:80].all() and not on[80:140].any() and not defrost[:140].any()
    restart = 140 + int(np.argmax(on[140:]))
    first = int(np.argmax(defrost))
    assert on[restart:first].all()
    # 80 min before the stop + 35 min after the restart ≥ the 90-min interval: the defrost
    # comes exactly when the minimum run since the start is reached, not in the first minute.
    assert (first - restart + 1) * dt == pytest.approx(2100.0)
    # Without the minimum run, the carried-over 80 min would trigger it 10 min after the start.
    early = PlantParams(heat_pump=replace(hp, defrost_min_run_s=1200.0))
    run = simulate_plant(house, early, np.full(len(sp), -2.0), dt, setpoint_c=sp, t_init_c=21.0)
    assert (int(np.argmax(run["defrost"][:, 0])) - restart + 1) * dt == pytest.approx(1200.0)


def test_default_heat_pump_holds_the_design_point():
    """Sized on its design point: at the design outdoor temperature (−10 °C), with no gains,
    the default heat pump holds the setpoint through its defrosts; its nominal output makes the
    mean capacity at −10 °C, defrosts included, ``sizing`` × the design load."""
    house = default_house()
    params = PlantParams()
    hp, e = params.heat_pump, params.emitter
    n = 3 * 1440
    run = simulate_plant(house, params, np.full(n, e.design_t_out_c), 60.0,
                         setpoint_c=np.full(n, 20.0), t_init_c=20.0)
    day3 = slice(2 * 1440, n)
    air = run["t_air_c"][day3, 0]
    assert run["defrost"][day3, 0].sum() >= 20 * hp.defrost_duration_s / 60.0   # ≥ 20 defrosts
    # Held on average, no drift from day to day; each defrost (no buffer) cools the radiators
    # and dips the room by well under a kelvin.
    assert air.mean() > 19.7 and air.min() > 19.0
    assert abs(air.mean() - run["t_air_c"][1440:2 * 1440, 0].mean()) < 0.05
    design_load = house.network.hlc_w_per_k * (20.0 - e.design_t_out_c)
    nominal = Plant(house, params).nominal_w
    f = 1.0 + hp.capacity_per_k * (e.design_t_out_c - 7.0)
    mean_cap = nominal * (hp.defrost_interval_s * f - hp.defrost_duration_s * hp.defrost_draw) / (
        hp.defrost_interval_s + hp.defrost_duration_s)
    assert mean_cap == pytest.approx(hp.sizing * design_load, rel=1e-12)
    # Below the defrost band the capacity alone is sized: P_nom·f(θ_d) = sizing × load.
    cold = PlantParams(emitter=Emitter(design_t_out_c=-15.0))
    f = 1.0 + hp.capacity_per_k * (-15.0 - 7.0)
    assert Plant(house, cold).nominal_w * f == pytest.approx(
        hp.sizing * house.network.hlc_w_per_k * 35.0, rel=1e-12)


def test_house_gains_step_by_step_follow_the_batch_profiles():
    """HouseGains (one house, step-wise) gives the batch functions' levels and sun shape: night
    and day levels, the sun only 08:00–16:00 with one clearness per local day, the walk's drift
    clipped to 0…2× the level."""
    g = Gains(night_w=200.0, day_w=500.0, drift_w=0.0, solar_peak_w=1000.0)
    hg = HouseGains(g, seed=4)
    t = np.arange(0, 3 * 86400, 600.0) + 0.5 * 86400          # from noon of day 0, 10-min steps
    out = np.array([hg.step(600.0, s) for s in t])
    hour = (t / 3600.0) % 24
    night = (hour >= 22) | (hour < 7)
    assert (out[night, 0] == 200.0).all() and (out[~night, 0] == 500.0).all()
    assert (out[(hour < 8) | (hour > 16), 1] == 0).all()
    sunny = (hour > 8) & (hour < 16)
    clear = out[sunny, 1] / (1000.0 * sun_shape(hour[sunny]))
    days = (t[sunny] // 86400).astype(int)
    per_day = [np.ptp(clear[days == d]) for d in np.unique(days)]
    assert max(per_day) < 1e-12 and len({round(c, 9) for c in clear}) == len(per_day)
    # The batch profile has the same shape: solar / sun_shape is one clearness per day.
    batch = solar_gains_w(hour, t // 86400, g, 1, np.random.default_rng(0))[:, 0]
    ratio = batch[sunny] / (1000.0 * sun_shape(hour[sunny]))
    assert all(np.ptp(ratio[days == d]) < 1e-12 for d in np.unique(days))
    # Drift: a random walk, clipped at 0 and 2× the level.
    walk = HouseGains(Gains(night_w=100.0, drift_w=80.0), seed=1)
    vals = np.array([walk.step(3600.0, 23 * 3600.0)[0] for _ in range(200)])
    assert vals.min() >= 0.0 and vals.max() <= 200.0 and vals.std() > 20.0


def test_dhw_pauses_space_heating_and_loop_off_stops_it():
    house = default_house()
    n = 240
    dhw = (np.arange(n) >= 60) & (np.arange(n) < 90)
    sp = np.where(np.arange(n) < 180, 21.0, np.nan)
    params = PlantParams(heat_pump=HeatPump(defrost=0))
    run = simulate_plant(house, params, np.full(n, -5.0), 60.0, setpoint_c=sp, dhw=dhw,
                         t_init_c=21.0)
    q = run["heat_pump_w"][:, 0]
    assert (q[dhw] == 0).all() and (run["dhw_w"][dhw, 0] > 0).all()
    assert run["compressor_on"][dhw, 0].all()
    assert (q[180:] == 0).all() and not run["compressor_on"][180:, 0].any()
    assert q[100:180].min() > 0


def test_sensor_statistics():
    """Noise SD, rounding, offset and lag of the room sensor; the meter's systematic error."""
    n = 400
    houses = HouseParameters.stack([default_house()] * n)
    sens = Sensors(t_air_noise_k=0.2, t_air_quantum_k=0.0, t_air_lag_s=0.0,
                   t_air_offset_k=0.3, meter_gain_error=0.04, meter_noise=0.0,
                   t_out_noise_k=0.3)
    params = PlantParams(sensors=sens, heat_pump=HeatPump(control=2))
    run = simulate_plant(houses, params, np.full(50, 0.0), 60.0, setpoint_c=np.full(50, 21.0),
                         t_init_c=21.0, seed=7)
    err = run["t_air_sensed_c"] - run["t_air_c"]
    assert err.mean() == pytest.approx(0.3, abs=0.01)
    assert err.std() == pytest.approx(0.2, rel=0.03)
    out_err = run["t_out_sensed_c"] - run["t_out_c"]
    assert out_err.std() == pytest.approx(np.sqrt(0.3**2 + 0.1**2 / 12), rel=0.05)
    np.testing.assert_allclose(run["heat_meter_w"], 1.04 * run["heat_pump_w"], rtol=1e-12)

    coarse = params.with_section("sensors", t_air_noise_k=0.0, t_air_quantum_k=0.5,
                                 t_air_offset_k=0.0)
    houses2 = HouseParameters.stack([default_house()] * 50)
    run = simulate_plant(houses2, coarse, np.full(50, 0.0), 60.0,
                         setpoint_c=np.linspace(20.0, 22.0, 50)[:, None] + np.zeros((1, 50))
                         + np.linspace(0, 0.5, 50)[None, :], t_init_c=21.0)
    sensed = run["t_air_sensed_c"]
    np.testing.assert_allclose(sensed * 2, np.round(sensed * 2), atol=1e-9)
    err = sensed - run["t_air_c"]
    assert np.abs(err).max() <= 0.25 + 1e-9
    assert err.std() == pytest.approx(0.5 / np.sqrt(12), rel=0.1)

    lagged = params.with_section("sensors", t_air_noise_k=0.0, t_air_offset_k=0.0,
                                 t_air_lag_s=600.0)
    house = default_house()
    sp = np.where(np.arange(120) < 1, 21.0, np.nan)
    run = simulate_plant(house, lagged, np.full(120, -10.0), 60.0, setpoint_c=sp, t_init_c=21.0)
    true, seen = run["t_air_c"][:, 0], run["t_air_sensed_c"][:, 0]
    assert (seen[5:60] > true[5:60]).all()   # the housing lags the falling air temperature


def test_step_api_matches_batch():
    """Plant.step drives the same core as simulate_plant: identical results for one house."""
    house = default_house()
    params = PlantParams(emitter=Emitter.underfloor(), heat_pump=HeatPump(min_modulation=0.3),
                         sensors=Sensors(t_air_noise_k=0.2, t_air_quantum_k=0.5))
    n = 300
    te = np.linspace(-5, 5, n)
    sp = np.where(np.arange(n) < 200, 22.0, np.nan)
    run = simulate_plant(house, params, te, 60.0, setpoint_c=sp, t_init_c=21.0, seed=5)
    plant = Plant(house, params, setpoint_c=21.0, t_out_c=te[0], seed=5)
    plant.setpoint_c = 22.0
    for i in range(n):
        plant.loop_on = i < 200
        out = plant.step(60.0, te[i])
        assert out["t_air_c"] == run["t_air_c"][i, 0]
        assert out["t_air_sensed_c"] == run["t_air_sensed_c"][i, 0]
        assert out["heat_pump_w"] == run["heat_pump_w"][i, 0]
        assert out["compressor_on"] == run["compressor_on"][i, 0]
    assert plant.time_s == pytest.approx(n * 60.0)
    # DHW charges driven by a schedule, as the simulator does: space heating pauses.
    plant.loop_on = True
    dhw_steps = [periodic(i * 60.0, 3600.0, 1200.0, offset_s=0.0) for i in range(120)]
    assert sum(dhw_steps) == 40
    outs = [plant.step(60.0, 0.0, dhw=d) for d in dhw_steps]
    assert all(o["dhw"] and o["heat_pump_w"] == 0 and o["dhw_w"] > 0
               for o, d in zip(outs, dhw_steps, strict=True) if d)
    assert any(o["heat_pump_w"] > 0 for o in outs)
    assert plant.t_supply_c >= plant.t_return_c
    assert isinstance(plant.pump_on, bool)


HOUSE_TOML = open(default_house.__globals__["__file__"].replace(
    "model/house.py", "data/default_house.toml")).read()


def test_house_toml_plant_sections(tmp_path):
    path = tmp_path / "house.toml"
    path.write_text(HOUSE_TOML + '\n[plant.emitter]\nkind = "underfloor"\n'
                    '[plant.heat_pump]\ncontrol = "thermostat"\nmin_modulation = 1.0\n'
                    '[plant.sensors]\nt_air_quantum_k = 0.5\n')
    house, params = load_plant(path)
    assert house.floor_area == 150.0
    assert params.emitter.kind == 1 and params.emitter.exponent == 1.1
    assert params.heat_pump.control == 1 and params.heat_pump.min_modulation == 1.0
    assert params.sensors.t_air_quantum_k == 0.5 and params.gains.night_w == 230.0


@pytest.mark.parametrize("section, problem, place", [
    ('[plant.emitter]\nexponent = 2.0\n', "must lie in 1–1.4", "plant.emitter.exponent"),
    ('[plant.emitter]\nkind = "fan coil"\n', "must be one of", "plant.emitter.kind"),
    ('[plant.heat_pump]\nmin_on_s = "long"\n', "must be a number", "plant.heat_pump.min_on_s"),
    ('[plant.sensors]\nlag = 3\n', "unknown key", "plant.sensors.lag"),
    ('[plant.heat_pump]\ncontrol = 0.5\n', "whole number", "plant.heat_pump.control"),
    ('[plant.windows]\nopen = 1\n', "unknown section", "plant.windows"),
    ('plant = 3\n', "must be a table", "'plant'"),
])
def test_bad_plant_sections_one_line(tmp_path, section, problem, place):
    path = tmp_path / "house.toml"
    path.write_text(section + HOUSE_TOML if section.startswith("plant =") else
                    HOUSE_TOML + "\n" + section)
    with pytest.raises(InputError) as info:
        load_plant(path)
    line = str(info.value)
    assert "\n" not in line and str(path) in line and problem in line and place in line
    # The same file through a command: one line on stderr, exit status 2.
    proc = subprocess.run([sys.executable, "-m", "impctl.plant", str(path)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip() == line and proc.stdout == ""
