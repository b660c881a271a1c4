"""The fitted parameters of the night model by name: the seven of Table IV and the nuisance
terms, their units and search bounds (:mod:`.parameters` adds the torch side). No torch: reading
and checking a NIGHTS file (:mod:`impctl.fit.nights.data`) needs the bounds, and a file refused
there is refused before torch is loaded."""

from __future__ import annotations

from ...model.house import H_MS, TABLE_IV, am_factor
from ...model.house_limits import PARAMETER_UNITS

#: The seven fitted parameters (the paper's Table IV), in this order everywhere.
PARAM_NAMES = TABLE_IV

PARAM_UNITS = {name: PARAMETER_UNITS[name] for name in TABLE_IV}

#: Parameters bounded by the classifiers' ranges; the others by :data:`PHYSICAL_BOUNDS`.
CLASSIFIED = ("floor_area", "c_f", "u_walls")

#: Search bounds. The three classified ones are the union of the paper's Table III classes and
#: apply only when no class range is given; the rest are wide physical limits for dwellings.
PHYSICAL_BOUNDS: dict[str, tuple[float, float]] = {
    "floor_area": (60.0, 300.0),
    "wall_height": (2.0, 6.0),
    "walls_area": (20.0, 600.0),
    "windows_area": (2.0, 150.0),
    "c_f": (0.8, 3.7),
    "u_walls": (0.2, 2.0),
    "u_windows": (0.5, 5.0),
}

#: Nuisance terms of the night model a real house needs (real-houses.md §2, §4, §7), fitted
#: after the seven (a row of parameters then has 10 entries): a constant internal gain over
#: the campaign (sleepers, base load) [W], split over the air, surface and mass nodes as ISO
#: 13790 C.1–C.3 splits Φ_int (:func:`impctl.fit.ode.node._gain_split`), and on constrained
#: nights the heat the emitter (and the air/furniture) still releases after the fit start,
#: emitter_w·exp(−t/emitter_tau_h) [W, h]. Bounded, reported, never the product's numbers.
#: The last, furniture_j_per_m2k, is heat capacity at the air node (air and furniture, per m²
#: of floor, real-houses.md §1: 3 + 10–31 kJ/(m²K)), charged through the furniture's coupling
#: time constant :data:`FURNITURE_TAU_S`: its heat flow C_fur·dT_fur/dt is computed from the
#: measured T_air (the data, not the state, drive it: a second state is not needed for a node
#: that follows T_air within an hour). It is part of the house's capacity: the reported C_m and
#: τ include it (:func:`lumped`).
#: The last, emitter_share, is the share of C_m that sits in the emitter (screed, radiator
#: water and metal, buffer) between the heat meter and the air node, with the time constant
#: emitter_tau_h (``NightFit(emitter_lag=True)``, :func:`build_rows`); the mass node keeps
#: the rest, so C_m and τ stay the house's whole (as the classes and the plant define them).
NUISANCE_NAMES = ("night_gain_w", "emitter_w", "emitter_tau_h", "furniture_j_per_m2k",
                  "emitter_share")

#: When no gain is fitted (``night_gain`` off, or not kept by the likelihood-ratio test) the
#: night_gain_w column is pinned to an assumed value (``NightFit(night_gain_w=…)``, default
#: :data:`impctl.imp.gain.NIGHT_GAIN_W`) by the box (g, g), not to 0 W.
NUISANCE_BOUNDS: dict[str, tuple[float, float]] = {
    # sleepers and base load, ≈ 150–400 W (real-houses.md §4). Not wide enough to absorb the
    # intercept sensor offsets make (HLC·(offset_in − offset_out)): with that much freedom the
    # gain trades against the emitter's release and the HLC (README "Accuracy")
    "night_gain_w": (0.0, 500.0),
    "emitter_w": (0.0, 4000.0),
    "emitter_tau_h": (0.2, 8.0),
    "furniture_j_per_m2k": (0.0, 40000.0),
    # screed 130–250 kJ/(m²K) of heated floor (real-houses.md §2): up to about half of C_m
    "emitter_share": (0.0, 0.6),
}

#: Furniture–air time constant [s]: 1/0.00022 s ≈ 76 min (real-houses.md §1, the Japanese
#: residential code's G_fur = 0.00022·C_fur).
FURNITURE_TAU_S = 1.0 / 0.00022

FUR_COLUMN = len(PARAM_NAMES) + 3   # column of furniture_j_per_m2k in a parameter row

EMC_COLUMN = len(PARAM_NAMES) + 4   # column of emitter_share


def eq63_margin(bounds: dict[str, tuple[float, float]]) -> float:
    """min over the box of H_tr,ms − H_tr,op [W/K]; eq. 63 needs it > 0 everywhere."""
    a_lo = bounds["floor_area"][0]
    h_ms = H_MS * float(am_factor(bounds["c_f"][0])) * a_lo
    return h_ms - bounds["u_walls"][1] * bounds["walls_area"][1]
