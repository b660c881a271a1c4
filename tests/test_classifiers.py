"""Range classifiers: the estimator, training split by household, saved models, classification."""

from __future__ import annotations

import json
import subprocess
import sys

import joblib
import numpy as np
import pandas as pd
import pytest
from sklearn.base import clone

from impctl.classifiers import (
    ClassResult,
    RangeClassifier,
    classify_nights,
    default_model_dir,
    load_models,
    save_models,
    train_classifiers,
)
from impctl.classifiers.campaign import (
    CAMPAIGN_FEATURE_NAMES,
    aggregate_nights,
    campaign_features,
    random_campaigns,
)
from impctl.classifiers.files.saved import credible_hull
from impctl.classifiers.training import TrainConfig, household_split
from impctl.errors import InputError
from impctl.imp import NIGHT_FEATURE_NAMES, night_features
from impctl.population import (
    ImpSimConfig,
    PopulationConfig,
    generate_dataset,
    sample_households,
    simulate_imp,
)
from impctl.population.ranges import bin_values, validate_ranges

U_RANGES = {"u_walls": ((0.2, 1.0), (1.0, 2.0))}
FAST = TrainConfig(n_estimators=60, campaigns_per_household=4)


def test_bin_values_and_range_validation():
    rs = ((60.0, 100.0), (100.0, 200.0), (200.0, 300.0))
    assert bin_values([60, 99.9, 100, 150, 200, 300, 400, 10], rs).tolist() == \
        [0, 0, 1, 1, 2, 2, 2, 0]
    with pytest.raises(InputError, match="at least two"):
        validate_ranges({"c_f": ((0.8, 3.7),)})
    with pytest.raises(InputError, match="0 < low < high"):
        validate_ranges({"c_f": ((1.0, 0.8), (0.8, 3.7))})


def test_range_classifier_is_a_scikit_learn_estimator():
    rng = np.random.default_rng(0)
    values = rng.uniform(60, 300, 400)
    x = np.c_[values + rng.normal(0, 5, 400), rng.normal(size=400)]
    model = RangeClassifier(n_estimators=30, random_state=0)
    assert clone(model).get_params() == model.get_params()
    model.fit(x, values)
    assert list(model.classes_) == ["60-100", "100-200", "200-300"]
    assert model.score(x, values) > 0.95
    assert set(model.predict(x[:5])) <= set(model.classes_)
    # A range absent from the training data still has a (zero) probability column.
    only_big = values > 100
    proba = RangeClassifier(n_estimators=10).fit(x[only_big], values[only_big]).predict_proba(x)
    assert proba.shape == (400, 3) and np.all(proba[:, 0] == 0)
    np.testing.assert_allclose(proba.sum(axis=1), 1.0)
    # A model pickled before ``max_samples`` existed (its state has no such key) still
    # describes itself, as every bootstrap-sized forest did.
    state = dict(model.__getstate__())
    del state["max_samples"]
    older = RangeClassifier.__new__(RangeClassifier)
    older.__setstate__(state)
    assert older.get_params()["max_samples"] is None and "RangeClassifier(" in repr(older)
    np.testing.assert_array_equal(older.predict(x[:20]), model.predict(x[:20]))


def test_household_split_keeps_households_whole():
    train, test = household_split(50, 0.2, np.random.default_rng(1))
    assert len(test) == 10 and len(train) == 40
    assert not set(train) & set(test) and set(train) | set(test) == set(range(50))


def test_random_campaigns_pick_the_asked_number_of_each_kind():
    cons = np.tile([True, False, False], 10)
    masks = random_campaigns(cons, 200, np.random.default_rng(2), n_constrained=2, n_normal=6)
    assert (masks & cons).sum(axis=1).tolist() == [2] * 200
    assert (masks & ~cons).sum(axis=1).tolist() == [6] * 200
    free = random_campaigns(cons, 500, np.random.default_rng(3), 4, 8)
    assert free.any(axis=1).all() and (free & cons).sum(axis=1).max() == 4


