"""House parameters (the paper's Table I) and the ISO 13790 quantities derived from them.

Every derived quantity is a small function of plain arithmetic, so the same code serves a float, a
NumPy array over houses and a torch tensor in the fit. Units: areas m², lengths m, c_f in
1e5 J/(m²K) (the paper's unit), U-values W/(m²K), air changes 1/h, conductances W/K, heat
capacity J/K, time constants h.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, fields
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from .house_limits import HouseFileError

#: Λ_at, ratio of internal surface area to floor area (ISO 13790 §7.2.2.2).
LAMBDA_AT = 4.5
#: h_is, air-to-surface heat transfer coefficient, W/(m²K) (eq. 9).
H_IS = 3.45
#: h_ms, mass-to-surface heat transfer coefficient, W/(m²K) (eq. 64).
H_MS = 9.1
#: ρ_a·c_a, volumetric heat capacity of air, J/(m³K).
RHO_C_AIR = 1200.0
#: Table 12 mass classes: c_f [1e5 J/(m²K)] and the A_m factor [-].
MASS_CLASS_C_F = (0.8, 1.1, 1.65, 2.6, 3.7)
MASS_CLASS_AM_FACTOR = (2.5, 2.5, 2.5, 3.0, 3.5)


def _ramp(x: Any) -> Any:
    """clip(x, 0, 1) written with abs() so it works on floats, arrays and torch tensors."""
    relu = (x + abs(x)) / 2
    shifted = x - 1
    return relu - (shifted + abs(shifted)) / 2


def am_factor(c_f: Any) -> Any:
    """Effective mass area per floor area A_m/A_f [-] from ISO 13790 Table 12.

    Linear between the class points (c_f = 0.8, 1.1, 1.65, 2.6, 3.7 → 2.5, 2.5, 2.5, 3.0, 3.5),
    2.5 below the lightest class and 3.5 above the heaviest.

    Parameters
    ----------
    c_f : float, array or tensor
        Heat capacity per floor area [1e5 J/(m²K)].
    """
    return (
        2.5
        + 0.5 * _ramp((c_f - 1.65) / (2.6 - 1.65))
        + 0.5 * _ramp((c_f - 2.6) / (3.7 - 2.6))
    )


@dataclass(frozen=True)
class Conductances:
    """The 5R1C network of one house (or of many: each field then an array over houses).

    Attributes are in W/K except ``c_m_j_per_k`` [J/K], ``a_m_m2``, ``a_t_m2`` [m²] and
    ``floor_area_m2`` [m²].
    """

    # H_tr,1…3 are cached on first use: the fit's row coefficients read each of them dozens
    # of times per network (frozen, so they cannot go stale)
    h_ve: Any
    h_tr_is: Any
    h_tr_w: Any
    h_tr_ms: Any
    h_tr_em: Any
    h_tr_op: Any
    c_m_j_per_k: Any
    a_m_m2: Any
    a_t_m2: Any
    floor_area_m2: Any

    @cached_property
    def h_tr_1(self) -> Any:
        """H_tr,1 = 1/(1/H_ve + 1/H_tr,is) (C.6) [W/K], written to stay finite at H_ve = 0."""
        return self.h_ve * self.h_tr_is / (self.h_ve + self.h_tr_is)

    @cached_property
    def h_tr_2(self) -> Any:
        """H_tr,2 = H_tr,1 + H_tr,w (C.7) [W/K]."""
        return self.h_tr_1 + self.h_tr_w

    @cached_property
    def h_tr_3(self) -> Any:
        """H_tr,3 = 1/(1/H_tr,2 + 1/H_tr,ms) (C.8) [W/K]."""
        return self.h_tr_2 * self.h_tr_ms / (self.h_tr_2 + self.h_tr_ms)

    @property
    def hlc_w_per_k(self) -> Any:
        """Steady-state heat loss coefficient air node → outside [W/K].

        HLC = H_ve + 1/(1/H_tr,is + 1/(H_tr,w + H_tr,op)).
        """
        env = self.h_tr_w + self.h_tr_op
        return self.h_ve + self.h_tr_is * env / (self.h_tr_is + env)

    @property
    def tau_h(self) -> Any:
        """Time constant of the free-running house τ = C_m/(H_tr,em + H_tr,3) [h]."""
        return self.c_m_j_per_k / (self.h_tr_em + self.h_tr_3) / 3600.0


def conductances(
    floor_area: Any,
    wall_height: Any,
    walls_area: Any,
    windows_area: Any,
    c_f: Any,
    u_walls: Any,
    u_windows: Any,
    ach_vent: Any,
    ach_infl: Any,
    heat_recovery: Any = 0.0,
) -> Conductances:
    """Derive the 5R1C network literally per ISO 13790 from the Table I parameters.

    Works on floats, NumPy arrays (one entry per house) and torch tensors alike.

    Parameters
    ----------
    floor_area : m²
    wall_height : m
    walls_area : m², opaque external walls
    windows_area : m²
    c_f : 1e5 J/(m²K)
    u_walls, u_windows : W/(m²K)
    ach_vent, ach_infl : 1/h
    heat_recovery : 0–1, efficiency applied to ventilation air only

    Returns
    -------
    Conductances
    """
    a_t = LAMBDA_AT * floor_area
    a_m = am_factor(c_f) * floor_area
    h_tr_ms = H_MS * a_m
    h_tr_op = u_walls * walls_area
    # eq. 63: the series path em → ms then conducts exactly H_tr,op.
    h_tr_em = 1.0 / (1.0 / h_tr_op - 1.0 / h_tr_ms)
    volume = floor_area * wall_height
    h_ve = RHO_C_AIR * volume * (ach_vent * (1.0 - heat_recovery) + ach_infl) / 3600.0
    return Conductances(
        h_ve=h_ve,
        h_tr_is=H_IS * a_t,
        h_tr_w=u_windows * windows_area,
        h_tr_ms=h_tr_ms,
        h_tr_em=h_tr_em,
        h_tr_op=h_tr_op,
        c_m_j_per_k=c_f * 1e5 * floor_area,
        a_m_m2=a_m,
        a_t_m2=a_t,
        floor_area_m2=floor_area,
    )


#: The seven physical parameters the fit estimates (the paper's Table IV), in this order.
TABLE_IV = ("floor_area", "wall_height", "walls_area", "windows_area", "c_f", "u_walls",
            "u_windows")

_REQUIRED = (
    "floor_area",
    "wall_height",
    "walls_area",
    "windows_area",
    "c_f",
    "u_walls",
    "u_windows",
    "ach_vent",
    "ach_infl",
)
_OPTIONAL = {"heat_recovery": 0.0, "max_heating_power": math.inf}
_POSITIVE = ("floor_area", "wall_height", "walls_area", "windows_area", "u_walls", "u_windows")


@dataclass(frozen=True)
class HouseParameters:
    """A house's Table I parameters; each field a float, or an array over houses.

    Parameters
    ----------
    floor_area : float
        Conditioned floor area A_f [m²].
    wall_height : float
        Storey height [m]; volume V = floor_area · wall_height.
    walls_area : float
        Opaque external wall area [m²].
    windows_area : float
        Window area [m²].
    c_f : float
        Heat capacity per floor area [1e5 J/(m²K)], 0.5–5 (classes 0.8 … 3.7).
    u_walls, u_windows : float
        U-values [W/(m²K)].
    ach_vent, ach_infl : float
        Air changes through ventilation and infiltration [1/h]; their sum must be > 0.
    heat_recovery : float, default 0
        Ventilation heat-recovery efficiency [0–1].
    max_heating_power : float, default inf
        Cap on the heating power [W].

    Raises
    ------
    InputError
        When a value is out of its physical domain; ``place`` names the key.
    """

    floor_area: Any
    wall_height: Any
    walls_area: Any
    windows_area: Any
    c_f: Any
    u_walls: Any
    u_windows: Any
    ach_vent: Any
    ach_infl: Any
    heat_recovery: Any = 0.0
    max_heating_power: Any = math.inf

    def __post_init__(self) -> None:
        problems = self._domain_problems()
        if len(problems) == 1:
            raise problems[0]
        if problems:
            raise HouseFileError(problems)

    def _domain_problems(self) -> list[InputError]:
        """Every violated domain rule; the ISO checks of the derived network only when the
        single values are valid (the network needs them)."""
        problems = []
        for name in _POSITIVE:
            if not np.all(np.asarray(getattr(self, name)) > 0):
                problems.append(InputError("must be > 0", place=f"key '{name}'"))
        for name in ("ach_vent", "ach_infl"):
            if not np.all(np.asarray(getattr(self, name)) >= 0):
                problems.append(InputError("must be >= 0", place=f"key '{name}'"))
        c_f = np.asarray(self.c_f)
        if not np.all((c_f >= 0.5) & (c_f <= 5.0)):
            problems.append(InputError("must lie in 0.5–5 (1e5 J/(m²K))", place="key 'c_f'"))
        hr = np.asarray(self.heat_recovery)
        if not np.all((hr >= 0) & (hr <= 1)):
            problems.append(InputError("must lie in 0–1", place="key 'heat_recovery'"))
        if not np.all(np.asarray(self.max_heating_power) > 0):
            problems.append(InputError("must be > 0 W", place="key 'max_heating_power'"))
        if problems:
            return problems
        if not np.all(np.asarray(self.ach_vent) + np.asarray(self.ach_infl) > 0):
            problems.append(InputError(
                "ach_vent + ach_infl must be > 0 (the air node needs some air exchange)",
                place="key 'ach_infl'"))
        net = self.network
        if not np.all(np.asarray(net.h_tr_op) < np.asarray(net.h_tr_ms)):
            problems.append(InputError(
                "u_walls·walls_area must stay below H_tr,ms = 9.1·A_m (ISO 13790 eq. 63)",
                place="key 'u_walls'"))
        if not np.all(np.asarray(net.a_t_m2 - net.a_m_m2 - net.h_tr_w / H_MS) >= 0):
            problems.append(InputError(
                "u_windows·windows_area too large: A_t ≥ A_m + H_tr,w/9.1 fails (ISO C.3)",
                place="key 'windows_area'"))
        return problems

    @property
    def network(self) -> Conductances:
        """The derived 5R1C conductances and capacity (see :func:`conductances`)."""
        return conductances(
            self.floor_area,
            self.wall_height,
            self.walls_area,
            self.windows_area,
            self.c_f,
            self.u_walls,
            self.u_windows,
            self.ach_vent,
            self.ach_infl,
            self.heat_recovery,
        )

    @property
    def hlc_w_per_k(self) -> Any:
        """Steady-state heat loss coefficient [W/K]."""
        return self.network.hlc_w_per_k

    @property
    def c_m_j_per_k(self) -> Any:
        """Heat capacity of the mass node C_m [J/K]."""
        return self.network.c_m_j_per_k

    @property
    def tau_h(self) -> Any:
        """Time constant τ = C_m/(H_tr,em + H_tr,3) [h]."""
        return self.network.tau_h

    @property
    def n_houses(self) -> int | None:
        """Number of houses when the fields are arrays, ``None`` for a single house."""
        shapes = {np.shape(getattr(self, f.name)) for f in fields(self)}
        sizes = [int(np.prod(s)) for s in shapes if s != ()]
        return max(sizes) if sizes else None

    def as_dict(self) -> dict[str, Any]:
        """The parameters as a plain dict (the keys of the house TOML)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def stack(cls, houses: list[HouseParameters]) -> HouseParameters:
        """Many single houses → one object whose fields are arrays over houses."""
        if not houses:
            raise ValueError("stack() needs at least one house")
        return cls(
            **{
                f.name: np.array([float(getattr(h, f.name)) for h in houses])
                for f in fields(cls)
            }
        )

    def take(self, index: int) -> HouseParameters:
        """The ``index``-th house of an array-valued object, as floats."""
        return HouseParameters(
            **{
                k: float(np.broadcast_to(v, (self.n_houses or 1,))[index])
                for k, v in self.as_dict().items()
            }
        )


