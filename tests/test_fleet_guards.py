"""``impctl fleet fit`` takes each household as ``impctl fit`` takes its file — the same
refusals with the same line, the same numbers — and keeps its output safe: a size guard per
household, no output inside the input, a manifest that marks an interrupted run partial, one
line for a malformed scheduler, no scikit-learn warnings. Real subprocesses, a real local Dask
cluster of worker processes, real files."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from cli_fixtures import run_impctl

from impctl.errors import InputError
from impctl.fleet.results.lock import LOCK_FILE, holding
from impctl.imp import write_nights

#: The fleet and impctl fit both fit at most this many nights (a third constrained): less than
#: the five each household has, so the choice of nights is exercised.
MAX_NIGHTS = "4"


#: The math libraries' threads of a Dask worker process (distributed's nanny sets them so):
#: the summation order of numpy's BLAS, and so the last digits of a fit, depend on them.
ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def run_impctl_process(*args: str, cwd: Path | None = None, env: dict | None = None
                       ) -> subprocess.CompletedProcess:
    """A real ``impctl`` process: where its environment (math-library threads) or what its
    interpreter prints (warnings) is part of the check."""
    return subprocess.run([sys.executable, "-c", "from impctl.cli import main; main()", *args],
                          capture_output=True, text=True, timeout=600, cwd=cwd,
                          env={**os.environ, **(env or {})})


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return run_impctl(*args, cwd=cwd)  # in this process: the output is checked


#: The command's Ctrl-C as a terminal gives it: a test run started in the background
#: (``cmd &`` in a script, nohup) passes SIGINT on ignored, and Python then keeps it ignored —
#: the run finished with the signal lost.
_CLI = ("import signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
        "from impctl.cli import main; main()")


def start_cli(*args: str, cwd: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", _CLI, *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd)


@pytest.fixture(scope="module")
def nights(two_fleet_households):
    return two_fleet_households


@pytest.fixture(scope="module")
def pickled_models(tmp_path_factory, trained_models) -> Path:
    """Trained classifiers without their compact arrays: the workers load the pickled
    scikit-learn forests (the path that warned in every batch)."""
    out = shutil.copytree(trained_models.out, tmp_path_factory.mktemp("models") / "models")
    (out / "forests.npz").unlink()
    meta = json.loads((out / "models.json").read_text())
    meta.pop("compact", None)
    (out / "models.json").write_text(json.dumps(meta))
    return out


def _in_kw(path: Path, nights, only_normal: int | None = None) -> None:
    """Write ``nights`` with q_hc in kW: every night, or the first ``only_normal`` normal ones."""
    write_nights(nights, path)
    table = pd.read_csv(path)
    normal = sorted(table.loc[table["kind"] == "normal", "night"].unique())
    rows = (table["night"].isin(normal[:only_normal]) if only_normal is not None
            else np.ones(len(table), bool))
    table.loc[rows, "q_hc"] = table.loc[rows, "q_hc"] / 1000.0
    table.to_csv(path, index=False)


@pytest.fixture(scope="module")
def work(tmp_path_factory, nights) -> Path:
    """A working folder holding the fleet's INPUT folder ``in``; paths are given relative to
    it, so the fleet's rows and impctl fit name a file the same way."""
    root = tmp_path_factory.mktemp("work")
    d = root / "in"
    d.mkdir()
    write_nights(nights[0], d / "house-a.csv")
    # house-b with an hour missing in a normal night (the fit keeps its longest piece)
    write_nights(nights[1], d / "gappy.csv")
    table = pd.read_csv(d / "gappy.csv")
    stamp = pd.to_datetime(table["timestamp"], utc=True)
    night = sorted(table.loc[table["kind"] == "normal", "night"].unique())[1]
    first = stamp[table["night"] == night].min()
    gap = (table["night"] == night) & (stamp > first + pd.Timedelta("2h")) & (
        stamp < first + pd.Timedelta("3h"))
    table[~gap].to_csv(d / "gappy.csv", index=False)
    _in_kw(d / "kw.csv", nights[0])
    _in_kw(d / "kw-some.csv", nights[0], only_normal=2)
    # 300 MB on disk (sparse: no disk space used); read, it would fill a worker's memory
    with open(d / "big.csv", "w") as fh:
        fh.write("timestamp,t_air,t_out,q_hc\n")
        fh.truncate(300 * 10**6)
    return root


@pytest.fixture(scope="module")
def fleet(work, pickled_models):
    done = run_impctl_process("fleet", "fit", "in", "--out", "FLEET.parquet", "--workers",
                              "1", "--model-dir", str(pickled_models), "--max-nights",
                              MAX_NIGHTS, cwd=work)
    assert done.returncode == 0, done.stderr
    table = pd.read_parquet(work / "FLEET.parquet").set_index("household")
    return table, done


