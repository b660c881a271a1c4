"""The model-error share of the intervals (impctl.fit.intervals.model_error): the packaged
calibration is
loaded and widens a realistic house's intervals by its stated share, barely touches an ideal
house's, a broken file is refused in one line, and two nights give a stated basis."""

from __future__ import annotations

import json

import numpy as np
import pytest

from impctl.errors import InputError
from impctl.fit.estimator import NightFit
from impctl.fit.intervals import model_error
from impctl.fit.result.report import fit_to_dict
from impctl.fit.result.table import format_table
from impctl.model import HouseParameters
from impctl.population.households import sample_households
from impctl.population.imp_run.synth import (
    imp_schedule,
    run_schedule_plant,
    sample_nights,
    synth_nights,
)
from impctl.population.realism import sample_params

HOUSE = HouseParameters(floor_area=150.0, wall_height=2.6, walls_area=200.0, windows_area=30.0,
                        c_f=1.65, u_walls=0.6, u_windows=1.4, ach_vent=0.0, ach_infl=0.01)
RANGES = {"floor_area": (100.0, 200.0), "c_f": (0.8, 1.65), "u_walls": (0.2, 1.0)}


def _sd(e) -> float:
    return float(np.log(e.high / e.low) / (2 * model_error.Z95))


@pytest.fixture(scope="module")
def realistic_nights():
    # one household of the realistic plant (emitter, control, gains, sensors), 5-min rows
    houses = sample_households(1, seed=11)
    sched = imp_schedule(1, seed=11, n_normal=4)
    logged, sp = run_schedule_plant(houses, sched, sample_params(1, 11), seed=11)
    return sample_nights(logged, sp, sched, 0, sample_step_s=300.0, power_noise=0.0, seed=11)


def test_the_packaged_calibration_is_loaded_and_widens_a_realistic_fit(realistic_nights):
    cal = model_error.load_calibration()
    assert cal["provenance"]["n_households"] >= 150 and cal["provenance"]["seed"] != 20260
    assert "bench/calibrate_intervals.py" in cal["provenance"]["command"]
    kw = dict(n_starts=2, per_night=False)
    off = NightFit(model_error=None, **kw).fit(realistic_nights, RANGES)
    on = NightFit(**kw).fit(realistic_nights, RANGES)
    group, band = on.model_error_["group"], on.model_error_["band"]
    assert group == model_error.group_of(model_error.diagnostics(off)) != "clean"
    assert band == "many"          # 6 nights: more than the campaigns' few
    share = cal["bands"][band]["groups"][group]["share"]
    assert max(share.values()) > 0.05
    for q in model_error.QUANTITIES:
        a, b = off.lumped_[q], on.lumped_[q]
        assert b.value == pytest.approx(a.value, rel=1e-9)      # widening only, no correction
        assert _sd(b) == pytest.approx(np.hypot(_sd(a), share[q]), rel=1e-6)
        assert b.low <= a.low and b.high >= a.high
    summary = fit_to_dict(on)
    assert f"group '{group}'" in summary["interval_method"]
    assert summary["fit"]["model_error"]["n_calibration"] == cal["provenance"]["n_households"]
    assert summary["fit"]["model_error"]["n_fits"] == cal["pooled"]["n"]
    assert "intervals: sandwich + type-B + model-error share calibrated on" in format_table(summary)
    assert "no model-error share" in fit_to_dict(off)["interval_method"]


def test_an_ideal_fit_is_clean_and_its_hlc_interval_is_not_widened():
    nights = synth_nights(HOUSE, seed=4, sample_step_s=300.0, n_normal=4)
    kw = dict(n_starts=2, per_night=False)
    off = NightFit(model_error=None, **kw).fit(nights, RANGES)
    on = NightFit(**kw).fit(nights, RANGES)
    assert on.model_error_["group"] == "clean"
    band = model_error.load_calibration()["bands"][on.model_error_["band"]]
    groups = band["groups"]
    # the realistic fits that look clean stay inside their own HLC interval (decision 0028)
    assert groups["clean"]["share"]["hlc"] == 0.0
    assert on.lumped_["hlc"].low == pytest.approx(off.lumped_["hlc"].low, rel=1e-12)
    for q in model_error.QUANTITIES:
        # widened by the "clean" share only, never more than the band's pooled share
        assert groups["clean"]["share"][q] <= band["pooled"][q]
        assert _sd(on.lumped_[q]) == pytest.approx(np.hypot(_sd(off.lumped_[q]),
                                                            groups["clean"]["share"][q]))
        truth = {"hlc": HOUSE.hlc_w_per_k, "c_m": HOUSE.c_m_j_per_k, "tau": HOUSE.tau_h}[q]
        assert on.lumped_[q].low <= truth <= on.lumped_[q].high