def house_from_mapping(data: dict[str, Any], source: str | Path | None = None) -> HouseParameters:
    """Validate a mapping with exactly the house-file keys and build the parameters.

    Every key is checked at once against :data:`~impctl.model.house_limits.HOUSE_LIMITS`
    (unknown, missing, not a number, implausible); then the ISO 13790 domain of the whole house.

    Raises
    ------
    InputError
        Naming ``source`` and the offending key; one line per problem.
    """
    from .house_limits import check_house_values

    # The optional [plant.*] tables belong to impctl.plant (impctl.plant.load_plant), not the 5R1C.
    envelope = {key: value for key, value in data.items() if key != "plant"}
    values = check_house_values(envelope, _REQUIRED + tuple(_OPTIONAL), _OPTIONAL, source)
    try:
        return HouseParameters(**values)
    except InputError as exc:
        raise exc.at(source) from None


def load_house(path: str | Path) -> HouseParameters:
    """Read a house TOML file (keys as :class:`HouseParameters`, units as documented there).

    Raises
    ------
    InputError
        Unreadable file, TOML syntax error, unknown/missing key, wrong type or bad value.
    """
    path = Path(path)
    return house_from_mapping(read_toml(path), path)


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; any failure is an :class:`InputError` naming the file."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid TOML: {exc}", path) from None


def default_house() -> HouseParameters:
    """The built-in default house: a 150 m² medium-weight single-family house."""
    from importlib.resources import files

    resource = files("impctl") / "data" / "default_house.toml"
    with resource.open("rb") as fh:
        return house_from_mapping(tomllib.load(fh), "default_house.toml")
