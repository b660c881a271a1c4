"""``impctl train`` and ``impctl classify`` end to end: run in this process where the output
is checked, as real subprocesses where what the process imported is."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from cli_fixtures import run_impctl

from impctl.imp import DEFAULT_CONSTRAINED_SETPOINT_C, DEFAULT_SETPOINTS_C, write_nights
from impctl.population import ImpSimConfig, sample_households, simulate_imp


def run_cli(*args: str, env_home: Path | None = None) -> subprocess.CompletedProcess:
    # in this process: these tests check the output (refused_and_loaded() runs a subprocess
    # where what the process imported is checked)
    env = None if env_home is None else {"XDG_DATA_HOME": str(env_home), "IMPCTL_MODEL_DIR": ""}
    return run_impctl(*args, env=env)


@pytest.fixture(scope="module")
def model_dir(trained_models) -> Path:
    done = trained_models.run
    assert "paper train/test" in done.stdout and "floor_area" in done.stdout
    return trained_models.out


@pytest.fixture(scope="module")
def nights_csv(tmp_path_factory) -> Path:
    # One constrained night a day, as a real household's export has (not the population's replays).
    result = simulate_imp(sample_households(1, seed=8),
                          config=ImpSimConfig(days=3, constrained_per_day=1), seed=8)
    path = tmp_path_factory.mktemp("nights") / "nights.csv"
    return write_nights(result.nights_of(0), path)


def test_train_writes_models_dataset_and_report(model_dir):
    names = {p.name for p in model_dir.iterdir()}
    assert {"models.json", "floor_area.joblib", "c_f.joblib", "u_walls.joblib", "report.txt",
            "report.json", "dataset"} <= names
    assert {p.name for p in (model_dir / "dataset").iterdir()} == {
        "households.parquet", "nights.parquet", "manifest.json"}
    report = json.loads((model_dir / "report.json").read_text())
    assert report["c_f"]["n_test_households"] == 4 and report["c_f"]["paper_test_accuracy"] == 0.78
    meta = json.loads((model_dir / "models.json").read_text())
    assert meta["seed"] == 4 and meta["dataset"]["n_households"] == 20
    # The models carry the protocol of their population: the realistic plant's constrained
    # nights stopped at T_min, as the gateway records them (ImpSimConfig.for_plant).
    imp = meta["dataset"]["imp"]
    assert imp["stop_at_t_min"] is True and imp["band_k"] == ImpSimConfig().band_k
    nights = pd.read_parquet(model_dir / "dataset" / "nights.parquet")
    cons = nights[nights["kind"] == "constrained"]
    assert (cons["cooling_time_h"] < cons["duration_h"] - 1.2).any()   # some stopped at T_min


def test_classify_prints_table_and_json(model_dir, nights_csv):
    done = run_cli("classify", "--nights", str(nights_csv), "--model-dir", str(model_dir))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    # 3 days × the population's plans: 1 constrained + 1 per normal setpoint (the gateway's)
    n_normal = 3 * len(DEFAULT_SETPOINTS_C)
    assert lines[0] == f"{3 + n_normal} nights: 3 constrained, {n_normal} normal"
    assert [ln.split()[0] for ln in lines[2:]] == ["floor_area", "c_f", "u_walls"]
    done = run_cli("classify", "--nights", str(nights_csv), "--model-dir", str(model_dir),
                   "--json")
    data = json.loads(done.stdout)
    for name in ("floor_area", "c_f", "u_walls"):
        cls = data["classes"][name]
        assert cls["range"][0] < cls["range"][1] and 0 < cls["probability"] <= 1
        assert cls["probability"] == max(cls["probabilities"].values())
    assert data["nights"]["constrained"] == 3


def _one_error_line(done: subprocess.CompletedProcess, *words: str) -> str:
    assert done.returncode == 2 and done.stdout == ""
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    for w in words:
        assert w in lines[0]
    return lines[0]


def test_classify_bad_file_names_file_and_row(tmp_path, model_dir):
    bad = tmp_path / "bad.csv"
    bad.write_text("timestamp,t_air,t_out,q_hc\n2026-01-12T22:00,22,1,2000\n"
                   "2026-01-12T22:10,22,x,2000\n")
    _one_error_line(run_cli("classify", "--nights", str(bad), "--model-dir", str(model_dir)),
                    str(bad), "row 3", "'t_out'")
    _one_error_line(run_cli("classify", "--nights", str(tmp_path / "none.csv")),
                    "file not found")


def test_classify_without_models_says_to_train(tmp_path, nights_csv):
    _one_error_line(run_cli("classify", "--nights", str(nights_csv), env_home=tmp_path),
                    "no trained models", "impctl train")


def test_train_bad_input_writes_nothing(tmp_path):
    out = tmp_path / "out"
    _one_error_line(run_cli("train", "--households", "5", "--out", str(out)), "--households")
    weather = tmp_path / "w.csv"
    weather.write_text("timestamp,t_out\n2026-01-12T00:00,1.0\n2026-01-12T01:00,warm\n")
    _one_error_line(run_cli("train", "--weather", str(weather), "--out", str(out)),
                    str(weather), "row 3")
    weather.write_text("timestamp,t_out\n2026-01-12T00:00,1.0\n2026-01-12T01:00,1.0\n")
    _one_error_line(run_cli("train", "--weather", str(weather), "--out", str(out)),
                    "usable nights")
    assert not out.exists()


def test_demo_retrains_models_of_another_night_protocol(model_dir, tmp_path):
    """The demo reuses cached classifiers only when their population ran the gateway's nights
    (since branch h14q: one constrained setpoint); models from the old population, whose
    manifest has no constrained_setpoint_c, are retrained; so are models of another plant's
    population (or of an unrecorded one), with the mismatch named."""
    import shutil

    from impctl.demo.run import _models_unfit

    def ok(path: Path) -> bool:  # `impctl train`'s default population: the realistic plant's
        return _models_unfit(path, "realistic") is None

    assert ok(model_dir)
    # Never for the other plant's demo: the mismatch is named.
    assert _models_unfit(model_dir, "iso") == (
        "they were trained for the realistic plant's population, the demo simulates the iso "
        "plant")
    old = shutil.copytree(model_dir, tmp_path / "old")
    meta = json.loads((old / "models.json").read_text())
    del meta["dataset"]["imp"]["constrained_setpoint_c"]
    (old / "models.json").write_text(json.dumps(meta))
    assert not ok(old)
    meta["dataset"]["imp"]["constrained_setpoint_c"] = DEFAULT_CONSTRAINED_SETPOINT_C + 1.0
    (old / "models.json").write_text(json.dumps(meta))
    assert not ok(old)
    # Since h14x the population's constrained nights stop at T_min as the gateway's do: models
    # of nights cooled to the window's end (stop_at_t_min false, or a manifest without the key,
    # from before h14r) are retrained.
    meta["dataset"]["imp"]["constrained_setpoint_c"] = DEFAULT_CONSTRAINED_SETPOINT_C
    for stale in (False, None):
        if stale is None:
            del meta["dataset"]["imp"]["stop_at_t_min"]
        else:
            meta["dataset"]["imp"]["stop_at_t_min"] = stale
        (old / "models.json").write_text(json.dumps(meta))
        assert not ok(old)
    meta["dataset"]["imp"]["stop_at_t_min"] = True
    (old / "models.json").write_text(json.dumps(meta))
    assert ok(old)
    # A manifest that does not record its plant is not reused either.
    del meta["dataset"]["plant"]
    (old / "models.json").write_text(json.dumps(meta))
    assert _models_unfit(old, "realistic") == (
        "they were trained for the unrecorded plant's population, the demo simulates the "
        "realistic plant")


def test_demo_checks_cached_models_as_impctl_fit_loads_them(model_dir, tmp_path):
    """Whether the demo may reuse cached classifiers is read from what ``impctl fit`` loads —
    the compact forests — without importing scikit-learn or unpickling the forests (seconds
    of every demo); with the pickles damaged but the compact forests whole, fit still works,
    and so the demo reuses them."""
    import shutil

    assert json.loads((model_dir / "models.json").read_text())["compact"]
    damaged = shutil.copytree(model_dir, tmp_path / "damaged")
    for pickled in damaged.glob("*.joblib"):
        pickled.write_bytes(b"not a pickle")
    probe = ("import sys; from pathlib import Path; from impctl.demo.run import _models_unfit; "
             "print([_models_unfit(Path(d), 'realistic') for d in sys.argv[1:]], "
             "'sklearn' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", probe, str(model_dir), str(damaged)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[None, None] False"


def _with_setpoint(src: Path, dst: Path, night_ids, setpoint_c: float) -> Path:
    table = pd.read_csv(src)
    table.loc[table["night"].isin(night_ids), "setpoint"] = setpoint_c
    table.to_csv(dst, index=False)
    return dst


def test_classify_leaves_out_nights_at_setpoints_never_trained_on(model_dir, nights_csv,
                                                                  tmp_path):
    # A normal night at 20 °C is not a night of the classifiers' population: its features
    # would put the house into a class for the wrong reason, so it is left out and named.
    table = pd.read_csv(nights_csv)
    normal = table.loc[table["kind"] == "normal", "night"].unique()
    moved = _with_setpoint(nights_csv, tmp_path / "moved.csv", normal[:1], 20.0)
    done = run_cli("classify", "--nights", str(moved), "--model-dir", str(model_dir), "--json")
    assert done.returncode == 0, done.stderr
    data = json.loads(done.stdout)
    left = data["classes"]["c_f"]["nights_left_out"]
    assert len(left) == 1 and "normal at 20 °C" in left[0]
    table_done = run_cli("classify", "--nights", str(moved), "--model-dir", str(model_dir))
    assert "left out (setpoint the classifiers were never trained on)" in table_done.stdout
    # The unchanged export leaves nothing out.
    plain = json.loads(run_cli("classify", "--nights", str(nights_csv), "--model-dir",
                               str(model_dir), "--json").stdout)
    assert "nights_left_out" not in plain["classes"]["c_f"]
    # Every night off the protocol: one line, exit 2, nothing classified.
    every = _with_setpoint(nights_csv, tmp_path / "every.csv", table["night"].unique(), 19.0)
    line = _one_error_line(run_cli("classify", "--nights", str(every), "--model-dir",
                                   str(model_dir)), "no night ran at a setpoint")
    assert f"normal nights at {'/'.join(f'{s:g}' for s in DEFAULT_SETPOINTS_C)} °C" in line
    assert f"constrained nights at {DEFAULT_CONSTRAINED_SETPOINT_C:g} °C" in line


#: Runs the CLI, then names on its last stderr line which heavy libraries it had loaded.
_LOADED = ("import sys\ntry:\n    from impctl.cli import main\n    main()\nfinally:\n"
           "    print('loaded:', *sorted(m for m in ('sklearn', 'torch') if m in sys.modules),"
           " file=sys.stderr)")


def refused_and_loaded(*args: str) -> tuple[str, str]:
    """(the one error line, the last line naming the heavy libraries loaded) of a refused
    command."""
    done = subprocess.run([sys.executable, "-c", _LOADED, *args], capture_output=True,
                          text=True, timeout=300)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and done.stdout == "" and len(lines) == 2, done.stderr
    return lines[0], lines[1]


def test_bad_input_is_refused_before_scikit_learn_is_loaded(tmp_path):
    """A mistyped option is told in a moment, not after scikit-learn's and torch's imports."""
    error, loaded = refused_and_loaded("train", "--households", "5", "--out",
                                       str(tmp_path / "out"))
    assert "--households" in error and loaded == "loaded:"
    error, loaded = refused_and_loaded("fit", "--nights", str(tmp_path / "n.csv"),
                                       "--night-gain-sd-w", "40")
    assert "--night-gain-w" in error and loaded == "loaded:"
