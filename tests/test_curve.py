"""The heating curve this house needs (``impctl.curve``) on the realistic plant: the emitter
measured, the need against the true house, the curve the heat pump runs read back, the
recommended line, the saving — and the plant running a two-point flow curve."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from impctl.curve import analyse
from impctl.curve.data.rows import rows_from_table
from impctl.curve.data.synth import owner_rows
from impctl.curve.emitter import EmitterUnknown, fit_emitter
from impctl.curve.need import GRID_T_OUT_C, NeedCurve, recommend, required_flow_c
from impctl.curve.savings import ASSUMED_DAYS, winter_climate
from impctl.imp.tables import parse_timestamps
from impctl.model import default_house
from impctl.plant import HeatPump, PlantCore, PlantParams, simulate_plant
from impctl.plant.hydronics.flow_curve import flow_for_node

TZ = "Europe/Ljubljana"
#: An installer's curve 30 % above the matched one, no room influence: the room overheats.
HIGH = PlantParams(heat_pump=HeatPump(curve_gain=1.3, room_influence_k_per_k=0.0))


def _table(rows: pd.DataFrame) -> pd.DataFrame:
    table = rows.copy()
    table["timestamp"] = parse_timestamps(table["timestamp"], "rows", TZ)
    return rows_from_table(table, "rows")


@pytest.fixture(scope="module")
def high():
    """14 owner days of the default house under a high installer's curve."""
    rows, core = owner_rows(default_house(), HIGH, 14, seed=3)
    return _table(rows), core


def _true_flow_c(core: PlantCore, t_out_c: float, gain_w: float = 230.0) -> float:
    """The flow the true house needs at ``t_out_c`` for 21 °C with its night gain [°C]."""
    q = max(float(core.hlc[0]) * (21.0 - t_out_c) - gain_w, 0.0)
    node = 21.0 + (q / core.k_w[0]) ** (1.0 / core.exponent[0])
    return float(flow_for_node(node, 21.0, core.k_w[0], core.exponent[0],
                               core.flow_lag_k_per_w[0]))


def test_the_curve_of_a_house_whose_installer_set_it_high(high):
    rows, core = high
    res = analyse(rows, None, setpoint_c=21.0)
    e = res.emitter.interval()
    # the radiators measured: the true exponent inside the interval, K close to the truth
    assert e["exponent"]["low"] <= core.exponent[0] <= e["exponent"]["high"]
    assert abs(np.exp(res.emitter.ln_k) / core.k_w[0] - 1) < 0.25
    # the need at 0 °C against the true house's (its heat loss, its night gain, its emitter)
    central0 = float(np.interp(0.0, res.need_curve.t_out_c, res.need_curve.central_c))
    assert abs(central0 - _true_flow_c(core, 0.0)) < 1.5
    # the curve it runs, read back from the heat pump's own flow target
    installer0 = core.controller.steady_flow_c(
        core.controller.target_water_c(np.array([21.0]), np.array([21.0]), np.array([0.0])),
        21.0, core.flow_lag_k_per_w)[0]
    assert res.running.source == "target"
    assert abs(res.running.line.at(0.0) - installer0) < 1.0
    # lower than it, above the need, and a saving
    assert res.lowers
    assert _true_flow_c(core, 0.0) < res.recommended.at(0.0) < res.running.line.at(0.0)
    assert res.savings.saving_kwh > 0 and res.savings.saving_low_kwh > 0
    assert "hotter than this house needs" in res.advice()


def test_a_curve_that_matches_the_house_is_kept():
    rows, _ = owner_rows(default_house(), PlantParams(heat_pump=HeatPump(curve_gain=0.95)), 10,
                         seed=4)
    res = analyse(_table(rows), None, setpoint_c=21.0)
    assert not res.lowers
    assert "lowering it" in res.advice()


def test_without_the_heat_pumps_electricity_the_efficiency_is_assumed(high):
    rows, _ = high
    res = analyse(rows.assign(p_el_w=np.nan), None, setpoint_c=21.0)
    assert res.cop.assumed and res.to_dict()["cop"]["assumed"] is True
    assert any("ASSUMED" in n for n in res.notes)
    measured = analyse(rows, None, setpoint_c=21.0)
    assert not measured.cop.assumed and abs(measured.cop.eta - 0.45) < 0.05


def test_nights_without_flow_and_return_are_refused_in_one_line(high):
    rows, _ = high
    with pytest.raises(Exception) as err:
        analyse(rows.assign(t_flow_c=np.nan, t_return_c=np.nan), None)
    assert "t_flow_c, t_return_c" in str(err.value) and "\n" not in str(err.value)


