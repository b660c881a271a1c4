"""Calibrated class probabilities (cross-validated by household), kept in the saved models and
their compact arrays, and a parameter the features do not determine reported as its prior."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from impctl.classifiers import RangeClassifier, save_models
from impctl.classifiers.campaign import CAMPAIGN_FEATURE_NAMES
from impctl.classifiers.files.compact import CompactForest, export_arrays, load_compact
from impctl.classifiers.files.saved import classify_with, load_models
from impctl.classifiers.result import NOT_DETERMINED
from impctl.classifiers.training import brier_score, expected_calibration_error
from impctl.population import ImpSimConfig, sample_households, simulate_imp
from impctl.population.ranges import bin_values

NAMES = list(CAMPAIGN_FEATURE_NAMES)
AREA = ((60.0, 100.0), (100.0, 200.0), (200.0, 300.0))
CF = ((0.8, 1.65), (1.65, 3.7))


def _data(n_houses: int, seed: int, rows_per_house: int = 4):
    """Campaign-shaped rows: floor area noisily carried by the first feature; c_f by none
    (drawn 70 / 30 % light / heavy, as the population's prior). Rows of a house share its
    parameters; 5 % of the cells missing."""
    rng = np.random.default_rng(seed)
    area = np.repeat(rng.uniform(61, 299, n_houses), rows_per_house)
    c_f = np.repeat(np.where(rng.random(n_houses) < 0.7, 1.2, 2.5), rows_per_house)
    x = rng.normal(size=(len(area), len(NAMES)))
    x[:, 0] = (area - 180) / 70 + rng.normal(0, 0.6, len(area))
    x[rng.random(x.shape) < 0.05] = np.nan
    groups = np.repeat(np.arange(n_houses), rows_per_house)
    return pd.DataFrame(x, columns=NAMES), {"floor_area": area, "c_f": c_f}, groups


@pytest.fixture(scope="module")
def fitted():
    x, y, groups = _data(300, 0)
    # leaves of one row: overconfident vote shares, which the calibration must temper; five
    # folds, whose forests see four fifths of the houses (the bag's trees see half: on 300
    # houses with leaves of one row their votes are too weak a stand-in, see below)
    return {name: RangeClassifier(rs, n_estimators=40, min_samples_leaf=1, random_state=3,
                                  calibration=method, cv=5).fit(x, y[name], groups=groups)
            for name, rs, method in (("floor_area", AREA, "isotonic"), ("c_f", CF, "sigmoid"))}


def test_out_of_bag_votes_never_come_from_a_tree_that_saw_the_house():
    # every house told apart by its first feature, its class drawn at random: a tree that saw
    # a house knows its class (leaves of one row), a tree that did not can only guess
    rng = np.random.default_rng(11)
    n_houses, per = 300, 4
    area = np.repeat(rng.choice([80.0, 150.0, 250.0], n_houses), per)
    groups = np.repeat(np.arange(n_houses), per)
    x = pd.DataFrame(np.zeros((len(area), len(NAMES))), columns=NAMES)
    x[NAMES[0]] = groups + rng.uniform(-0.1, 0.1, len(groups))   # the only feature that varies
    model = RangeClassifier(AREA, n_estimators=30, min_samples_leaf=1, max_features=None,
                            random_state=0).fit(x, area, groups=groups)
    # held-out accuracy at chance (three classes about equally often), not the ~100 % a
    # row-level bag would give (the house's other campaigns in the tree)
    assert model.cv_accuracy_ < 0.45
    assert not model.determined_
    # the same data with the forest's own out-of-bag rows would leak: the check can fail
    leaky = RangeClassifier(AREA, n_estimators=30, min_samples_leaf=1, max_features=None,
                            random_state=0).fit(x, area, groups=np.arange(len(area)))
    assert leaky.cv_accuracy_ > 0.9 and leaky.determined_


def test_out_of_bag_calibration_is_as_good_as_five_folds_at_the_products_settings():
    x, y, groups = _data(600, 12)
    xt, yt, _ = _data(400, 13, rows_per_house=1)
    truth = bin_values(yt["floor_area"], AREA)
    score = {}
    for cv in (5, "oob"):
        model = RangeClassifier(AREA, n_estimators=100, min_samples_leaf=8, max_samples=0.5,
                                random_state=2, cv=cv).fit(x, y["floor_area"], groups=groups)
        assert model.calibrated_ and model.determined_
        cal = model.predict_calibrated(xt)
        np.testing.assert_allclose(cal.sum(axis=1), 1.0, atol=1e-12)
        score[cv] = brier_score(cal, truth)
    assert score["oob"] < score[5] + 0.01


def test_calibration_beats_the_vote_shares_on_new_houses(fitted):
    model = fitted["floor_area"]
    assert model.calibrated_ and model.determined_
    assert model.cv_margin_low_ >= 0.05 and model.cv_accuracy_ > model.cv_majority_ + 0.05
    x, y, _ = _data(400, 1, rows_per_house=1)
    truth = bin_values(y["floor_area"], AREA)
    cal, votes = model.predict_calibrated(x), model.predict_votes(x)
    np.testing.assert_allclose(cal.sum(axis=1), 1.0, atol=1e-12)
    assert brier_score(cal, truth) < brier_score(votes, truth)
    assert expected_calibration_error(cal, truth) < expected_calibration_error(votes, truth)
    np.testing.assert_array_equal(model.predict_proba(x), cal)   # determined: reported as is


def test_a_parameter_the_features_do_not_determine_reports_its_prior(fitted):
    model = fitted["c_f"]
    assert model.calibrated_ and not model.determined_
    assert model.cv_margin_low_ < 0.05
    x, _, _ = _data(50, 2, rows_per_house=1)
    proba = model.predict_proba(x)
    np.testing.assert_allclose(proba, np.tile(model.prior_, (50, 1)))
    assert model.prior_[0] == pytest.approx(0.7, abs=0.08) and model.prior_.sum() == \
        pytest.approx(1.0)
    assert not np.allclose(model.predict_calibrated(x), proba)   # the forest's are kept aside


def test_saved_models_give_the_same_probabilities_reloaded_and_as_arrays(fitted, tmp_path):
    save_models(fitted, tmp_path, seed=3, n_households=300, emission_lag_h=1.0)
    meta = json.loads((tmp_path / "models.json").read_text())
    assert meta["format"] == 2 and meta["compact"]
    assert meta["parameters"]["floor_area"]["calibration"] == "isotonic"
    assert meta["parameters"]["c_f"]["determined"] is False
    loaded, _ = load_models(tmp_path)
    compact = load_compact(tmp_path, list(fitted))
    x, _, _ = _data(80, 5, rows_per_house=1)
    for name, model in fitted.items():
        want = model.predict_proba(x)
        np.testing.assert_array_equal(loaded[name].predict_proba(x), want)
        np.testing.assert_allclose(compact[name].predict_proba(x.to_numpy()), want, atol=1e-12)
        np.testing.assert_allclose(compact[name].predict_calibrated(x.to_numpy()),
                                   model.predict_calibrated(x), atol=1e-12)
        assert compact[name].determined_ is model.determined_
        np.testing.assert_allclose(want.sum(axis=1), 1.0, atol=1e-12)


def test_sigmoid_and_isotonic_arrays_match_scikit_learn_on_three_classes():
    x, y, groups = _data(300, 6)
    for method in ("sigmoid", "isotonic"):
        model = RangeClassifier(AREA, n_estimators=20, random_state=1, calibration=method,
                                min_margin=-1.0).fit(x, y["floor_area"], groups=groups)
        arrays = export_arrays(model)
        xt, _, _ = _data(60, 7, rows_per_house=1)
        np.testing.assert_allclose(CompactForest(arrays).predict_proba(xt.to_numpy()),
                                   model.predict_proba(xt), atol=1e-12)


def test_classification_says_not_determined_and_keeps_the_prior(fitted, tmp_path):
    save_models(fitted, tmp_path, seed=3, n_households=300, emission_lag_h=1.0)
    houses = sample_households(1, seed=9)
    nights = simulate_imp(houses, config=ImpSimConfig(days=2), seed=9).nights_of(0)
    for models in (load_models(tmp_path)[0], load_compact(tmp_path, list(fitted))):
        result = classify_with(nights, models, {})
        cf, area = result["c_f"], result["floor_area"]
        assert not cf.determined and cf.source == NOT_DETERMINED
        assert cf.range == (0.8, 3.7) and cf.fit_range == (0.8, 3.7)   # no class: all of it
        assert list(cf.probabilities.values()) == pytest.approx(list(fitted["c_f"].prior_))
        assert "not determined by the nights" in cf.probability_text()
        assert cf.as_dict()["source"] == NOT_DETERMINED and not cf.as_dict()["determined"]
        assert area.determined and area.source == "classifier"
        assert area.probability_text().endswith("(calibrated probability)")
        for r in result.values():
            assert sum(r.probabilities.values()) == pytest.approx(1.0)


def test_the_report_says_when_a_verdict_sits_at_the_rules_edge():
    """A determination bound within two points of the rule's +5 is the training seed's
    verdict as much as the nights' (c_f on the realistic plant: +1.4 … +5.1 over seeds 0–5):
    the report says so; a clear one is reported plainly."""
    from impctl.classifiers.report import format_report
    from impctl.classifiers.training import ParameterReport

    def report(name: str, bound: float) -> ParameterReport:
        return ParameterReport(
            name, ["0.8-1.65", "1.65-3.7"], 0.9, 0.8, 0.75, 0.7, 0.5, [[5, 1], [2, 4]], [6, 6],
            None, None, 100, 12, list(range(12)), brier=0.3, brier_votes=0.32, brier_prior=0.42,
            calibrated=True, determined=bound >= 0.05, cv_accuracy=0.78, cv_majority=0.69,
            cv_margin_low=bound)

    text = format_report({"c_f": report("c_f", 0.051), "u_walls": report("u_walls", 0.2),
                          "floor_area": report("floor_area", 0.035)})
    verdicts = {line.split(":")[0]: line for line in text.splitlines()
                if line.startswith(("c_f:", "u_walls:", "floor_area:"))}
    assert set(verdicts) == {"c_f", "u_walls", "floor_area"}
    assert "c_f: determined" in verdicts["c_f"] and "+5.1 points" in verdicts["c_f"]
    assert "the rule asks +5.0" in verdicts["c_f"] and "rule's edge" in verdicts["c_f"]
    assert "NOT DETERMINED" in verdicts["floor_area"] and "rule's edge" in verdicts["floor_area"]
    assert "rule's edge" not in verdicts["u_walls"]
