"""Outdoor temperature: a seeded winter generator and EPW/CSV weather files.

The functions return a pandas Series of outdoor dry-bulb temperature [°C] indexed by
timezone-aware timestamps at a fixed step; :func:`winter_temperatures` gives the generator's
series as arrays, without pandas (the Modbus simulator, which starts often, does not load it).

The built-in generator's climate (documented, not fitted to any station) is a continental
heating-season climate like the paper's case study (Slovenj Gradec, Slovenia, Dec–Jan):

* daily mean temperature: AR(1) around ``mean_c`` = −0.5 °C, stationary standard deviation
  ``daily_sd_k`` = 4.0 K, day-to-day correlation ``daily_corr`` = 0.7;
* diurnal cycle: a sine with a daily amplitude drawn uniformly in ``amplitude_k`` = (1.5, 4.5) K,
  minimum at 06:00 and maximum at 15:00 local time (two half-sines, continuous);
* hour-to-hour noise: AR(1) with standard deviation 0.3 K and correlation 0.8.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, tzinfo
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import InputError

if TYPE_CHECKING:
    import pandas as pd

DEFAULT_TZ = "Europe/Ljubljana"


@dataclass(frozen=True)
class WinterClimate:
    """Parameters of the built-in winter generator (see the module docstring; °C and K)."""

    mean_c: float = -0.5
    daily_sd_k: float = 4.0
    daily_corr: float = 0.7
    amplitude_k: tuple[float, float] = (1.5, 4.5)
    hour_min: float = 6.0
    hour_max: float = 15.0
    noise_sd_k: float = 0.3
    noise_corr: float = 0.8


def _ar1(rng: np.random.Generator, n: int, sd: float, corr: float) -> np.ndarray:
    out = np.empty(n)
    x = rng.normal(0.0, sd)
    innov = sd * np.sqrt(1.0 - corr**2)
    for i in range(n):
        out[i] = x
        x = corr * x + rng.normal(0.0, innov)
    return out


def _diurnal_shape(hour: np.ndarray, h_min: float, h_max: float) -> np.ndarray:
    """−1 at h_min, +1 at h_max, half-cosines in between (continuous, period 24 h)."""
    rise = (hour - h_min) % 24.0
    rise_len = (h_max - h_min) % 24.0
    fall_len = 24.0 - rise_len
    up = -np.cos(np.pi * rise / rise_len)
    down = np.cos(np.pi * (rise - rise_len) / fall_len)
    return np.where(rise <= rise_len, up, down)


def winter_weather(
    start: str | pd.Timestamp = "2026-01-05 00:00",
    days: float = 31,
    step_s: float = 3600,
    seed: int = 0,
    tz: str = DEFAULT_TZ,
    climate: WinterClimate = WinterClimate(),
) -> pd.Series:
    """Generate winter outdoor temperatures [°C] at ``step_s`` for ``days`` days.

    Parameters
    ----------
    start : local start time (naive → localised to ``tz``)
    days : length [days]
    step_s : sampling step [s]; the series holds floor(days·86400/step_s) samples
    seed : random seed; the same seed gives the same weather
    tz : IANA time zone of the timestamps
    climate : WinterClimate

    Returns
    -------
    pandas.Series named ``t_out`` [°C]
    """
    import pandas as pd

    start_ts = pd.Timestamp(start)
    if start_ts.tzinfo is None:
        start_ts = start_ts.tz_localize(tz)
    n = _samples(days, step_s)
    index = start_ts + pd.to_timedelta(np.arange(n) * step_s, unit="s")
    hours_since = (index - start_ts.normalize()).total_seconds().to_numpy() / 3600.0
    local_hour = (index.hour + index.minute / 60.0 + index.second / 3600.0).to_numpy()
    return pd.Series(_temperatures(hours_since, local_hour, days, seed, climate), index=index,
                     name="t_out")


def winter_temperatures(start: datetime, days: float = 31, step_s: float = 3600,
                        seed: int = 0, climate: WinterClimate = WinterClimate()
                        ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`winter_weather`'s series as arrays, without pandas: (POSIX time [s], outdoor
    temperature [°C]); ``start`` is time zone-aware, and its zone is the weather's. The same
    numbers as :func:`winter_weather` from that start (whole-second steps)."""
    if start.tzinfo is None:
        raise ValueError("start must be time zone-aware")
    n = _samples(days, step_s)
    zone = start.tzinfo
    start_s = start.timestamp()
    offsets = np.arange(n) * float(step_s)
    midnight = datetime(start.year, start.month, start.day, tzinfo=zone).timestamp()
    hours_since = (offsets + (start_s - midnight)) / 3600.0
    posix_s = start_s + offsets
    local_s = np.floor(posix_s + _utc_offsets_s(posix_s, zone)) % 86400.0
    hour, rest = np.divmod(local_s, 3600.0)
    minute, second = np.divmod(rest, 60.0)
    local_hour = hour + minute / 60.0 + second / 3600.0
    return posix_s, _temperatures(hours_since, local_hour, days, seed, climate)