def test_no_scikit_learn_warning_before_the_progress_bar(fleet):
    _, done = fleet
    assert "5 households: 5 fitted now (2 ok, 0 insufficient, 3 error)" in done.stdout
    assert "Warning" not in done.stderr and "n_jobs" not in done.stderr, done.stderr


@pytest.mark.parametrize("household", ["kw", "kw-some", "big"])
def test_the_fleet_refuses_what_impctl_fit_refuses_with_the_same_line(fleet, work,
                                                                    pickled_models, household):
    table, _ = fleet
    alone = run_cli("fit", "--nights", f"in/{household}.csv", "--model-dir",
                    str(pickled_models), "--max-nights", MAX_NIGHTS, cwd=work)
    assert alone.returncode == 2, alone.stdout + alone.stderr
    line = alone.stderr.strip()
    assert len(line.splitlines()) == 1 and line.startswith("impctl: in/")
    row = table.loc[household]
    assert row["status"] == "error" and np.isnan(row["hlc_w_per_k"])
    assert row["error"] == line.removeprefix("impctl: ")
    expected = {"kw": "implausible units", "kw-some": "implausible units", "big": "too large"}
    assert row["reason"] == expected[household]
    if household.startswith("kw"):
        assert "q_hc looks like kW" in row["error"]


@pytest.mark.parametrize("household", ["house-a", "gappy"])
def test_a_fleet_row_equals_impctl_fit_on_the_same_file(fleet, work, pickled_models,
                                                        household, tmp_path):
    """The fleet's numbers are impctl fit's: the same nights chosen (cut at the gap, the most
    recent --max-nights), classes, prior and fit; only the optimiser calls are merged. With
    the worker's one math-library thread they are the same to the last digits (with numpy's
    BLAS on two threads impctl fit's HLC here differs in the 5th digit, 3e-5)."""
    table, _ = fleet
    alone = run_impctl_process("fit", "--nights", f"in/{household}.csv", "--model-dir",
                               str(pickled_models), "--max-nights", MAX_NIGHTS, "--json",
                               str(tmp_path / "fit.json"), cwd=work, env=ONE_THREAD)
    assert alone.returncode == 0, alone.stderr
    fit = json.loads((tmp_path / "fit.json").read_text())
    row = table.loc[household]
    assert row["status"] == "ok"
    assert row["nights_used"] == 4 and row["nights_constrained"] == 1
    assert "--max-nights 4" in " ".join(fit["notes"])
    for key, col in (("hlc", "hlc_w_per_k"), ("c_m", "c_m_j_per_k"), ("tau", "tau_h")):
        # the same numbers: a merged optimiser call keeps each household's problem apart
        # (fit.optim.batch)
        for part, suffix in (("value", ""), ("low", "_low"), ("high", "_high")):
            assert row[f"{col}{suffix}"] == pytest.approx(fit["lumped"][key][part], rel=1e-12)
    assert {c["source"] for c in fit["classes"].values()} == {"classifier"}
    assert row["floor_area_class"] and row["c_f_class"] and row["u_walls_class"]


def test_a_household_s_parquet_rows_are_counted_before_they_are_read(tmp_path, nights,
                                                                    monkeypatch):
    """A Parquet household (its own file, or its rows of a shared dataset) with more rows
    than the limit is refused from the metadata; its rows are never parsed."""
    import impctl.imp.files.limits
    from impctl.fleet.inputs import discover, read_sources

    write_nights(nights[0], tmp_path / "a.csv")
    frame = pd.read_csv(tmp_path / "a.csv")
    limit = len(frame) - 1
    monkeypatch.setattr(impctl.imp.files.limits, "MAX_ROWS", limit)
    d = tmp_path / "files"
    d.mkdir()
    bad = frame.copy()
    bad["t_air"] = 999.0  # read, it would be refused as implausible
    bad.to_parquet(d / "many.parquet")
    frame.iloc[:limit].to_parquet(d / "fits.parquet")
    got = read_sources(discover(d), "Europe/Ljubljana")
    assert got["many"].reason == "too large" and f"{len(frame):,} rows" in str(got["many"])
    assert isinstance(got["fits"], list) and got["fits"]
    shared = pd.concat([bad.assign(household="many"),
                        frame.iloc[:limit].assign(household="fits")])
    shared.to_parquet(tmp_path / "all.parquet")
    got = read_sources(discover(tmp_path / "all.parquet"), "Europe/Ljubljana")
    assert got["many"].reason == "too large" and "(household many)" in str(got["many"])
    assert isinstance(got["fits"], list) and got["fits"]


def _listing(d: Path) -> list[str]:
    return sorted(str(p.relative_to(d)) for p in d.rglob("*"))


