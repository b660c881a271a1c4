"""The realistic plant's groups of realism, each at its ideal limit: the error budgets'
ablation (``bench/fit_budget.py`` for the IMP fit, ``bench/season.py --ideal`` for the season
model).

Each group is either as :func:`impctl.population.realism.sample_params` drew it for the house or
at its ideal limit (:func:`ablate`). ``gains`` is the IMP budget's: its bench switches the gains
off itself (the plant still draws them, so the noise stays the same). The season's budget splits
them: ``drift`` (the slow random walk on the internal gains → none; the night and day levels
stay) and ``solar`` (the sun → none).
"""

from __future__ import annotations

from impctl.plant.params import CONTROL_IDEAL, RADIATORS, PlantParams

#: Groups of realism and what each is when on; order = the tables' order.
GROUPS = {
    "meter_gain": "heat-meter gain error ±5 %",
    "offsets": "sensor offsets T_air ±1 K, T_out ±2 K",
    "gains": "internal + solar gains",
    "noise": "room and outdoor sensor noise",
    "sensors": "T_air quantisation and lag; meter noise, positive-only meter (the season: "
               "flow and return sensors' offsets and lag, the flow's wander)",
    "air": "air + furniture capacity",
    "emitter": "emitter capacity (radiators, screed, buffer)",
    "control": "heat-pump control, cycling, modulation limits",
    "defrost": "heat-pump defrosts",
}
#: The season budget's split of ``gains`` (module docstring).
GAIN_PARTS = {
    "drift": "the internal gains' slow random walk (0–80 W per √h)",
    "solar": "solar gains",
}


def ablate(full: PlantParams, off: set[str]) -> tuple[PlantParams, bool]:
    """(realism options, gains on) with the groups in ``off`` (:data:`GROUPS`,
    :data:`GAIN_PARTS`) at their ideal limit."""
    p = full
    if "meter_gain" in off:
        p = p.with_section("sensors", meter_gain_error=0.0)
    if "offsets" in off:
        p = p.with_section("sensors", t_air_offset_k=0.0, t_out_offset_k=0.0)
    if "noise" in off:
        p = p.with_section("sensors", t_air_noise_k=0.0, t_out_noise_k=0.0)
    if "sensors" in off:
        p = p.with_section("sensors", t_air_quantum_k=0.0, t_air_lag_s=0.0, meter_noise=0.0,
                           meter_positive_only=0)
    if "air" in off:
        p = p.with_section("capacities", air_j_per_m3k=0.0, furniture_j_per_m2k=0.0)
    if "emitter" in off:
        p = p.with_section("emitter", kind=RADIATORS, radiator_j_per_k_per_w=0.0,
                           buffer_l_per_kw=0.0)
    if "control" in off:
        p = p.with_section("heat_pump", control=CONTROL_IDEAL)
    if "defrost" in off:
        p = p.with_section("heat_pump", defrost=0)
    if "drift" in off:
        p = p.with_section("gains", drift_w=0.0)
    if "solar" in off:
        p = p.with_section("gains", solar_peak_w=0.0)
    return p, "gains" not in off