def _utc_offsets_s(posix_s: np.ndarray, zone: tzinfo) -> np.ndarray:
    """The zone's UTC offset [s] at each POSIX time."""
    return np.array([datetime.fromtimestamp(t, zone).utcoffset().total_seconds()
                     for t in posix_s.tolist()])


def _samples(days: float, step_s: float) -> int:
    n = int(round(days * 86400.0 / step_s)) if step_s > 0 and days > 0 else 0
    if n < 1:
        raise InputError(f"{days:g} days at a {step_s:g} s step hold no sample",
                         place="--days")
    return n


def _temperatures(hours_since: np.ndarray, local_hour: np.ndarray, days: float, seed: int,
                  climate: WinterClimate) -> np.ndarray:
    """The generator's temperatures [°C] at ``hours_since`` the start's local midnight [h],
    ``local_hour`` the local time of day [h]."""
    rng = np.random.default_rng(seed)
    n_days = int(np.ceil(days)) + 2
    daily = climate.mean_c + _ar1(rng, n_days, climate.daily_sd_k, climate.daily_corr)
    amp = rng.uniform(*climate.amplitude_k, size=n_days)
    # Daily mean and amplitude interpolated between day centres, so no jump at midnight.
    centres = np.arange(n_days) * 24.0 - 12.0
    mean_t = np.interp(hours_since, centres, daily)
    amp_t = np.interp(hours_since, centres, amp)
    n_hours = int(np.ceil(hours_since[-1])) + 2
    noise_h = _ar1(rng, n_hours, climate.noise_sd_k, climate.noise_corr)
    noise = np.interp(hours_since, np.arange(n_hours), noise_h)
    return mean_t + amp_t * _diurnal_shape(local_hour, climate.hour_min, climate.hour_max) + noise


def read_weather(path: str | Path, tz: str = DEFAULT_TZ) -> pd.Series:
    """Read outdoor temperature [°C] from an EPW file or a ``timestamp,t_out`` CSV.

    EPW: the dry-bulb column (field 7) with hours 1–24 as hour-ending local standard time; the
    series is stamped at the start of each hour. CSV: ISO 8601 timestamps (naive ones are
    localised to ``tz``).

    Raises
    ------
    InputError
        Unreadable file, missing column, bad number or timestamp.
    """
    import pandas as pd

    path = Path(path)
    if not path.exists():
        raise InputError("file not found", path)
    if path.suffix.lower() == ".epw":
        return _read_epw(path, tz)
    from .imp.tables import read_table

    table = read_table(path, required=("timestamp", "t_out"), numeric=("t_out",), tz=tz)
    return pd.Series(table["t_out"].to_numpy(), index=table["timestamp"], name="t_out")


def _read_epw(path: Path, tz: str) -> pd.Series:
    import pandas as pd

    try:
        header = path.read_text(errors="replace").splitlines()[0].split(",")
        raw = pd.read_csv(path, skiprows=8, header=None)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise InputError(f"not a readable EPW file: {exc}", path) from None
    if raw.shape[1] < 7:
        raise InputError("EPW data rows need at least 7 fields", path, "row 9")
    try:
        offset_h = float(header[8]) if len(header) > 8 else 0.0
    except ValueError:
        offset_h = 0.0
    temp = pd.to_numeric(raw[6], errors="coerce")
    bad = temp.isna() | (temp >= 99.9)
    if bad.any():
        row = int(np.argmax(bad.to_numpy())) + 9
        raise InputError("dry-bulb temperature missing or not a number", path, f"row {row}")
    # EPW hours are hour-ending 1–24 in local standard time (fixed UTC offset, no DST).
    stamps = pd.to_datetime(
        dict(year=raw[0], month=raw[1], day=raw[2]), errors="coerce"
    ) + pd.to_timedelta(raw[3] - 1, unit="h")
    fixed = f"Etc/GMT{-int(offset_h):+d}" if offset_h == int(offset_h) else "UTC"
    index = pd.DatetimeIndex(stamps).tz_localize(fixed).tz_convert(tz)
    return pd.Series(temp.to_numpy(dtype=float), index=index, name="t_out")