def test_the_emitter_is_read_back_from_its_blocks():
    rng = np.random.default_rng(0)
    n = 40
    dt = rng.uniform(8.0, 25.0, n)
    q = 90.0 * dt**1.3 * np.exp(0.03 * rng.standard_normal(n))
    blocks = pd.DataFrame({"t_water_c": 21.0 + dt, "t_air_c": 21.0, "q_w": q,
                           "spread_k": q / 1500.0,
                           "evening": np.repeat(np.arange(n // 2), 2)})
    fit = fit_emitter(blocks)
    iv = fit.interval()
    assert iv["exponent"]["low"] <= 1.3 <= iv["exponent"]["high"]
    assert iv["k_w_per_k_n"]["low"] <= 90.0 <= iv["k_w_per_k_n"]["high"]
    assert abs(fit.flow_w_per_k - 1500.0) < 1.0
    with pytest.raises(EmitterUnknown):
        fit_emitter(blocks.iloc[:2])


@pytest.mark.parametrize("seed", range(20))
def test_the_recommended_line_is_the_lowest_above_the_need(seed):
    rng = np.random.default_rng(seed)
    t = GRID_T_OUT_C
    curvature = rng.uniform(0.0, 0.02)
    central = 35.0 - rng.uniform(0.3, 1.0) * t - curvature * (t + 15.0) ** 2
    upper = central + rng.uniform(0.2, 1.0) + 0.05 * np.abs(t - 2.0)
    curve = NeedCurve(t, central, upper, np.maximum(3000.0 - 150.0 * t, 0.0))
    weights = np.exp(-0.5 * ((t + 1.0) / 4.0) ** 2)
    line = recommend(curve, 1.0, weights, 21.0, cold_c=-10.0, anchor_c=2.0)
    need = required_flow_c(curve, 1.0, 21.0, -10.0, 2.0)
    held = np.isfinite(need)
    assert np.all(line.at(t)[held] >= need[held] - 1e-6)
    # no line on a fine grid of the two points is feasible and cheaper
    a, b = np.meshgrid(np.arange(20.0, 70.0, 0.1), np.arange(20.0, 45.0, 0.1))
    s = (t[held] + 15.0) / 30.0
    lines = a[..., None] + (b - a)[..., None] * s
    feasible = np.all(lines >= need[held] - 1e-9, axis=-1)
    sw = (t + 15.0) / 30.0
    cost = lambda fa, fb: fa * np.sum(weights * (1 - sw)) + fb * np.sum(weights * sw)  # noqa: E731
    assert cost(line.flow_a_c, line.flow_b_c) <= cost(a, b)[feasible].min() + 1e-6


def test_a_recorded_season_is_the_winter_else_an_assumed_one():
    stamps = pd.date_range("2026-10-15", periods=100 * 24, freq="1h", tz=TZ)
    rows = pd.DataFrame({"timestamp": stamps, "t_out": 3.0 + np.sin(np.arange(len(stamps)))})
    climate = winter_climate(rows)
    assert climate.source == "recorded" and climate.days == pytest.approx(100.0)
    short = winter_climate(rows.iloc[:240])
    assert short.source == "assumed" and short.days == ASSUMED_DAYS
    assert "assumed" in short.describe()


def test_the_plant_runs_a_two_point_flow_curve():
    """With curve points (45 °C at −15 °C, 30 °C at +15 °C) the heat pump aims its flow at the
    line: at a steady 0 °C the flow it reports as its target is 37.5 °C, and the water the
    radiators hold settles where that flow's heat goes out."""
    house = default_house()
    params = PlantParams(heat_pump=HeatPump(room_influence_k_per_k=0.0, defrost=0,
                                            min_modulation=0.3))
    core = PlantCore(house, params, seed=0, n=1)
    core.start_steady(21.0, 0.0)
    core.set_flow_curve(45.0, 30.0, 21.0)
    steps = 3 * 1440
    run = simulate_plant(house, params, np.zeros(steps), 60.0, setpoint_c=np.full(steps, 21.0),
                         internal_gains_w=230.0, core=core,
                         outputs=("t_supply_c", "heat_pump_w", "t_air_c", "t_water_c"))
    assert core.controller.flow_target_c[0] == pytest.approx(37.5, abs=0.05)
    last = slice(-1440, None)
    on = run["heat_pump_w"][last, 0] > 0
    assert abs(np.mean(run["t_supply_c"][last, 0][on]) - 37.5) < 1.5
    # taken off (the owner's own points back), the house's target is its built-in curve's
    # again: the last curve's flow is not left standing
    core.set_flow_curve(np.nan, np.nan, 21.0)
    assert not np.isfinite(core.controller.flow_target_c).any()
    # the built-in curve elsewhere: NaN points leave a house on its own curve
    core2 = PlantCore(house, params, seed=0, n=1)
    core2.set_flow_curve(np.nan, np.nan, 21.0)
    assert not np.isfinite(core2.controller.flow_target_c).any()


def test_a_room_kept_too_warm_counts_in_the_saving(high):
    """The installer's curve warms the room above the setpoint (no room influence): the
    lower curve saves that heat as well as the COP's, and says how warm the room runs."""
    from impctl.curve.savings import season_savings

    rows, _ = high
    res = analyse(rows, None, setpoint_c=21.0)
    s = res.savings
    assert s.room_excess_k > 0.5 and 0.0 <= s.room_excess_new_k < s.room_excess_k
    cop_only = season_savings(res.need, res.cop, res.running.line, res.recommended,
                              res.climate, 21.0, np.random.default_rng(0))
    assert cop_only.room_excess_k == 0.0
    assert s.saving_kwh > 1.2 * cop_only.saving_kwh
    assert s.running_kwh > cop_only.running_kwh  # the warm room's heat is in the running's
    assert f"Your rooms run {s.room_excess_k:.1f} K above 21.0 °C" in res.advice()
    block = res.to_dict()["savings"]["room_above_setpoint_k"]
    assert block == {"running": round(s.room_excess_k, 2),
                     "recommended": round(s.room_excess_new_k, 2)}


def test_a_constant_flow_temperature_is_told_from_a_curve(high):
    rows, _ = high
    assert not analyse(rows, None, setpoint_c=21.0).running.constant
    res = analyse(rows.assign(t_flow_target_c=45.0), None, setpoint_c=21.0)
    assert res.running.slope_read and res.running.constant
    assert res.to_dict()["running"]["constant"] is True
    assert "45 °C whatever the weather outside" in res.advice()