@pytest.mark.parametrize("content, problem", [
    ("{not json", "unreadable"),
    (json.dumps({"schema": "other"}), "schema"),
    (json.dumps({"schema": "impctl-model-error/1", "grouping": model_error.GROUPING}),
     "schema"),    # the 8-night-only calibration: refused, not read as the few-nights band
    (json.dumps({"schema": model_error.SCHEMA, "grouping": "rows-residuals-nuisance-discharge/5"}),
     "grouping"),
    (json.dumps({"schema": "impctl-model-error/2", "grouping": model_error.GROUPING}),
     "schema"),    # the few band of the 2 + 6 protocol's first nights: refused
    (json.dumps({"schema": model_error.SCHEMA, "grouping": model_error.GROUPING,
                 "bands": {"few": {"groups": {}}}}),
     "band 'few' has no protocol"),
    (json.dumps({"schema": model_error.SCHEMA, "grouping": model_error.GROUPING,
                 "bands": {"few": {"protocol": {"constrained_setpoint_c": 21.0,
                                                "normal_setpoints_c": [21.0]},
                                   "groups": {"clean": {"share": {"hlc": 0.1, "c_m": 0.1}}}}}}),
     "band 'few', group 'clean': share of tau"),
])
def test_a_corrupt_calibration_file_gives_one_clear_error_before_any_work(tmp_path, content,
                                                                         problem):
    path = tmp_path / "model_error.json"
    path.write_text(content)
    nights = synth_nights(HOUSE, seed=4, sample_step_s=3600.0, n_normal=1)
    with pytest.raises(InputError, match=problem) as err:
        NightFit(model_error=str(path)).fit(nights, RANGES)
    msg = str(err.value)
    assert str(path) in msg and "calibrate_intervals.py" in msg and "\n" not in msg


def test_the_few_band_was_calibrated_on_the_gateways_campaign_nights():
    # stale-file check: the few band must be calibrated on the nights a gateway runs by
    # default; after a change of CampaignConfig's setpoints regenerate model_error.json
    # (bench/calibrate_intervals.py reads them from there)
    from impctl.config import CampaignConfig

    cfg = CampaignConfig()
    cal = model_error.load_calibration()
    assert model_error.few_protocol(cal) == (cfg.constrained_setpoint_c,
                                             tuple(cfg.normal_setpoints_c))
    sequences = cal["bands"]["few"]["protocol"]["sequences"]
    assert any(s.startswith("c") and s.count("c") == 1 for s in sequences)   # adaptive endings
    assert any(s.count("c") == cfg.constrained_nights for s in sequences)    # the fixed plan


def test_the_calibration_ran_the_gateways_constrained_nights():
    # stale-file check (issue 14, h14w): the share is calibrated on constrained nights that end
    # as the gateway ends them, at the default band; after a change of DEFAULT_BAND_K
    # regenerate model_error.json with bench/calibrate_intervals.py
    from impctl.imp.protocol import DEFAULT_BAND_K

    protocol = model_error.load_calibration()["bands"]["few"]["protocol"]
    assert protocol.get("band_k") == DEFAULT_BAND_K
    assert str(protocol.get("constrained_nights", "")).startswith("gateway")


def test_coarse_rows_take_the_coarse_share_whatever_the_residuals_say():
    # at 15-minute or hourly rows a realistic house's residuals look as clean as an ideal one's
    clean = {"rho_power": 0.0, "rmse_over_noise_power": 1.0, "nuisance_selected": False}
    assert model_error.group_of({**clean, "row_step_s": 300.0}) == "clean"
    assert model_error.group_of({**clean, "row_step_s": 610.0}) == "clean"   # a gateway's 10 min
    assert model_error.group_of({**clean, "row_step_s": 900.0}) == "coarse"
    assert model_error.group_of({**clean, "row_step_s": 3600.0}) == "coarse"


def test_few_night_fits_have_their_own_band_and_a_thin_cell_never_takes_the_narrower_share():
    assert model_error.band_of({"n_nights": 2}) == "few"
    assert model_error.band_of({"n_nights": model_error.FEW_MAX_NIGHTS}) == "few"
    assert model_error.band_of({"n_nights": model_error.FEW_MAX_NIGHTS + 1}) == "many"
    rng = np.random.default_rng(1)
    plain = {"rho_power": 0.5, "rmse_over_noise_power": 2.0, "nuisance_selected": False,
             "row_step_s": 300.0}

    def recs(n, nights, scale, diag=plain):
        return [{"diagnostics": {**diag, "n_nights": nights},
                 "log_error": {q: float(scale * rng.standard_normal()) for q in
                               model_error.QUANTITIES},
                 "sd": {q: 0.02 for q in model_error.QUANTITIES}} for _ in range(n)]

    # few-night fits err twice as much as 8-night ones: their band's share is wider
    coarse = {**plain, "row_step_s": 3600.0}
    records = recs(60, 8, 0.1) + recs(60, 3, 0.2) + recs(40, 8, 0.4, coarse)
    cal = model_error.calibrate(records, {})
    few, many = cal["bands"]["few"]["groups"], cal["bands"]["many"]["groups"]
    assert few["plain"]["n"] == 60 and many["plain"]["n"] == 60
    assert few["plain"]["share"]["tau"] > 1.3 * many["plain"]["share"]["tau"]
    # no coarse few-night fit: the wider of the few band's pooled share and the coarse one
    assert few["coarse"]["n"] == 0
    for q in model_error.QUANTITIES:
        assert few["coarse"]["share"][q] == max(many["coarse"]["share"][q],
                                                cal["bands"]["few"]["pooled"][q])
    band, group, entry = model_error.entry_of(cal, {**plain, "n_nights": 4})
    assert (band, group) == ("few", "plain") and entry is few["plain"]