def test_output_overlapping_the_input_is_refused_and_no_advice_leads_into_a_trap(work):
    before = _listing(work / "in")
    for out in ("in", "in/FLEET.parquet", "."):
        done = run_cli("fleet", "fit", "in", "--out", out, cwd=work)
        assert done.returncode == 2, done.stdout + done.stderr
        assert len(done.stderr.strip().splitlines()) == 1, done.stderr
        assert "would be read as households" in done.stderr and "--resume" not in done.stderr
    again = run_cli("fleet", "fit", "in", "--out", "in", "--resume", cwd=work)
    assert again.returncode == 2 and "would be read as households" in again.stderr
    assert _listing(work / "in") == before
    # a folder that is no FLEET dataset: never "pass --resume"
    (work / "notes").mkdir(exist_ok=True)
    (work / "notes" / "todo.txt").write_text("x")
    for extra in ((), ("--resume",)):
        done = run_cli("fleet", "fit", "in", "--out", "notes", *extra, cwd=work)
        assert done.returncode == 2 and "not a FLEET dataset" in done.stderr
        assert "--resume" not in done.stderr
    assert _listing(work / "notes") == ["todo.txt"]
    report = run_cli("fleet", "fit", "in", "--out", "F2", "--report", "F2/report", cwd=work)
    assert report.returncode == 2 and "--report" in report.stderr
    assert not (work / "F2").exists()


@pytest.mark.parametrize("address", ["nonsense", "tcp://127.0.0.1:abc", "foo://h:1",
                                     "tcp://h:99999"])
def test_a_malformed_scheduler_is_one_line(work, address):
    done = run_cli("fleet", "fit", "in", "--out", "F3", "--scheduler", address, cwd=work)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [done.stderr.strip()]
    assert "--scheduler" in done.stderr and "Traceback" not in done.stderr
    assert not (work / "F3").exists()


#: Households of the interrupted run: each costs a fit (~2 CPU-s) in the run or its resume.
CTRL_C_HOUSES = 4


def test_ctrl_c_leaves_a_dataset_marked_partial(tmp_path, nights, pickled_models):
    from impctl.report.fleet import write_fleet_report

    src = tmp_path / "in"
    src.mkdir()
    # four households, one at a time: the Ctrl-C, sent within 50 ms of the first part, lands
    # with work left however late the loaded machine delivers it (it would have to wait for
    # three more fits of ~2 CPU-s each to find none)
    for i in range(CTRL_C_HOUSES):
        write_nights(nights[i % 2], src / f"h{i}.csv")
    out = tmp_path / "FLEET.parquet"
    args = ("fleet", "fit", "in", "--out", "FLEET.parquet", "--workers", "1", "--batch-size",
            "1", "--model-dir", str(pickled_models), "--quiet")
    proc = start_cli(*args, cwd=tmp_path)
    deadline = time.monotonic() + 300
    while not list(out.glob("part-*.parquet")):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    # the run holds its dataset's lock while it writes (itself, not its workers)
    with pytest.raises(InputError, match=rf"another fleet run \(process {proc.pid}\)"):
        with holding(out):
            pass
    proc.send_signal(signal.SIGINT)  # Ctrl-C
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stdout + stderr
    manifest = json.loads((out / "_manifest.json").read_text())
    rows = len(pd.read_parquet(out))
    assert manifest["complete"] is False and manifest["households"] == CTRL_C_HOUSES
    assert manifest["done"] == rows and 1 <= rows < CTRL_C_HOUSES
    assert f"interrupted: partial: {rows} of {CTRL_C_HOUSES} households" in stdout
    # the advice printed is the command that finishes it
    assert f"impctl fleet fit {src.resolve()} --out FLEET.parquet --resume" in stdout
    flex = run_cli("flex", "FLEET.parquet", cwd=tmp_path)
    assert flex.returncode == 0, flex.stderr
    assert f"partial: {rows} of {CTRL_C_HOUSES} households" in flex.stdout.splitlines()[0]
    as_json = run_cli("flex", "FLEET.parquet", "--json", cwd=tmp_path)
    assert f"partial: {rows} of {CTRL_C_HOUSES} households" in as_json.stderr
    json.loads(as_json.stdout)  # stdout stays JSON
    page = write_fleet_report(out, tmp_path / "report").read_text()
    assert f"partial: {rows} of {CTRL_C_HOUSES} households" in page
    resumed = run_cli(*args, "--resume", cwd=tmp_path)
    assert resumed.returncode == 0, resumed.stderr
    assert json.loads((out / "_manifest.json").read_text())["complete"] is True
    assert sorted(pd.read_parquet(out)["household"]) == [f"h{i}" for i in range(CTRL_C_HOUSES)]
    flex = run_cli("flex", "FLEET.parquet", cwd=tmp_path)
    assert "partial" not in flex.stdout + flex.stderr
    shutil.rmtree(tmp_path / "report")