def test_campaign_row_combines_kinds_into_tau_and_capacity():
    rows = [
        {"is_constrained": 1.0, "decay_rate_per_h": 0.02, "t_out_mean_c": 0.0},
        {"is_constrained": 1.0, "decay_rate_per_h": 0.03, "t_out_mean_c": 2.0},
        {"is_constrained": 0.0, "q_hc_mean_w": 4400.0, "t_set_c": 22.0, "t_out_mean_c": 0.0},
        {"is_constrained": 0.0, "q_hc_mean_w": 3800.0, "t_set_c": 22.0, "t_out_mean_c": 3.0},
    ]
    row = campaign_features(rows)
    assert list(row) == list(CAMPAIGN_FEATURE_NAMES)
    hlc = (4400 * 22 + 3800 * 19) / (22**2 + 19**2)
    assert row["n_hlc_w_per_k"] == pytest.approx(hlc)
    assert row["tau_h"] == pytest.approx(1 / 0.025)
    assert row["c_m_mj_per_k"] == pytest.approx(40 * hlc * 3600 / 1e6)
    assert row["c_t_out_mean_c"] == 1.0 and row["n_t_out_mean_c"] == 1.5
    only_normal = campaign_features(rows[2:])
    assert np.isnan(only_normal["tau_h"]) and np.isfinite(only_normal["n_hlc_w_per_k"])
    empty = aggregate_nights(np.zeros((1, 0, len(NIGHT_FEATURE_NAMES))), np.zeros((1, 0), bool))
    assert empty.shape == (1, len(CAMPAIGN_FEATURE_NAMES)) and np.isnan(empty).all()


@pytest.fixture(scope="module")
def envelope_dataset():
    """Houses that differ mainly in u_walls: the heat-loss coefficient then gives it away."""
    cfg = PopulationConfig(floor_area_m2=(150, 152), c_f=(1.6, 1.7), u_windows=(1.3, 1.4),
                           window_wall_ratio=(0.2, 0.21), aspect_ratio=(1.4, 1.5),
                           two_storey_probability=(1.0, 1.0))
    return generate_dataset(60, seed=11, ranges=U_RANGES, population=cfg,
                            imp=ImpSimConfig(days=3))


@pytest.fixture(scope="module")
def trained(envelope_dataset):
    return train_classifiers(envelope_dataset, FAST, seed=11)


def test_training_learns_an_identifiable_parameter_and_reports_baselines(trained):
    models, reports = trained
    r = reports["u_walls"]
    assert r.n_train_households + r.n_test_households == 60 and r.n_test_households == 12
    assert np.sum(r.confusion) == 12 and r.test_class_counts == np.sum(r.confusion, 1).tolist()
    assert r.test_accuracy >= 0.9 and r.test_accuracy_small >= 0.75
    assert r.test_accuracy > r.majority_accuracy
    assert 0.0 <= r.shuffled_accuracy <= 1.0
    assert r.paper_test_accuracy == 0.84 and len(r.test_households) == 12
    # probabilities: 48 training households are too few to calibrate on, so
    # the vote shares are kept (and said so); they still beat the prior
    assert not r.calibrated and not models["u_walls"].calibrated_
    assert r.brier == pytest.approx(r.brier_votes, rel=1e-9) and r.brier < r.brier_prior
    assert sum(b[2] for b in r.reliability) == 12 * FAST.test_campaigns * len(r.labels)
    m = models["u_walls"]
    p = m.predict_proba(pd.DataFrame(np.zeros((1, m.n_features_in_)), columns=m.feature_names_in_))
    assert p.sum() == pytest.approx(1.0)