def test_a_thin_clean_cell_takes_the_conformal_share_of_the_clean_fits_of_both_bands():
    rng = np.random.default_rng(2)
    clean = {"rho_power": 0.0, "rmse_over_noise_power": 1.0, "nuisance_selected": False,
             "row_step_s": 300.0}
    plain = {**clean, "rho_power": 0.5, "rmse_over_noise_power": 2.0}

    def recs(n, nights, diag, hlc, tau):
        return [{"diagnostics": {**diag, "n_nights": nights},
                 "log_error": {"hlc": float(hlc * rng.standard_normal()), "c_m": 0.0,
                               "tau": float(tau * rng.standard_normal())},
                 "sd": {q: 0.02 for q in model_error.QUANTITIES}} for _ in range(n)]

    # many nights: 3 clean fits, one far off in HLC; few nights: 40 clean fits whose HLC sits
    # within its own interval and whose τ errs by 10 %
    thin = recs(2, 8, clean, 0.0, 0.05) + [{"diagnostics": {**clean, "n_nights": 8},
                                           "log_error": {"hlc": 0.5, "c_m": 0.0, "tau": 0.0},
                                           "sd": {q: 0.02 for q in model_error.QUANTITIES}}]
    records = thin + recs(40, 3, clean, 0.005, 0.1) + recs(60, 8, plain, 0.3, 0.3)
    cal = model_error.calibrate(records, {})
    cell = cal["bands"]["many"]["groups"]["clean"]
    assert cell["n"] == 3 and "43 clean fits of both bands" in cell["source"]
    both = [r for r in records if model_error.group_of(r["diagnostics"]) == "clean"]
    for q in model_error.QUANTITIES:
        pooled = model_error.conformal_share([r["log_error"][q] for r in both],
                                             [r["sd"][q] for r in both])
        assert cell["share"][q] == min(pooled, cal["bands"]["many"]["pooled"][q])
    # the one fit off by 50 % is one of 43: no reason to widen every clean HLC interval by it
    assert cell["share"]["hlc"] == 0.0 and cell["share"]["tau"] > 0.05
    # too few clean fits in both bands: the largest share its own fits needed, as before
    few_clean = model_error.calibrate(thin + recs(10, 3, clean, 0.005, 0.1)
                                      + recs(60, 8, plain, 0.3, 0.3), {})
    assert few_clean["bands"]["many"]["groups"]["clean"]["share"]["hlc"] > 0.2


def test_the_conformal_share_covers_the_stated_share_of_households():
    rng = np.random.default_rng(0)
    err, sd = 0.2 * rng.standard_normal(99), np.full(99, 0.05)
    s = model_error.conformal_share(err, sd)
    covered = np.abs(err) <= model_error.Z95 * np.hypot(sd, s)
    assert covered.sum() == 95          # ⌈0.95·100⌉ of the 99
    assert model_error.conformal_share(err[:5], sd[:5]) == float("inf")


def test_two_nights_say_the_interval_is_model_based_not_sandwich():
    nights = synth_nights(HOUSE, seed=4, sample_step_s=300.0, n_constrained=1, n_normal=1)
    fit = NightFit(n_starts=2, per_night=False).fit(nights, RANGES)
    assert fit.interval_basis_.startswith("too few nights (2)")
    assert fit.model_error_["band"] == "few"
    assert all(v == "laplace" for v in fit.interval_source_.values())
    summary = fit_to_dict(fit)
    assert "too few nights" in summary["interval_method"]
    assert "too few nights" in format_table(summary)
    for q in model_error.QUANTITIES:   # no t(1) = 12.7 blow-up of the statistical part
        stat_sd = np.sqrt(_sd(fit.lumped_[q]) ** 2 - fit.model_error_["share"][q] ** 2)
        assert np.exp(model_error.Z95 * stat_sd) < 2.0