def test_a_part_written_before_the_manifest_counts(tmp_path):
    """A run stopped between a part's rename and the manifest's rewrite: readers count the
    part file's rows, not the manifest's stale number."""
    from impctl.fleet.results.manifest import Manifest, completeness, read_manifest, write_manifest
    from impctl.fleet.results.table import empty_row, write_part

    out = tmp_path / "F"
    write_manifest(out, Manifest(input="in", options={}, households=4, done=0))
    write_part(out, "abcd1234", 0, [empty_row("h0"), empty_row("h1")])
    assert read_manifest(out).done == 0  # the file itself is one batch behind
    assert completeness(out).startswith("partial: 2 of 4 households")


def test_resume_with_other_options_is_refused(tmp_path, nights):
    from impctl.fleet.results.manifest import Manifest, write_manifest

    src = tmp_path / "in"
    src.mkdir()
    write_nights(nights[0], src / "h0.csv")
    out = tmp_path / "F"
    write_manifest(out, Manifest(input=str(src.resolve()), households=1, done=0, options={
        "normal_model": "demand", "timestamps": "instant", "ach_infl": 0.01, "ach_vent": 0.0,
        "max_nights": 30, "night_gain_w": 250.0, "tz": "Europe/Ljubljana",
        "model_dir": "prior"}))
    done = run_impctl("fleet", "fit", "in", "--out", "F", "--resume", "--max-nights", "10",
                      cwd=tmp_path, env={"IMPCTL_MODEL_DIR": str(tmp_path / "no-models")})
    assert done.returncode == 2, done.stderr
    assert "max_nights 30" in done.stderr and "give a new --out" in done.stderr
    assert not list(out.glob("part-*"))


def test_a_dataset_without_manifest_is_not_called_complete(tmp_path):
    from impctl.fleet.results.manifest import completeness
    from impctl.fleet.results.table import empty_row, write_part

    write_part(tmp_path / "F", "abcd1234", 0, [empty_row("h0")])
    line = completeness(tmp_path / "F")
    assert line is not None and line.startswith("completeness unknown: no _manifest.json")


def test_fleet_output_is_never_read_as_households(tmp_path, nights):
    """Parts left in a folder of nights (or a FLEET dataset given as INPUT) would be phantom
    households: refused with one line saying what to move."""
    from impctl.errors import InputError
    from impctl.fleet.inputs import discover
    from impctl.fleet.results.table import empty_row, write_part

    d = tmp_path / "in"
    d.mkdir()
    write_nights(nights[0], d / "h0.csv")
    assert [s.household for s in discover(d)] == ["h0"]
    write_part(d, "abcd1234", 0, [empty_row("h0")])
    with pytest.raises(InputError, match="holds the output of impctl fleet fit"):
        discover(d)
    write_part(tmp_path / "F", "abcd1234", 0, [empty_row("h0")])
    with pytest.raises(InputError, match="part-abcd1234-000000.parquet"):
        discover(tmp_path / "F")


#: Holds a dataset's lock as a run does, until killed.
_HOLDER = """
import sys, time
from pathlib import Path
from impctl.fleet.results.lock import holding
with holding(Path(sys.argv[1])):
    print("held", flush=True)
    time.sleep(600)
"""


def test_one_run_at_a_time_writes_a_dataset(work, tmp_path):
    """A second run on an ``--out`` another run holds is one line, exit 2, nothing written,
    whether it would start the dataset or resume it; a killed holder leaves no lock behind."""
    out = tmp_path / "FLEET.parquet"
    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, str(out)],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        for extra in ((), ("--resume",)):
            res = run_cli("fleet", "fit", "in", "--out", str(out), "--workers", "1", *extra,
                          cwd=work)
            assert res.returncode == 2, res.stdout + res.stderr
            line, = res.stderr.strip().splitlines()
            assert f"is being written by another fleet run (process {holder.pid})" in line
            assert str(out) in line
            assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE]
    finally:
        holder.kill()
        holder.wait(timeout=30)
    with holding(out):  # the kernel let go of the killed holder's lock
        pass


def test_a_refused_run_leaves_no_new_dataset_behind(work, tmp_path):
    """A check that fails under the lock (here: INPUT without households) removes the ``--out``
    folder the lock created: a refused run writes nothing."""
    (tmp_path / "empty").mkdir()
    out = tmp_path / "NEW.parquet"
    res = run_cli("fleet", "fit", str(tmp_path / "empty"), "--out", str(out), cwd=work)
    assert res.returncode == 2 and "no NIGHTS file" in res.stderr, res.stderr
    assert not out.exists()
