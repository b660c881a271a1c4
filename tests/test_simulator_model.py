"""The simulated plant: thermostat, emitter lag, heating off, COP, counters, interruptions."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from impctl_sim import Plant, PlantParams, WeatherFeed
from impctl_sim.image import initial_rw, kronoterm_values, register_words

from impctl.heatpump import REGISTERS, Generation, decode
from impctl.model import HouseParameters, default_house, load_house, simulate

DT = 60.0


def settle(plant: Plant, hours: float, t_out_c: float = -5.0, dt: float = DT) -> None:
    for _ in range(int(hours * 3600 / dt)):
        plant.step(dt, t_out_c)


def steady_plant(t_out_c: float = -5.0, **params) -> Plant:
    plant = Plant(default_house(), PlantParams(**params), setpoint_c=21.0)
    settle(plant, 96, t_out_c, dt=300.0)
    settle(plant, 2, t_out_c)
    return plant


def test_thermostat_holds_and_tracks_the_setpoint():
    plant = steady_plant()
    assert plant.t_air_c == pytest.approx(21.0, abs=0.1)
    # In steady state the heat given equals the house's loss at 21 °C vs −5 °C.
    hlc = float(default_house().hlc_w_per_k)
    assert plant.q_em_w == pytest.approx(hlc * 26.0, rel=0.05)
    plant.setpoint_c = 19.0
    settle(plant, 12)
    assert plant.t_air_c == pytest.approx(19.0, abs=0.15)


def test_heat_keeps_flowing_about_an_hour_after_switch_off():
    plant = steady_plant()
    q0 = plant.q_em_w
    plant.loop_mode = 0
    plant.step(DT, -5.0)
    assert plant.p_th_w == 0.0 and plant.q_em_w > 0.9 * q0
    settle(plant, 0.5)
    assert 0.3 * q0 < plant.q_em_w < 0.4 * q0 + 200  # ≈ e^(−30/20) plus the falling air
    settle(plant, 0.5)
    assert 0.0 < plant.q_em_w < 0.25 * q0
    settle(plant, 2)
    assert plant.q_em_w < 0.02 * q0 and plant.p_el_w == pytest.approx(20.0)


def test_emitter_free_house_matches_the_model_when_heating_is_off():
    house = default_house()
    plant = Plant(house, PlantParams(), setpoint_c=21.0)
    plant.system_on = 0
    plant.t_w_c = -100.0  # emitter below the air: gives nothing, so the house free-floats
    t_out = np.full(120, -3.0)
    ref = simulate(house, t_out, DT, t_m_init_c=21.0)
    airs = []
    for t in t_out:
        plant.step(DT, float(t))
        airs.append(plant.t_air_c)
    np.testing.assert_allclose(airs, ref.t_air_c, atol=1e-9)
    assert plant.p_th_w == 0 and plant.p_el_w == 0 and plant.e_th_kwh == 0


def test_cop_and_energy_counters():
    plant = steady_plant(t_out_c=-5.0)
    assert 1.5 <= plant.cop <= 6.5
    assert plant.p_el_w == pytest.approx(plant.p_th_w / plant.cop + 20.0)
    e_th, e_el = plant.e_th_kwh, plant.e_el_kwh
    settle(plant, 1)
    assert plant.e_th_kwh - e_th == pytest.approx(plant.p_th_w / 1000, rel=0.05)
    assert 0 < plant.e_el_kwh - e_el < plant.e_th_kwh - e_th
    warm = steady_plant(t_out_c=10.0)
    assert warm.cop > plant.cop  # smaller lift, better COP


def test_dhw_and_defrost_interrupt_space_heating():
    plant = steady_plant(dhw_period_s=6 * 3600.0, defrost_period_s=3600.0)
    seen_dhw = seen_defrost = False
    for _ in range(int(6 * 3600 / DT)):
        plant.step(DT, -5.0)
        values = kronoterm_values(plant, initial_rw(21.0), room_thermostat=True,
                                  t_air_c=plant.t_air_c, t_out_c=-5.0)
        if plant.dhw_active:
            seen_dhw = True
            assert values[2001] == 1 and plant.q_em_w >= 0 and values[2329] > 0
        if plant.defrost_active:
            seen_defrost = True
            assert values[2011] == 1 and values[2329] < 0
    assert seen_dhw and seen_defrost


def test_register_image_encodings():
    plant = steady_plant()
    plant.t_air_c = 20.96  # quantised to 0.1 °C on the wire
    values = kronoterm_values(plant, initial_rw(21.0), room_thermostat=True,
                              t_air_c=plant.t_air_c, t_out_c=-5.04)
    blocks = dict(register_words(values, Generation.EXTENDED, missing={2102}))
    words = blocks[1999]  # MA 2000 at PDU address 1999

    def word(ma: int) -> int:
        return words[ma - 2000]

    assert word(2160) == 210 and word(2103) == (-50) & 0xFFFF and word(2102) == (-600) & 0xFFFF
    assert word(2187) == 210 and word(2042) == 1 and word(2161) == (-400) & 0xFFFF
    thermal = decode(REGISTERS[2363], [word(2363), word(2364)], pd.Timestamp.now(tz="UTC"))
    assert thermal.value == pytest.approx(int(plant.e_th_kwh * 10) / 10)
    compact = dict(register_words(values, Generation.COMPACT))
    assert set(compact) == {538, 1999, 2127, 2159, 2186}
    assert len(compact[1999]) == 127  # MA 2000–2126


def test_weather_feed_interpolates_and_wraps():
    index = pd.date_range("2026-01-01", periods=3, freq="h", tz="UTC")
    feed = WeatherFeed(pd.Series([0.0, 2.0, 4.0], index=index))
    t0 = index[0].timestamp()
    assert feed.t_out_c(t0 + 1800) == pytest.approx(1.0)
    assert feed.t_out_c(t0 + 7200 + 1800) == pytest.approx(1.0)  # wrapped after the end


def test_plant_from_a_house_file(tmp_path):
    path = tmp_path / "h.toml"
    path.write_text("floor_area = 100\nwall_height = 2.5\nwalls_area = 150\nwindows_area = 20\n"
                    "c_f = 2.6\nu_walls = 0.3\nu_windows = 1.1\nach_vent = 0\nach_infl = 0.5\n"
                    "max_heating_power = 6000\n")
    plant = Plant(load_house(path))
    assert plant.max_power_w == 6000.0
    with pytest.raises(ValueError, match="one house"):
        Plant(HouseParameters.stack([default_house(), default_house()]))