def test_calibration_turns_crowded_vote_shares_into_probabilities():
    """Noisy labels: vote shares are overconfident on the training houses' look-alikes; the
    calibrated probabilities, fitted on held-out households, score a better Brier on new ones."""
    from impctl.classifiers.estimator import RangeClassifier
    from impctl.classifiers.training import brier_score

    rng = np.random.default_rng(4)

    def data(n):
        x = rng.normal(size=(n, 4))
        value = 0.5 + 0.5 / (1 + np.exp(-1.5 * x[:, 0])) + rng.normal(0, 0.25, n)
        return x, np.clip(value, 0.21, 1.99), np.repeat(np.arange(n // 4), 4)[:n]

    x, y, groups = data(1600)
    clf = RangeClassifier(U_RANGES["u_walls"], n_estimators=60, min_samples_leaf=1,
                          random_state=0).fit(x, y, groups=groups)
    assert clf.calibrated_
    xt, yt, _ = data(800)
    idx = np.searchsorted([r[1] for r in U_RANGES["u_walls"]], yt, side="right")
    idx = np.minimum(idx, len(U_RANGES["u_walls"]) - 1)
    assert brier_score(clf.predict_calibrated(xt), idx) < brier_score(clf.predict_votes(xt), idx)


def test_saved_models_round_trip_and_classify_measured_nights(trained, envelope_dataset,
                                                              tmp_path):
    models, reports = trained
    save_models(models, tmp_path, seed=11, n_households=60, emission_lag_h=1.0,
                report={k: v.as_dict() for k, v in reports.items()},
                dataset_manifest=envelope_dataset.manifest)
    loaded, meta = load_models(tmp_path)
    assert meta["campaign_features"] == list(CAMPAIGN_FEATURE_NAMES)
    assert meta["parameters"]["u_walls"]["labels"] == ["0.2-1", "1-2"]
    houses = sample_households(1, seed=99, config=PopulationConfig(
        floor_area_m2=(150, 152), c_f=(1.6, 1.7), u_walls=(1.6, 1.7), u_windows=(1.3, 1.4),
        window_wall_ratio=(0.2, 0.21), aspect_ratio=(1.4, 1.5),
        two_storey_probability=(1.0, 1.0)))
    nights = simulate_imp(houses, config=ImpSimConfig(days=3), seed=99).nights_of(0)
    result = classify_nights(nights, tmp_path)["u_walls"]
    assert isinstance(result, ClassResult)
    assert result.label == "1-2" and result.range == (1.0, 2.0)
    assert result.probability == max(result.probabilities.values())
    assert sum(result.probabilities.values()) == pytest.approx(1.0)
    # the fit searches every class the probabilities do not rule out, the likeliest included
    ranked = sorted(zip(result.probabilities.values(), U_RANGES["u_walls"], strict=True),
                    reverse=True)
    inside = ranked[:1] if ranked[0][0] >= 0.95 else ranked
    assert result.fit_range == (min(r[0] for _, r in inside), max(r[1] for _, r in inside))
    assert result.as_dict()["search_range"] == list(result.fit_range)
    row = campaign_features([night_features(n) for n in nights])
    x = pd.DataFrame([row], columns=list(CAMPAIGN_FEATURE_NAMES))
    np.testing.assert_allclose(loaded["u_walls"].predict_proba(x),
                               models["u_walls"].predict_proba(x))


def _corrupt(directory, edit):
    meta = json.loads((directory / "models.json").read_text())
    edit(meta)
    (directory / "models.json").write_text(json.dumps(meta))


@pytest.mark.parametrize("edit, words", [
    (lambda m: m.update(format=99), "model format 99"),
    (lambda m: m["versions"].update({"scikit-learn": "0.24.2"}), "scikit-learn 0.24.2"),
    (lambda m: m.update(campaign_features=["x"]), "other features"),
    (lambda m: m["parameters"]["u_walls"].update(ranges=[[0, 1], [1, 5]]), "not the u_walls"),
])
def test_incompatible_models_are_refused_clearly(trained, tmp_path, edit, words):
    save_models(trained[0], tmp_path, seed=11, n_households=60, emission_lag_h=1.0)
    _corrupt(tmp_path, edit)
    with pytest.raises(InputError) as err:
        load_models(tmp_path)
    assert words in str(err.value) and "impctl train" in str(err.value)


def test_missing_or_damaged_models_tell_the_user_to_train(trained, tmp_path):
    with pytest.raises(InputError, match="no trained models here; run `impctl train`"):
        classify_nights([], tmp_path / "empty")
    save_models(trained[0], tmp_path, seed=11, n_households=60, emission_lag_h=1.0)
    (tmp_path / "u_walls.joblib").write_bytes(b"not a pickle")
    with pytest.raises(InputError, match="cannot load the u_walls model"):
        load_models(tmp_path)
    joblib.dump({"not": "a model"}, tmp_path / "u_walls.joblib")
    with pytest.raises(InputError, match="not the u_walls model"):
        load_models(tmp_path)


def test_default_model_dir(monkeypatch, tmp_path):
    monkeypatch.setenv("IMPCTL_MODEL_DIR", str(tmp_path / "m"))
    assert default_model_dir() == tmp_path / "m"
    monkeypatch.delenv("IMPCTL_MODEL_DIR")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    assert default_model_dir() == tmp_path / "data" / "impctl" / "models"


def test_importing_the_pipeline_packages_loads_neither_torch_nor_scikit_learn():
    code = ("import sys, impctl.cli, impctl.population as p, impctl.classifiers as c, impctl.fit; "
            "c.default_model_dir(); c.DEFAULT_RANGES; p.DEFAULT_RANGES; "
            "print(sorted(m for m in ('torch', 'sklearn') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_forests_on_a_subset_of_features_are_for_benches_not_for_saving(envelope_dataset,
                                                                        tmp_path):
    """``TrainConfig(features=...)`` (bench/classify_compare.py measures what a feature adds)
    trains on those columns only; such models are refused by save_models, since
    classification computes every campaign feature."""
    from dataclasses import replace

    subset = ("n_hlc_w_per_k", "tau_h")
    models, reports = train_classifiers(envelope_dataset, replace(FAST, features=subset), seed=11,
                                        with_baselines=False)
    assert list(models["u_walls"].feature_names_in_) == list(subset)
    assert reports["u_walls"].test_accuracy > reports["u_walls"].majority_accuracy
    with pytest.raises(ValueError, match="not trained on all campaign features"):
        save_models(models, tmp_path, seed=11, n_households=60, emission_lag_h=1.0)
    assert not (tmp_path / "models.json").exists()
    with pytest.raises(ValueError, match="unknown campaign features"):
        train_classifiers(envelope_dataset, replace(FAST, features=("nope",)), seed=11)


def test_gateway_campaigns_keep_valid_constrained_nights_and_give_up_after_three():
    """The 2+6 campaign as the gateway delivers it: invalid constrained nights (NaN features)
    are retried with another night, never used, and after 3 invalid ones the household has
    what it has."""
    from impctl.classifiers.campaign import gateway_campaigns

    n_rows, cons = 300, np.array([True] * 5 + [False] * 8)
    values = np.ones((n_rows, cons.size, len(NIGHT_FEATURE_NAMES)))
    values[:, :, NIGHT_FEATURE_NAMES.index("is_constrained")] = cons
    cool = NIGHT_FEATURE_NAMES.index("cooling_time_h")
    values[100:200, [0, 1, 2, 3], cool] = np.nan       # one valid constrained night of five
    values[200:, :5, cool] = np.nan                       # none valid
    masks = gateway_campaigns(values, np.random.default_rng(0))
    assert (masks[:, ~cons].sum(axis=1) == 6).all()
    n_cons = masks[:, cons].sum(axis=1)
    assert (n_cons[:100] == 2).all() and (n_cons[200:] == 0).all()
    assert not masks[100:200, :4].any()                   # the invalid nights are never used
    # The valid night comes before the third invalid one in 3 of 5 orders.
    assert set(n_cons[100:200]) == {0, 1} and 0.45 < n_cons[100:200].mean() < 0.75
    assert gateway_campaigns(values, np.random.default_rng(0)).tolist() == masks.tolist()


@pytest.mark.parametrize("proba, hull", [
    ((0.97, 0.02, 0.01), (60.0, 100.0)),    # one class is enough
    ((0.70, 0.25, 0.05), (60.0, 200.0)),    # the two likeliest reach 95 %
    ((0.60, 0.01, 0.39), (60.0, 300.0)),    # the middle class is inside the hull
    ((0.05, 0.90, 0.05), (60.0, 300.0)),    # a tie at the edge of 95 %: both kept
])
def test_credible_hull_is_the_classes_up_to_95_percent(proba, hull):
    ranges = ((60.0, 100.0), (100.0, 200.0), (200.0, 300.0))
    assert credible_hull(ranges, proba) == hull
