"""House files and ``impctl simulate`` end to end, run in this process."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from cli_fixtures import run_impctl

from impctl.errors import InputError
from impctl.model import HouseParameters, load_house, simulate

GOOD = """\
floor_area = 120.0
wall_height = 2.5
walls_area = 150.0
windows_area = 24.0
c_f = 2.6
u_walls = 0.4
u_windows = 1.2
ach_vent = 0.0
ach_infl = 0.3
"""


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return run_impctl(*args, cwd=cwd)  # in this process: the tests check the output


@pytest.fixture
def house_file(tmp_path: Path) -> Path:
    path = tmp_path / "house.toml"
    path.write_text(GOOD)
    return path


def test_load_house_reads_all_keys_and_defaults(house_file):
    house = load_house(house_file)
    assert house.floor_area == 120.0 and house.c_f == 2.6
    assert house.heat_recovery == 0.0 and house.max_heating_power == float("inf")


@pytest.mark.parametrize(
    "text, key, words",
    [
        (GOOD + "colour = 3\n", "colour", "unknown key"),
        (GOOD.replace("c_f = 2.6\n", ""), "c_f", "missing key"),
        (GOOD.replace("c_f = 2.6", 'c_f = "heavy"'), "c_f", "must be a number"),
        (GOOD.replace("c_f = 2.6", "c_f = true"), "c_f", "must be a number"),
        (GOOD.replace("floor_area = 120.0", "floor_area = -5"), "floor_area",
         "-5 is outside the plausible range [10, 5000] m²"),
        (GOOD.replace("windows_area = 24.0", "windows_area = 0"), "windows_area",
         "(0, 5000] m²"),
        (GOOD.replace("c_f = 2.6", "c_f = 6.0"), "c_f", "[0.5, 5]"),
        (GOOD.replace("ach_infl = 0.3", "ach_infl = 0.0"), "ach_infl", "ach_vent + ach_infl"),
        (GOOD + "heat_recovery = 2\n", "heat_recovery", "[0, 1]"),
        (GOOD + "max_heating_power = -1\n", "max_heating_power", "[100, 1e+06] W"),
    ],
)
def test_bad_house_file_names_file_and_key(tmp_path, text, key, words):
    path = tmp_path / "h.toml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        load_house(path)
    message = str(info.value)
    assert str(path) in message and f"key '{key}'" in message and words in message
    assert "\n" not in message


def test_bad_toml_syntax(tmp_path):
    path = tmp_path / "h.toml"
    path.write_text("floor_area = = 3\n")
    with pytest.raises(InputError, match="not valid TOML"):
        load_house(path)


def _drivers(tmp_path: Path, rows: list[str], header: str = "timestamp,t_out,setpoint,phi_hc"):
    path = tmp_path / "drivers.csv"
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def test_simulate_cli_end_to_end_matches_model(tmp_path, house_file):
    rows = []
    ts = pd.date_range("2026-01-10 18:00", periods=16, freq="30min")
    for i, t in enumerate(ts):
        sp = "" if 8 <= i < 12 else "21"        # heating off for 2 h
        phi = "1500" if i == 14 else ""          # one forced step
        rows.append(f"{t.isoformat()},{-2 - 0.1 * i:.1f},{sp},{phi}")
    drivers = _drivers(tmp_path, rows)
    out = tmp_path / "out.csv"
    result = run_cli("simulate", "--house", str(house_file), "--drivers", str(drivers),
                     "--out", str(out), "--t-m-init", "20.5")
    assert result.returncode == 0, result.stderr
    assert "HLC" in result.stdout and "W/K" in result.stdout
    df = pd.read_csv(out)
    assert list(df.columns) == ["timestamp", "t_out", "t_air", "t_s", "t_m", "phi_hc"]
    assert len(df) == 16
    # Same numbers as calling the model directly with the same inputs.
    sp = np.array([np.nan if 8 <= i < 12 else 21.0 for i in range(16)])
    forced = np.full(16, np.nan)
    forced[14] = 1500.0
    ref = simulate(load_house(house_file), df["t_out"].to_numpy(), 1800, setpoint_c=sp,
                   phi_hc_w=forced, t_m_init_c=20.5)
    np.testing.assert_allclose(df["t_air"], ref.t_air_c, atol=1e-4)
    np.testing.assert_allclose(df["t_m"], ref.t_m_c, atol=1e-4)
    np.testing.assert_allclose(df["phi_hc"], ref.phi_hc_w, atol=1e-4)
    assert (df["phi_hc"].iloc[8:12] == 0).all() and df["phi_hc"].iloc[14] == 1500.0
    assert df["t_air"].iloc[11] < 21.0 - 0.5


def test_simulate_setpoint_and_heating_off_options(tmp_path, house_file):
    ts = pd.date_range("2026-01-10 20:00", periods=12, freq="h")
    drivers = _drivers(tmp_path, [f"{t.isoformat()},0" for t in ts], header="timestamp,t_out")
    out = tmp_path / "out.csv"
    result = run_cli("simulate", "--house", str(house_file), "--drivers", str(drivers),
                     "--out", str(out), "--setpoint", "22", "--heating-off", "22:00-05:00")
    assert result.returncode == 0, result.stderr
    df = pd.read_csv(out)
    hours = pd.to_datetime(df["timestamp"].str.slice(0, 19)).dt.hour
    off = (hours >= 22) | (hours < 5)
    assert (df.loc[off, "phi_hc"] == 0).all()
    assert (df.loc[~off, "phi_hc"] > 0).all()
    assert np.allclose(df.loc[~off & (hours < 22), "t_air"], 22.0, atol=1e-3)


def test_simulate_without_arguments_prints_summary():
    result = run_cli("simulate", "--days", "3")
    assert result.returncode == 0, result.stderr
    for word in ("HLC", "tau", "mean heating power", "min t_air", "max t_air"):
        assert word in result.stdout


@pytest.mark.parametrize(
    "header, rows, words, row",
    [
        ("timestamp,temp", ["2026-01-01T00:00,1"], "missing column 't_out'", "row 1"),
        ("timestamp,t_out", ["2026-01-01T00:00,1", "yesterday,2"], "cannot parse", "row 3"),
        ("timestamp,t_out", ["2026-01-01T00:00,1", "2026-01-01T01:00,2", "2026-01-01T03:00,2"],
         "unequal steps", "row 4"),
        ("timestamp,t_out", ["2026-01-01T00:00,1", "2026-01-01T01:00,nan"], "not a finite",
         "row 3"),
        ("timestamp,t_out", ["2026-01-01T00:00,1", "2026-01-01T01:00,warm"], "not a finite",
         "row 3"),
        ("timestamp,t_out", ["2026-01-01T00:00,1", "2026-01-01T01:00,"], "empty cell", "row 3"),
        ("timestamp,t_out,phi_hc", ["2026-01-01T00:00,1,", "2026-01-01T01:00,1,lots"],
         "column 'phi_hc'", "row 3"),
    ],
)
def test_bad_drivers_give_one_line_exit_2_and_no_output(tmp_path, house_file, header, rows,
                                                         words, row):
    drivers = _drivers(tmp_path, rows, header=header)
    out = tmp_path / "out.csv"
    result = run_cli("simulate", "--house", str(house_file), "--drivers", str(drivers),
                     "--out", str(out))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert str(drivers) in lines[0] and words in lines[0] and row in lines[0]
    assert not out.exists()
    assert list(tmp_path.glob(".out.csv*")) == []


def test_empty_drivers_file(tmp_path, house_file):
    drivers = tmp_path / "empty.csv"
    drivers.write_text("")
    result = run_cli("simulate", "--house", str(house_file), "--drivers", str(drivers),
                     "--out", str(tmp_path / "o.csv"))
    assert result.returncode == 2 and "empty" in result.stderr
    assert not (tmp_path / "o.csv").exists()


def test_bad_house_file_through_cli(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(GOOD.replace("u_walls = 0.4\n", ""))
    result = run_cli("simulate", "--house", str(bad), "--days", "1")
    assert result.returncode == 2
    assert result.stderr.strip() == f"impctl: {bad}: key 'u_walls': missing key"


def test_house_parameters_stack_and_take_round_trip(house_file):
    house = load_house(house_file)
    many = HouseParameters.stack([house, house])
    assert many.n_houses == 2 and many.take(1) == house
