"""Pictures people look at: the nights figure as a grid with a legend and power axes from
0 kW, and the report's opening for the household — heat loss in kW at everyday outdoor
temperatures and the comfort cost of the experiment, computed from a real fit and a real
store file.
"""

from __future__ import annotations

import html
import re
from datetime import timedelta

import numpy as np
import pytest

from impctl.model import HouseParameters
from impctl.population.imp_run.synth import synth_nights
from impctl.report import write_report
from impctl.store import Sample, Store

HOUSE = HouseParameters(floor_area=120.0, wall_height=2.7, walls_area=160.0, windows_area=25.0,
                        c_f=2.2, u_walls=0.5, u_windows=1.3, ach_vent=0.0, ach_infl=0.01)


@pytest.mark.parametrize("n", [1, 2, 4, 5, 8, 9, 27, 60])
def test_the_grid_wraps_at_four_columns(n):
    from impctl.fit.result.plot import MAX_COLUMNS, grid_shape

    rows, cols = grid_shape(n)
    assert cols <= MAX_COLUMNS and rows * cols >= n and rows * cols - n < cols
    assert (rows, cols) == ((1, n) if n <= MAX_COLUMNS else (-(-n // 4), 4))


def _pred(i: int, kind: str) -> dict:
    t = np.arange(0, 7 * 3600 + 1, 600.0)
    if kind == "normal":
        return {"night_id": f"n{i}", "kind": kind, "time_s": t, "t_air_model_c": None,
                "t_air_measured_c": np.full(t.size, 22.0),
                "q_measured_w": 2200 + 100 * np.sin(t / 3600), "q_model_w": np.full(t.size, 2250.0)}
    return {"night_id": f"c{i}", "kind": kind, "time_s": t,
            "t_air_measured_c": 23.5 - t / 3600 * 0.6, "t_air_model_c": 23.5 - t / 3600 * 0.58}


def test_27_nights_make_a_readable_grid_with_a_legend_and_honest_axes():
    from impctl.fit.result.plot import draw_nights

    preds = [_pred(i, "normal" if i % 3 else "constrained") for i in range(27)]
    fig = draw_nights(preds, "title", dpi=110)
    width_px, height_px = fig.get_size_inches() * fig.dpi
    assert width_px <= 1500 and height_px < 3000     # was 7,722 px wide in one row
    drawn = [ax for ax in fig.axes if ax.axison]
    assert len(drawn) == 27
    power = [ax for ax in drawn if ax.get_ylabel() == "heat power [kW]"]
    assert len(power) == 18 and all(ax.get_ylim()[0] == 0.0 for ax in power)
    assert len({ax.get_ylim() for ax in power}) == 1   # one scale: nights compare
    labels = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    assert labels == ["measured", "T_air fitted (constrained night)",
                      "heat power predicted (normal night, T_air held)"]


# -- the household's summary -------------------------------------------------------------------
@pytest.fixture(scope="module")
def fitted():
    from impctl.fit.estimator import NightFit
    from impctl.fit.result.report import fit_to_dict

    nights = synth_nights(HOUSE, seed=11, sample_step_s=900.0, n_normal=3)
    estimator = NightFit().fit(nights)
    return nights, fit_to_dict(estimator)


def _store(tmp_path, nights):
    """A real store holding the nights, as the daemon would have recorded them."""
    db = tmp_path / "impctl.db"
    with Store(db) as store:
        for n in nights:
            sp = 21.0 if n.kind == "constrained" else float(n.setpoint_c)
            start = n.start.to_pydatetime()
            nid = store.create_night(n.kind, sp, start, start + timedelta(hours=7),
                                     t_min_c=sp - 2.5 if n.kind == "constrained" else None)
            store.set_night_state(nid, "done")
            for t, t_air in zip(n.time_s, n.t_air_c, strict=True):
                store.add_sample(Sample(nid, start + timedelta(seconds=float(t)),
                                        t_air_c=float(t_air)))
    return db


def _hours_below(nights, threshold) -> float:
    total = 0.0
    for n in nights:
        if n.kind != "constrained":
            continue
        t = np.asarray(n.time_s, float)
        below = np.asarray(n.t_air_c, float)[:-1] < threshold(n)
        total += float(np.sum(np.diff(t)[below])) / 3600.0
    return total


def test_the_report_opens_with_the_household_summary(tmp_path, fitted):
    from impctl.report.household import COOL_C

    nights, fit = fitted
    page = write_report(_store(tmp_path, nights), tmp_path / "rep", fit=fit).read_text()
    text = html.unescape(re.sub(r"<[^>]+>", "", page))
    hlc = fit["lumped"]["hlc"]["value"]
    # what was learnt, before the engineer's tables
    assert page.index("In short: what the nights found out") < page.index(
        "What the nights determine")
    assert f"Your house loses an estimated {hlc:.0f} W per degree" in text
    for t_out in (-10, 0, 7):
        assert f"{t_out:g} °C{hlc * (21 - t_out) / 1e3:.1f} kW".replace("-", "−") in text
    # the comfort cost, from the stored samples
    cons = [n for n in nights if n.kind == "constrained"]
    coldest = min(float(np.min(n.t_air_c)) for n in cons)
    assert f"coldest {coldest:.1f} °C" in text
    below_sp = _hours_below(nights, lambda n: 21.0)
    below_cool = _hours_below(nights, lambda n: COOL_C)
    assert f"spent {below_sp:.1f} h below the night's setpoint (21 °C)" in text
    assert f"{below_cool:.1f} h below 19 °C" in text
    assert below_sp > 0


def test_heat_loss_rows_carry_the_interval():
    from impctl.report.household import heat_loss_rows

    rows = heat_loss_rows({"value": 106.0, "low": 100.0, "high": 112.0})
    assert [round(r["loss_w"]) for r in rows] == [3286, 2226, 1484]
    assert rows[0]["low_w"] == pytest.approx(3100.0) and rows[0]["high_w"] == pytest.approx(3472.0)


# -- what a class probability is ---------------------------------------------------------------
@pytest.mark.parametrize("calibrated, words", [(True, "calibrated"),
                                               (False, "forest vote share"),
                                               (None, "calibration not recorded")])
def test_the_classes_figure_says_what_the_probability_is(fitted, calibrated, words):
    import matplotlib.pyplot as plt

    from impctl.fit.result.table import format_table
    from impctl.report.figures import class_figure

    _, fit = fitted
    classes = {name: {**c, "probability": 0.8, "calibrated": calibrated, "source": "classifier"}
               for name, c in fit["classes"].items()}
    fig = class_figure({**fit, "classes": classes})
    ax = fig.axes[0]
    assert ax.get_xlabel() == f"probability of the chosen range ({words})"
    assert [t.get_text() for t in ax.texts] == [f"0.80 {words}"] * len(classes)
    plt.close(fig)
    table = format_table({**fit, "classes": classes})
    assert table.count(f"p = 0.80 ({words})") == len(classes)


def _curve_json() -> dict:
    t = np.arange(-15.0, 15.5, 0.5)
    return {"schema": "impctl-curve/1", "setpoint_c": {"value": 21.0, "source": "given"},
            "margin_k": 1.0, "confidence": 0.95,
            "need": {"t_out_c": t.tolist(), "flow_c": (34.0 - 0.6 * t).tolist(),
                     "flow_upper_c": (35.0 - 0.62 * t).tolist()},
            "recommended": {"t_out_c": [-15.0, 15.0], "flow_c": [45.5, 27.0],
                            "flow_at_0_c": 36.2},
            "running": {"t_out_c": [-15.0, 15.0], "flow_c": [52.0, 30.0], "flow_at_0_c": 41.0,
                        "source": "target", "t_out_range_c": [-6.0, 8.0]},
            "advice": "Your heating runs its water 5 K hotter than this house needs at 0 °C "
                      "outside. Setting the heating curve to 46 °C at −15 °C outside and 27 °C "
                      "at +15 °C keeps the rooms at 21.0 °C with 1 K to spare and would save "
                      "about 310 kWh of electricity.",
            "notes": ["the saving is over an ASSUMED winter"]}


def test_the_report_says_what_heating_curve_to_set(tmp_path, fitted):
    """With a heating curve kept beside the store, the report opens with it in plain words:
    the advice, the suggested and the running flow at everyday outdoor temperatures, the
    figure; a kept file that is no curve result costs the section, not the report."""
    import json

    nights, fit = fitted
    db = _store(tmp_path, nights)
    (db.parent / "curve.json").write_text(json.dumps(_curve_json()))
    page = write_report(db, tmp_path / "rep", fit=fit).read_text()
    text = html.unescape(re.sub(r"<[^>]+>", "", page))
    assert page.index("Your heating curve") < page.index("What the nights determine")
    assert "Your heating runs its water 5 K hotter than this house needs" in text
    assert "−15 °C46 °C52 °C" in text
    assert "0 °C36 °C41 °C" in text
    assert (tmp_path / "rep" / "fig_curve.png").read_bytes()[:4] == b"\x89PNG"
    (db.parent / "curve.json").write_text("[]")
    page = write_report(db, tmp_path / "rep2", fit=fit).read_text()
    assert "Your heating curve" not in page and "What the nights determine" in page
