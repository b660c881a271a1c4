"""Weather: the seeded winter generator and EPW / CSV files."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from impctl.errors import InputError
from impctl.weather import read_weather, winter_temperatures, winter_weather


def test_generator_is_seeded_and_wintry():
    a = winter_weather(days=30, seed=3)
    b = winter_weather(days=30, seed=3)
    c = winter_weather(days=30, seed=4)
    pd.testing.assert_series_equal(a, b)
    assert not np.allclose(a.to_numpy(), c.to_numpy())
    assert len(a) == 30 * 24 and a.index.tz is not None
    assert -6.0 < a.mean() < 5.0 and a.min() > -30.0 and a.max() < 20.0
    # Nights colder than afternoons on average (minimum 06:00, maximum 15:00 local).
    assert a[a.index.hour == 6].mean() < a[a.index.hour == 15].mean() - 1.0
    sub = winter_weather(days=2, step_s=300, seed=3)
    assert (sub.index[1] - sub.index[0]).total_seconds() == 300


@pytest.mark.parametrize("zone", ["Europe/Ljubljana", "UTC", "America/New_York",
                                  "Australia/Lord_Howe"])
def test_the_arrays_are_the_series_numbers_across_the_clock_changes(zone):
    """The generator without pandas (the simulator's) gives the series' times and values to the
    bit, over the spring and autumn clock changes and a half-hour offset (Lord Howe)."""
    from datetime import datetime
    from zoneinfo import ZoneInfo

    for start in ("2026-03-20 00:00", "2026-10-20 06:00", "2026-04-01 00:00"):
        series = winter_weather(start, days=14, step_s=900, seed=5, tz=zone)
        aware = datetime.fromisoformat(start).replace(tzinfo=ZoneInfo(zone))
        t, v = winter_temperatures(aware, days=14, step_s=900, seed=5)
        assert np.array_equal(t, series.index.as_unit("ns").asi8 / 1e9)
        assert np.array_equal(v, series.to_numpy())
    with pytest.raises(ValueError, match="aware"):
        winter_temperatures(datetime(2026, 1, 1))


def _epw(path, temps, offset_h=1):
    header = [f"LOCATION,Ljubljana,-,SVN,IWEC,130140,46.22,14.48,{offset_h:.1f},385.0"]
    header += ["DESIGN CONDITIONS,0", "TYPICAL/EXTREME PERIODS,0", "GROUND TEMPERATURES,0",
               "HOLIDAYS/DAYLIGHT SAVINGS,No,0,0,0", "COMMENTS 1,x", "COMMENTS 2,x",
               "DATA PERIODS,1,1,Data,Sunday, 1/ 1,12/31"]
    rows = [f"2005,1,1,{h + 1},60,?9?9?9,{t:.1f},-5.0,80,98000" for h, t in enumerate(temps)]
    path.write_text("\n".join(header + rows) + "\n")


def test_epw_file_is_read_in_local_standard_time(tmp_path):
    path = tmp_path / "w.epw"
    temps = [float(-h) for h in range(24)]
    _epw(path, temps)
    series = read_weather(path, tz="UTC")
    assert len(series) == 24
    np.testing.assert_allclose(series.to_numpy(), temps)
    # Hour 1 of local standard time UTC+1 is stamped at its start, 00:00+01:00 = 23:00 UTC.
    assert series.index[0] == pd.Timestamp("2004-12-31 23:00", tz="UTC")


def test_epw_missing_temperature_names_the_row(tmp_path):
    path = tmp_path / "w.epw"
    _epw(path, [1.0, 99.9, 2.0])
    with pytest.raises(InputError, match="row 10"):
        read_weather(path)


def test_csv_weather_and_its_errors(tmp_path):
    good = tmp_path / "w.csv"
    good.write_text("timestamp,t_out\n2026-01-01T00:00+01:00,-3.5\n2026-01-01T01:00+01:00,-4\n")
    series = read_weather(good)
    np.testing.assert_allclose(series.to_numpy(), [-3.5, -4.0])
    bad = tmp_path / "bad.csv"
    bad.write_text("timestamp,temperature\n2026-01-01T00:00,1\n")
    with pytest.raises(InputError, match="missing column 't_out'"):
        read_weather(bad)
    with pytest.raises(InputError, match="file not found"):
        read_weather(tmp_path / "nope.csv")
