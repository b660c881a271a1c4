"""From the store to the fit: the house's own sensors stored beside the samples (as the
daemon stores them) → ``impctl export`` → ``impctl fit`` in subprocesses, which says the night
gain was measured. Needs the fit's measured-gain path (NIGHTS ``p_house_w``, ``occupants``).
"""

from __future__ import annotations

import json
from datetime import timedelta

from daemon_fixtures import run_cli, write_config

from impctl.model import default_house
from impctl.population.imp_run.synth import synth_nights
from impctl.store import Sample, Store
from impctl.store.house_inputs import HouseInputRow


def test_exported_house_power_is_the_fits_measured_gain(tmp_path):
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
                ts = start + timedelta(seconds=float(t_s))
                store.add_sample(Sample(nid, ts, t_air_c=float(night.t_air_c[k]),
                                        t_out_c=float(night.t_out_c[k]),
                                        q_hc_w=float(night.q_hc_w[k])))
                store.add_house_inputs(HouseInputRow(nid, ts, house_power_w=180.0,
                                                     p_house_w=180.0, occupants=2.0))
    out = tmp_path / "nights.csv"
    done = run_cli("export", "--config", str(config), "--out", str(out))
    assert done.returncode == 0, done.stderr
    fitted = run_cli("fit", "--nights", str(out), "--json", str(tmp_path / "fit.json"),
                     timeout_s=300)
    assert fitted.returncode == 0, fitted.stderr
    gain = json.loads((tmp_path / "fit.json").read_text())["fit"]["night_gain"]
    assert gain["source"] == "measured", gain
    # 180 W of household electricity (its indoor share) and two sleepers, night by night.
    assert 180.0 < gain["value_w"] < 180.0 + 2 * 100.0, gain


def test_a_night_with_a_defrost_on_a_signed_reading_goes_from_store_to_fit(tmp_path):
    """The heat pump reports negative heat while it defrosts (flagged, as the gateway stores
    it): the export carries the sample and the fit takes the file and keeps the night."""
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
                defrost = night.kind == "normal" and k == 20
                store.add_sample(Sample(nid, start + timedelta(seconds=float(t_s)),
                                        t_air_c=float(night.t_air_c[k]),
                                        t_out_c=float(night.t_out_c[k]),
                                        q_hc_w=-1200.0 if defrost else float(night.q_hc_w[k]),
                                        defrost=defrost))
    out = tmp_path / "nights.csv"
    done = run_cli("export", "--config", str(config), "--out", str(out))
    assert done.returncode == 0, done.stderr
    assert "-1200" in out.read_text()
    fitted = run_cli("fit", "--nights", str(out), "--json", str(tmp_path / "fit.json"),
                     timeout_s=300)
    assert fitted.returncode == 0, fitted.stderr
    quality = json.loads((tmp_path / "fit.json").read_text())["night_quality"]
    held = [q for q in quality if q["kind"] == "normal"]
    assert len(held) == 2 and all(q["used"] for q in held)
    assert all(any(i["kind"] == "defrost" for i in q["interruptions"]) for q in held)
