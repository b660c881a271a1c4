"""The virtual population: households drawn from a documented, physically plausible prior.

Independent draws (uniform unless said otherwise):

* ``floor_area`` A_f [m²] over the hull of its classifier ranges (default 60–300);
* ``c_f`` [1e5 J/(m²K)] over its ranges' hull (default 0.8–3.7, ISO 13790 very light … very heavy);
* ``u_walls`` [W/(m²K)] over its ranges' hull (default 0.2–2.0: insulated … solid brick);
* ``u_windows`` [W/(m²K)] 0.8–3.5 (triple glazing … old double glazing);
* the geometry below.

Geometry — the walls follow from the floor area instead of being drawn on their own:

* storeys: 1 or 2, with P(2 storeys) rising linearly from 0.2 at the smallest to 0.8 at the
  largest floor area of the population (bungalows are small, large houses have two floors);
* storey height ``wall_height`` [m] 2.5–3.0 (the model's volume is A_f · wall_height);
* a rectangular footprint A_f / storeys [m²] with aspect ratio length/width 1.0–2.0, so the
  perimeter is P = 2·(w + l) with w = √(footprint/aspect), l = aspect·w;
* gross facade = P · storeys · wall_height [m²]; a window-to-wall ratio 0.10–0.30 of it is
  ``windows_area``, the rest is the opaque ``walls_area``. As in the paper's Table I only the
  facade is envelope: roof and ground-floor losses are not modelled separately.

Ventilation as in the paper: ``ach_vent`` = 0, ``ach_infl`` = 0.01 1/h (configurable). No heating
power limit (ideal heating: every normal night holds its setpoint). A 150 m² two-storey house
with storey height 2.7 m, aspect 1.5 and 20 % windows gets 153 m² of walls and 38 m² of windows;
the paper's case-study house (250 m²) had 263 m² and 66 m².
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np
import pandas as pd

from ..model import HouseParameters
from .ranges import DEFAULT_RANGES, Ranges, hull, validate_ranges

Interval = tuple[float, float]


@dataclass(frozen=True)
class PopulationConfig:
    """Prior of the virtual population (see the module docstring); bounds are (low, high).

    Parameters
    ----------
    floor_area_m2, c_f, u_walls, u_windows : (float, float)
        Uniform bounds [m²], [1e5 J/(m²K)], [W/(m²K)], [W/(m²K)].
    wall_height_m : (float, float)
        Storey height bounds [m].
    aspect_ratio : (float, float)
        Footprint length/width bounds [-].
    window_wall_ratio : (float, float)
        Share of the gross facade that is windows [-].
    two_storey_probability : (float, float)
        P(2 storeys) at the smallest and at the largest floor area [-].
    ach_vent, ach_infl : float
        Air changes per hour [1/h].
    """

    floor_area_m2: Interval = (60.0, 300.0)
    c_f: Interval = (0.8, 3.7)
    u_walls: Interval = (0.2, 2.0)
    u_windows: Interval = (0.8, 3.5)
    wall_height_m: Interval = (2.5, 3.0)
    aspect_ratio: Interval = (1.0, 2.0)
    window_wall_ratio: Interval = (0.10, 0.30)
    two_storey_probability: Interval = (0.2, 0.8)
    ach_vent: float = 0.0
    ach_infl: float = 0.01

    @classmethod
    def for_ranges(cls, ranges: Ranges = DEFAULT_RANGES, **overrides) -> PopulationConfig:
        """A configuration whose classified parameters span the hull of their ranges."""
        ranges = validate_ranges(ranges)
        keys = {"floor_area": "floor_area_m2", "c_f": "c_f", "u_walls": "u_walls",
                "u_windows": "u_windows", "wall_height": "wall_height_m"}
        values = {keys[name]: hull(rs) for name, rs in ranges.items()}
        values.update(overrides)
        return replace(cls(), **values)

    def as_dict(self) -> dict:
        """Plain-JSON form for manifests."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


def sample_population(n: int, seed: int = 0, config: PopulationConfig | None = None
                      ) -> pd.DataFrame:
    """Draw ``n`` households: their Table I parameters and the geometry behind them.

    Parameters
    ----------
    n : int
        Number of households (> 0).
    seed : int
        Random seed; the same (n, seed, config) gives the same households.
    config : PopulationConfig, optional

    Returns
    -------
    DataFrame
        One row per household: ``floor_area`` [m²], ``wall_height`` [m], ``walls_area`` [m²],
        ``windows_area`` [m²], ``c_f`` [1e5 J/(m²K)], ``u_walls``, ``u_windows`` [W/(m²K)],
        ``ach_vent``, ``ach_infl`` [1/h], and ``storeys``, ``aspect_ratio``,
        ``window_wall_ratio`` [-], ``hlc_w_per_k`` [W/K], ``c_m_j_per_k`` [J/K], ``tau_h`` [h].
    """
    if n < 1:
        raise ValueError("n must be >= 1")
    cfg = config or PopulationConfig()
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5EED]))

    def uniform(bounds: Interval) -> np.ndarray:
        return rng.uniform(bounds[0], bounds[1], n)

    floor_area = uniform(cfg.floor_area_m2)
    c_f = uniform(cfg.c_f)
    u_walls = uniform(cfg.u_walls)
    u_windows = uniform(cfg.u_windows)
    height = uniform(cfg.wall_height_m)
    aspect = uniform(cfg.aspect_ratio)
    wwr = uniform(cfg.window_wall_ratio)
    lo, hi = cfg.floor_area_m2
    share = (floor_area - lo) / (hi - lo) if hi > lo else np.full(n, 0.5)
    p_two = cfg.two_storey_probability[0] + share * np.diff(cfg.two_storey_probability)[0]
    storeys = np.where(rng.uniform(size=n) < p_two, 2, 1)
    width = np.sqrt(floor_area / storeys / aspect)
    perimeter = 2.0 * (width + aspect * width)
    facade = perimeter * storeys * height
    table = pd.DataFrame({
        "floor_area": floor_area,
        "wall_height": height,
        "walls_area": facade * (1.0 - wwr),
        "windows_area": facade * wwr,
        "c_f": c_f,
        "u_walls": u_walls,
        "u_windows": u_windows,
        "ach_vent": np.full(n, float(cfg.ach_vent)),
        "ach_infl": np.full(n, float(cfg.ach_infl)),
        "storeys": storeys,
        "aspect_ratio": aspect,
        "window_wall_ratio": wwr,
    })
    houses = households_from_table(table)
    table["hlc_w_per_k"] = houses.hlc_w_per_k
    table["c_m_j_per_k"] = houses.c_m_j_per_k
    table["tau_h"] = houses.tau_h
    return table


_HOUSE_COLUMNS = ("floor_area", "wall_height", "walls_area", "windows_area", "c_f", "u_walls",
                  "u_windows", "ach_vent", "ach_infl")


def households_from_table(table: pd.DataFrame) -> HouseParameters:
    """The houses of a population table as one array-valued :class:`HouseParameters`."""
    return HouseParameters(**{c: table[c].to_numpy(dtype=float) for c in _HOUSE_COLUMNS})


def sample_households(n: int, seed: int = 0, config: PopulationConfig | None = None
                      ) -> HouseParameters:
    """Draw ``n`` households (see :func:`sample_population`) as array-valued HouseParameters.

    A seed the classifiers were not trained with gives households they never saw.
    """
    return households_from_table(sample_population(n, seed, config))
