"""The range forests as arrays (impctl.classifiers.files.compact): the same probabilities as
scikit-learn, calibrated or not, with missing features; classification without scikit-learn;
fallback to the pickles when the arrays are missing, damaged or stale."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from impctl.classifiers import RangeClassifier, classify_nights, save_models
from impctl.classifiers.campaign import CAMPAIGN_FEATURE_NAMES
from impctl.classifiers.files.compact import (
    COMPACT_FILE,
    CompactForest,
    export_arrays,
    load_compact,
    save_compact,
)
from impctl.classifiers.files.saved import add_compact, load_models
from impctl.population import ImpSimConfig, sample_households, simulate_imp

RANGES = {"floor_area": ((60.0, 100.0), (100.0, 200.0), (200.0, 300.0)),
          "u_walls": ((0.2, 1.0), (1.0, 2.0))}
NAMES = list(CAMPAIGN_FEATURE_NAMES)


def _data(n: int, seed: int):
    """Campaign-shaped rows whose first two features carry the parameters; 5 % missing."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, len(NAMES)))
    area = np.clip(180 + 70 * x[:, 0] + rng.normal(0, 30, n), 61, 299)
    u = np.clip(1.0 + 0.4 * x[:, 1] + rng.normal(0, 0.2, n), 0.21, 1.99)
    x[rng.random(x.shape) < 0.05] = np.nan
    return pd.DataFrame(x, columns=NAMES), {"floor_area": area, "u_walls": u}


@pytest.fixture(scope="module")
def models():
    x, y = _data(1200, 0)
    groups = np.repeat(np.arange(300), 4)
    out = {name: RangeClassifier(rs, n_estimators=40, random_state=1).fit(x, y[name],
                                                                         groups=groups)
           for name, rs in RANGES.items()}
    assert all(m.calibrated_ for m in out.values())
    return out


@pytest.mark.parametrize("calibrated", [True, False])
def test_arrays_give_scikit_learns_probabilities(models, calibrated):
    x, _ = _data(500, 7)
    for name, model in models.items():
        if not calibrated:
            model = RangeClassifier(RANGES[name], n_estimators=25, random_state=2,
                                    calibration=None).fit(*_xy(name))
        compact = CompactForest(export_arrays(model))
        assert compact.calibrated_ is calibrated
        got = compact.predict_proba(x.to_numpy())
        np.testing.assert_allclose(got, model.predict_proba(x), rtol=0, atol=1e-12)
        assert list(compact.classes_) == list(model.classes_)
        assert not np.allclose(got, got[0])   # the rows are not all classified alike


def _xy(name):
    x, y = _data(400, 3)
    return x, y[name]


def test_saved_models_classify_from_the_arrays_without_scikit_learn(models, tmp_path):
    save_models(models, tmp_path, seed=0, n_households=300, emission_lag_h=1.0)
    meta = json.loads((tmp_path / "models.json").read_text())
    assert meta["compact"] == COMPACT_FILE and (tmp_path / COMPACT_FILE).is_file()
    houses = sample_households(1, seed=5)
    nights = simulate_imp(houses, config=ImpSimConfig(days=3), seed=5).nights_of(0)
    fast = classify_nights(nights, tmp_path)
    (tmp_path / COMPACT_FILE).unlink()   # the pickles: the reference path
    slow = classify_nights(nights, tmp_path)
    for name in RANGES:
        assert fast[name].label == slow[name].label
        assert fast[name].range == slow[name].range
        assert fast[name].calibrated and slow[name].calibrated
        for label, p in slow[name].probabilities.items():
            assert fast[name].probabilities[label] == pytest.approx(p, abs=1e-12)
    assert add_compact(tmp_path) and (tmp_path / COMPACT_FILE).is_file()
    # A fresh interpreter classifies from the arrays: scikit-learn is never imported.
    code = ("import sys, pickle; from impctl.classifiers import classify_nights; "
            f"nights = pickle.load(open({str(tmp_path / 'n.pkl')!r}, 'rb')); "
            f"r = classify_nights(nights, {str(tmp_path)!r}); "
            "print(r['u_walls'].label, 'sklearn' in sys.modules)")
    import pickle

    (tmp_path / "n.pkl").write_bytes(pickle.dumps(nights))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == [slow["u_walls"].label, "False"]


def test_damaged_or_stale_arrays_fall_back_to_the_pickles(models, tmp_path):
    save_models(models, tmp_path, seed=0, n_households=300, emission_lag_h=1.0)
    houses = sample_households(1, seed=6)
    nights = simulate_imp(houses, config=ImpSimConfig(days=3), seed=6).nights_of(0)
    want = {k: v.probabilities for k, v in classify_nights(nights, tmp_path).items()}
    (tmp_path / COMPACT_FILE).write_bytes(b"not an npz")
    assert load_compact(tmp_path, list(RANGES)) is None
    got = classify_nights(nights, tmp_path)
    for name in RANGES:
        assert got[name].probabilities == pytest.approx(want[name], abs=1e-12)
    # Arrays of other ranges than models.json names are not used.
    other = {"u_walls": RangeClassifier(((0.2, 0.6), (0.6, 2.0)), n_estimators=10,
                                        random_state=0, calibration=None).fit(*_xy("u_walls")),
             "floor_area": models["floor_area"]}
    assert save_compact(other, tmp_path) is not None
    got = classify_nights(nights, tmp_path)
    assert got["u_walls"].range in RANGES["u_walls"]
    assert got["u_walls"].probabilities == pytest.approx(want["u_walls"])


def test_load_models_still_checks_the_pickles(models, tmp_path):
    save_models(models, tmp_path, seed=0, n_households=300, emission_lag_h=1.0)
    loaded, meta = load_models(tmp_path)
    assert set(loaded) == set(RANGES) and meta["compact"] == COMPACT_FILE


def test_a_model_the_arrays_cannot_express_gets_no_compact_file(tmp_path):
    x, y = _data(1200, 4)
    groups = np.repeat(np.arange(300), 4)
    temperature = {"u_walls": RangeClassifier(RANGES["u_walls"], n_estimators=20,
                                              random_state=0, calibration="temperature").fit(
        x, y["u_walls"], groups=groups)}
    assert temperature["u_walls"].calibrated_
    (tmp_path / COMPACT_FILE).write_bytes(b"stale")
    save_models(temperature, tmp_path, seed=0, n_households=300, emission_lag_h=1.0)
    assert not (tmp_path / COMPACT_FILE).exists()
    assert "compact" not in json.loads((tmp_path / "models.json").read_text())
    houses = sample_households(1, seed=8)
    nights = simulate_imp(houses, config=ImpSimConfig(days=3), seed=8).nights_of(0)
    result = classify_nights(nights, tmp_path)["u_walls"]   # from the pickle
    assert result.calibrated and sum(result.probabilities.values()) == pytest.approx(1.0)
