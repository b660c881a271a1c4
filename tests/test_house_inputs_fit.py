"""From the store to the fit: the house's own sensors stored beside the samples (as the
daemon stores them) → ``impctl export`` → ``impctl fit`` in subprocesses, which says the night
gain was measured. Needs the fit's measured-gain path (NIGHTS ``p_house_w``, ``occupants``).
"""

from __future__ import annotations

import json
from datetime import timedelta

import pytest
from cli_fixtures import run_impctl
from daemon_fixtures import write_config

from impctl.model import default_house
from impctl.population.imp_run.synth import synth_nights
from impctl.store import Sample, Store
from impctl.store.recording.house_inputs import HouseInputRow


def _export_and_fit(tmp_path, add_rows):
    """Store three simulated nights as the daemon stores them — ``add_rows(store, night_id,
    night, k, ts)`` adds sample ``k`` and whatever goes beside it — then ``impctl export`` and
    ``impctl fit`` in subprocesses: (the fit's JSON, its stdout, the exported CSV's text)."""
    state = tmp_path / "state"
    config = write_config(tmp_path / "config.toml", {
        "state_dir": str(state), "heatpump": {"host": "127.0.0.1"}})
    nights = synth_nights(default_house(), seed=3, n_constrained=1, n_normal=2)
    with Store(state / "impctl.db") as store:
        for night in nights:
            start = night.start.to_pydatetime()
            end = start + timedelta(seconds=float(night.time_s[-1]) + 60)
            nid = store.create_night(night.kind, night.setpoint_c, start, end)
            store.assess_night(nid, True, [])
            for k, t_s in enumerate(night.time_s):
                add_rows(store, nid, night, k, start + timedelta(seconds=float(t_s)))
    out = tmp_path / "nights.csv"
    done = run_impctl("export", "--config", str(config), "--out", str(out))
    assert done.returncode == 0, done.stderr
    fitted = run_impctl("fit", "--nights", str(out), "--json", str(tmp_path / "fit.json"))
    assert fitted.returncode == 0, fitted.stderr
    return json.loads((tmp_path / "fit.json").read_text()), fitted.stdout, out.read_text()


def test_exported_house_power_is_the_fits_measured_gain(tmp_path):
    def add_rows(store, nid, night, k, ts):
        store.add_sample(Sample(nid, ts, t_air_c=float(night.t_air_c[k]),
                                t_out_c=float(night.t_out_c[k]), q_hc_w=float(night.q_hc_w[k])))
        store.add_house_inputs(HouseInputRow(nid, ts, house_power_w=180.0, p_house_w=180.0,
                                             occupants=2.0))

    result, _, _ = _export_and_fit(tmp_path, add_rows)
    gain = result["fit"]["night_gain"]
    assert gain["source"] == "measured", gain
    # 180 W of household electricity (its indoor share) and two sleepers, night by night.
    assert 180.0 < gain["value_w"] < 180.0 + 2 * 100.0, gain


@pytest.mark.parametrize("reading_w", [-1200.0, 0.0])
def test_a_logged_defrost_goes_from_store_to_fit_and_an_unread_draw_is_said(tmp_path,
                                                                              reading_w):
    """The heat pump flags its defrosts (register 2011, stored with each sample). A signed
    reading (−1200 W) goes through the export into the fit, which takes the file and keeps
    the nights; a reading that stays at 0 W did not read the heat the defrost drew, and the
    fit says that its heat, HLC and C_m read high."""
    def add_rows(store, nid, night, k, ts):
        defrost = night.kind == "normal" and k in (20, 21)
        store.add_sample(Sample(nid, ts, t_air_c=float(night.t_air_c[k]),
                                t_out_c=float(night.t_out_c[k]),
                                q_hc_w=reading_w if defrost else float(night.q_hc_w[k]),
                                defrost=defrost))

    result, stdout, exported = _export_and_fit(tmp_path, add_rows)
    assert "defrost" in exported.splitlines()[0]
    held = [q for q in result["night_quality"] if q["kind"] == "normal"]
    assert len(held) == 2 and all(q["used"] for q in held)
    check = result["cross_checks"]["defrost"]
    assert check["nights"] == 2 and check["defrost_h"] > 0
    if reading_w < 0:
        assert check["unread_h"] == 0 and not check["flagged"] and "statement" not in check
        assert "read high" not in stdout
    else:
        assert check["unread_h"] == check["defrost_h"] and check["flagged"]
        assert "read high" in check["statement"] and "read high" in stdout
