"""Drivers tables (DRIVERS.csv) → a 5R1C run → the OUT.csv table, for ``impctl simulate``.

Temperatures °C, powers W, time steps s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .atomic import replacing
from .errors import InputError
from .imp.tables import read_table, step_seconds
from .model import HouseParameters, simulate
from .numtext import non_ascii_problem, parse_int

_NUMERIC = ("t_out", "setpoint", "phi_hc", "internal_gains", "solar_gains")
_MAY_BE_EMPTY = ("setpoint", "phi_hc")
#: Plausible temperatures; outside them the file is refused (a sensor sentinel such as −600,
#: tenths of a degree, Fahrenheit) — as for NIGHTS.csv.
PLAUSIBLE_C = {"t_out": (-60.0, 60.0), "setpoint": (5.0, 35.0)}
#: Plausible powers [W]: a dwelling's heating (as NIGHTS.csv q_hc) and its gains; a negative
#: power (cooling) or one in mW or kW of a wrong column is refused.
PLAUSIBLE_W = {"phi_hc": (0.0, 100_000.0), "internal_gains": (0.0, 50_000.0),
               "solar_gains": (0.0, 100_000.0)}


@dataclass(frozen=True)
class Window:
    """A daily local-time window [start, end) in minutes after midnight; may cross midnight."""

    start_min: int
    end_min: int

    def contains(self, index: pd.DatetimeIndex) -> np.ndarray:
        minute = (index.hour * 60 + index.minute).to_numpy()
        if self.start_min <= self.end_min:
            return (minute >= self.start_min) & (minute < self.end_min)
        return (minute >= self.start_min) | (minute < self.end_min)


def parse_window(text: str) -> Window:
    try:
        a, b = text.split("-")
        parts = [tuple(parse_int(x) for x in t.strip().split(":")) for t in (a, b)]
        if any(len(p) != 2 or not (0 <= p[0] < 24 and 0 <= p[1] < 60) for p in parts):
            raise ValueError
    except ValueError:
        raise InputError(non_ascii_problem(text) or f"expected HH:MM-HH:MM, got {text!r}",
                         place="--heating-off") from None
    (h1, m1), (h2, m2) = parts
    return Window(h1 * 60 + m1, h2 * 60 + m2)


def read_drivers(path: Path, step: float | None, tz: str) -> tuple[pd.DataFrame, float]:
    table = read_table(
        path, required=("timestamp", "t_out"), numeric=_NUMERIC, may_be_empty=_MAY_BE_EMPTY,
        tz=tz,
    )
    limits = {**{c: (lo, hi, "°C") for c, (lo, hi) in PLAUSIBLE_C.items()},
              **{c: (lo, hi, "W") for c, (lo, hi) in PLAUSIBLE_W.items()}}
    for col, (lo, hi, unit) in limits.items():
        values = table[col].to_numpy(dtype=float) if col in table else np.array([])
        bad = np.isfinite(values) & ((values < lo) | (values > hi))
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(f"column '{col}': {values[i]:g} is outside {lo:g}…{hi:g} {unit}",
                             path, f"row {i + 2}")
    data_step = step_seconds(table["timestamp"], path)
    if step is not None and data_step is not None and step != data_step:
        raise InputError(
            f"--step {step:g} s differs from the data's step {data_step:g} s", path, "row 3"
        )
    dt_s = step if step is not None else data_step
    if dt_s is None:
        raise InputError("one row only: give the time step with --step", path)
    return table, dt_s


def write_atomically(df: pd.DataFrame, out: Path) -> None:
    """Write to a temporary file beside ``out`` and rename, so no half file is left behind."""
    out.parent.mkdir(parents=True, exist_ok=True)
    with replacing(out, mode=0o600) as tmp, open(tmp, "w", newline="") as fh:
        df.to_csv(fh, index=False, float_format="%.4f")


def run_drivers(
    house: HouseParameters,
    table: pd.DataFrame,
    dt_s: float,
    setpoint_c: float | None,
    heating_off: Window | None,
    t_m_init_c: float | None,
) -> pd.DataFrame:
    """Simulate one house over a drivers table; returns the OUT.csv frame (°C, W)."""
    index = pd.DatetimeIndex(table["timestamp"])
    n = len(table)
    if "setpoint" in table:
        sp = table["setpoint"].to_numpy(dtype=float)
    else:
        sp = np.full(n, np.nan if setpoint_c is None else float(setpoint_c))
        if heating_off is not None:
            sp[heating_off.contains(index)] = np.nan
    forced = table["phi_hc"].to_numpy(dtype=float) if "phi_hc" in table else None
    if t_m_init_c is None:
        finite = sp[np.isfinite(sp)]
        t_m_init_c = float(finite[0]) if finite.size else 20.0
    sim = simulate(
        house,
        table["t_out"].to_numpy(dtype=float),
        dt_s,
        setpoint_c=sp,
        phi_hc_w=forced,
        internal_gains_w=table["internal_gains"].to_numpy() if "internal_gains" in table else 0.0,
        solar_gains_w=table["solar_gains"].to_numpy() if "solar_gains" in table else 0.0,
        t_m_init_c=t_m_init_c,
    )
    return pd.DataFrame(
        {
            "timestamp": [t.isoformat() for t in index],
            "t_out": table["t_out"].to_numpy(),
            "t_air": sim.t_air_c,
            "t_s": sim.t_s_c,
            "t_m": sim.t_m_c,
            "phi_hc": sim.phi_hc_w,
        }
    )


def summary(house: HouseParameters, out: pd.DataFrame, dt_s: float, label: str) -> str:
    energy_kwh = float(out["phi_hc"].sum()) * dt_s / 3.6e6
    rows = [
        ("house", label, ""),
        ("steps", f"{len(out)} × {dt_s:g}", "s"),
        ("HLC", f"{float(house.hlc_w_per_k):.1f}", "W/K"),
        ("C_m", f"{float(house.c_m_j_per_k) / 1e6:.2f}", "MJ/K"),
        ("tau", f"{float(house.tau_h):.1f}", "h"),
        ("mean t_out", f"{out['t_out'].mean():.2f}", "°C"),
        ("mean heating power", f"{out['phi_hc'].mean():.0f}", "W"),
        ("heat delivered", f"{energy_kwh:.1f}", "kWh"),
        ("min t_air", f"{out['t_air'].min():.2f}", "°C"),
        ("max t_air", f"{out['t_air'].max():.2f}", "°C"),
    ]
    width = max(len(r[0]) for r in rows)
    return "\n".join(f"{k:<{width}}  {v:>14} {u}" for k, v, u in rows)
