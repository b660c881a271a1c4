"""``impctl fleet fit`` keeps each row its household's and its run's: ids of a partitioned
dataset as written, one household's unreadable file not failing its batch, classifiers trained
anew not mistaken for the old, a resume refusing rows of other code or unknown options, a lost
worker's batch fitted again, an interrupted resume not called complete.

Small synthetic households (the two houses of ``test_fleet.py``, 15-minute samples), a real
local Dask cluster of one worker process (one test: an in-process cluster), real Parquet
datasets on disk.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from cli_fixtures import run_impctl
from test_fleet import HOUSES, _frame

from impctl.errors import InputError
from impctl.fit.household import FitOptions
from impctl.fleet import fit_fleet, read_fleet
from impctl.imp import write_nights
from impctl.population.imp_run.synth import imp_schedule, run_schedule, sample_nights

TZ = "Europe/Ljubljana"


@pytest.fixture(scope="module")
def nights():
    sched = imp_schedule(2, n_constrained=2, n_normal=3, seed=5)
    sim, sp = run_schedule(HOUSES, sched)
    return [sample_nights(sim, sp, sched, i, sample_step_s=900.0, seed=i) for i in range(2)]


def quiet(_line: str) -> None:
    pass


@pytest.fixture(scope="module")
def client():
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address="127.0.0.1:0") as cluster, Client(cluster) as c:
        yield c


@pytest.fixture(scope="module")
def other_models(tmp_path_factory) -> Path:
    """Classifiers as ``impctl train`` writes them on another day (seed 9, not the shared
    fixture's seed 4): they put house 0 into another floor-area class."""
    out = tmp_path_factory.mktemp("retrained") / "models"
    done = run_impctl("train", "--households", "20", "--seed", "9", "--out", str(out))
    assert done.returncode == 0, done.stderr
    return out


def _normal_only(nights, path: Path) -> None:
    """A household without a constrained night: ``insufficient``, no fit (cheap)."""
    write_nights([n for n in nights if n.kind == "normal"], path)


def _expected_class(path: Path, model_dir: Path) -> str:
    """The floor-area class ``impctl fit`` gives the file with the classifiers now in
    ``model_dir`` (in this process, read fresh)."""
    from impctl.fit.household import choose_nights, household_classes
    from impctl.imp.files.nights_csv import read_nights

    cut = choose_nights(read_nights(path, TZ), FitOptions().max_nights).cut
    return household_classes(cut, model_dir).labels["floor_area"]


def _retrain_in_place(model_dir: Path, retrained: Path) -> None:
    """What ``impctl train --out MODEL_DIR`` does to a directory a fleet reads: new files,
    same path."""
    shutil.rmtree(model_dir)
    shutil.copytree(retrained, model_dir)


# --- 1. household ids of a hive-partitioned dataset --------------------------------------


def test_hive_partitioned_household_ids_keep_their_text(tmp_path, nights):
    """A dataset partitioned by household (``df.to_parquet(path, partition_cols=["household"])``,
    the hive layout the docs accept) whose ids look like numbers: pyarrow infers the partition
    key as int32, so ``01`` and ``1`` become the same household 1 (one row with both houses'
    nights, the other household gone) and ``007`` is reported as ``7``."""
    from impctl.fleet.inputs import discover, read_sources

    frame = pd.concat([_frame(nights[0]).assign(household="01"),
                       _frame(nights[1]).assign(household="1"),
                       _frame(nights[0]).assign(household="007")], ignore_index=True)
    path = tmp_path / "fleet"
    frame.to_parquet(path, partition_cols=["household"], index=False)
    assert sorted(p.name for p in path.iterdir()) == [
        "household=007", "household=01", "household=1"]
    sources = discover(path)
    got = read_sources(sources, TZ)
    per_household = {h: (len(v) if isinstance(v, list) else str(v)) for h, v in got.items()}
    assert sorted(s.household for s in sources) == ["007", "01", "1"], per_household


# --- 2. one household's unreadable file, not its whole batch --------------------------------


def test_one_households_out_of_range_timestamp_does_not_fail_its_batchmates(tmp_path, nights,
                                                                           client):
    """A household whose file has one timestamp past pandas' nanosecond range (2300) raises
    OutOfBoundsDatetime out of the reader — not an InputError — so the per-household guard in
    ``read_sources`` lets it through and the whole batch becomes "worker failed" rows: its
    batch-mate (a plain ``insufficient`` household) loses its row's content, and the error
    names no file."""
    src = tmp_path / "in"
    src.mkdir()
    write_nights(nights[0], src / "a-late.csv")
    table = pd.read_csv(src / "a-late.csv")
    table.loc[table.index[-1], "timestamp"] = "2300-01-01T00:00:00Z"
    table.to_csv(src / "a-late.csv", index=False)
    for h in ("b", "c", "d"):   # four households on one worker, batch size 2: [a, b], [c, d]
        _normal_only(nights[1], src / f"{h}-normal.csv")
    fit_fleet(src, tmp_path / "F", client=client, batch_size=2, model_dir=None,
              progress=False, echo=quiet)
    rows = read_fleet(tmp_path / "F").set_index("household")
    mate = rows.loc["b-normal"]
    late = rows.loc["a-late"]
    assert (mate["status"], mate["reason"]) == (
        rows.loc["c-normal", "status"], rows.loc["c-normal", "reason"]), (
        mate["status"], mate["reason"], mate["error"])
    assert late["status"] == "error" and "a-late.csv" in late["error"], late["error"]


# --- 3. classifiers retrained in place: --previous fits again ---------------------------


def _fitted_then_retrained(tmp_path, nights, client, trained_models, other_models):
    """(input, model dir, h0's row of a first run, the class the classifiers trained anew in
    that directory give h0): a run with one set of classifiers, then ``impctl train``'s new
    ones written into the same folder."""
    src = tmp_path / "in"
    src.mkdir()
    write_nights(nights[0], src / "h0.csv")
    models = shutil.copytree(trained_models.out, tmp_path / "models")
    fit_fleet(src, tmp_path / "F1", client=client, model_dir=models, progress=False,
              echo=quiet)
    before = read_fleet(tmp_path / "F1").set_index("household").loc["h0"]
    _retrain_in_place(models, other_models)
    now = _expected_class(src / "h0.csv", models)
    assert now != before["floor_area_class"]   # the retrained classifiers classify otherwise
    return src, models, before, now


def test_previous_is_not_carried_over_after_the_classifiers_were_retrained(
        tmp_path, nights, client, trained_models, other_models):
    """``--previous`` keeps an IMP fit only "fitted there with the same … classifiers", but
    compares the model directory's *path* only: after ``impctl train`` wrote new classifiers
    into the same directory (the default per-user directory is always the same path), the
    old run's classes and the fit made with them are carried over as this run's."""
    src, models, before, now = _fitted_then_retrained(tmp_path, nights, client,
                                                      trained_models, other_models)
    fit_fleet(src, tmp_path / "F2", client=client, model_dir=models, previous=tmp_path / "F1",
              progress=False, echo=quiet)
    row = read_fleet(tmp_path / "F2").set_index("household").loc["h0"]
    assert (bool(row["imp_fit_reused"]), row["floor_area_class"]) == (False, now), (
        f"carried over: imp_fit_reused={row['imp_fit_reused']}, class "
        f"{row['floor_area_class']!r} of the old classifiers; these give {now!r}")


# --- 4. a worker's classifiers follow their folder -----------------------------------------


def test_a_workers_classifiers_follow_the_directory_they_are_read_from(
        tmp_path, nights, client, trained_models, other_models):
    """On a cluster that outlives a run (``--scheduler``, the docs' every-morning setup), a
    worker caches the classifiers by directory path: after ``impctl train`` rewrote the
    directory, a full run (no ``--previous``) still classifies with the old forests, while a
    worker that joins later (or ``impctl fit``) reads the new ones — one FLEET, two sets of
    classifiers under one ``model_dir`` in the manifest."""
    src, models, before, now = _fitted_then_retrained(tmp_path, nights, client,
                                                      trained_models, other_models)
    old = before["floor_area_class"]
    assert now != old
    fit_fleet(src, tmp_path / "F2", client=client, model_dir=models, progress=False,
              echo=quiet)
    got = read_fleet(tmp_path / "F2").set_index("household").loc["h0", "floor_area_class"]
    assert got == now, f"classified with the cached old classifiers: {got!r}, now {now!r}"


# --- 5. --resume and rows of other code -----------------------------------------------------


def _two_part_fleet(tmp_path, nights, client, **kw) -> tuple[Path, Path, Path]:
    """A finished two-household FLEET (h0 fitted, h1 insufficient), one part each."""
    src = tmp_path / "in"
    src.mkdir()
    write_nights(nights[0], src / "h0.csv")
    _normal_only(nights[1], src / "h1.csv")
    out = tmp_path / "F"
    fit_fleet(src, out, client=client, model_dir=None, progress=False, echo=quiet, **kw)
    parts = sorted(out.glob("part-*.parquet"))
    assert len(parts) == 2
    by = {pq.read_table(p).column("household")[0].as_py(): p for p in parts}
    return src, by["h0"], by["h1"]


def test_resume_does_not_mix_rows_of_other_code(tmp_path, nights, client):
    """Interrupted, the code updated (a checkout, an editable install, a new release), then
    ``--resume``: the old rows stay, the new households are fitted by the new code, and one
    dataset holds two ``impctl_version``s — what ``--previous`` refuses to mix
    (:func:`impctl.fleet.results.table.version`). Nothing refuses it or refits the rows."""
    from impctl.fleet.results.table import version

    src, h0_part, h1_part = _two_part_fleet(tmp_path, nights, client)
    older = version().rsplit("+src.", 1)[0] + "+src.00000000"
    table = pq.read_table(h0_part)
    pq.write_table(table.set_column(table.schema.get_field_index("impctl_version"),
                                    "impctl_version",
                                    pa.array([older], pa.string())),
                   h0_part)   # h0's row as the code before the update wrote it
    h1_part.unlink()          # the run was interrupted before h1's batch
    try:
        fit_fleet(src, tmp_path / "F", client=client, model_dir=None, resume=True,
                  progress=False, echo=quiet)
    except InputError:
        return   # refused: fine
    versions = sorted(set(read_fleet(tmp_path / "F")["impctl_version"]))
    assert versions == [version()], f"one dataset, rows of two codes: {versions}"


# --- 6. --resume of a dataset without its manifest ------------------------------------------


def test_resume_without_a_manifest_does_not_adopt_rows_of_other_options(tmp_path, nights,
                                                                      client):
    """A FLEET dataset whose manifest is gone (a copy that left it behind, a dataset written
    before manifests: both named by :func:`completeness`) is resumed with any options: the
    run writes a new manifest claiming its options for rows fitted with others."""
    src, _h0_part, h1_part = _two_part_fleet(tmp_path, nights, client,
                                             options=FitOptions(max_nights=4))
    out = tmp_path / "F"
    assert read_fleet(out).set_index("household").loc["h0", "nights_used"] == 4
    (out / "_manifest.json").unlink()
    h1_part.unlink()
    with pytest.raises(InputError):
        fit_fleet(src, out, client=client, model_dir=None, resume=True, progress=False,
                  echo=quiet)   # default options: max_nights 30


# --- 7. "complete" counts the input's households only -----------------------------------------


def test_an_interrupted_resume_is_not_called_complete_while_a_household_is_missing(
        tmp_path, nights, client, monkeypatch):
    """The input's households changed between the run and its resume (one left the
    portfolio, one joined). The resume is interrupted before the new household's batch:
    ``recount`` counts every household id in the parts — the departed one included — so the
    manifest and every reader say "complete: 2 households" while the new one has no row."""
    import impctl.fleet.run as run_module
    from impctl.fleet.results.manifest import completeness

    src = tmp_path / "in"
    src.mkdir()
    _normal_only(nights[1], src / "a.csv")
    _normal_only(nights[1], src / "b.csv")
    out = tmp_path / "F"
    fit_fleet(src, out, client=client, model_dir=None, progress=False, echo=quiet)
    (src / "b.csv").unlink()
    _normal_only(nights[1], src / "c.csv")

    def interrupted(*_a, **_k):
        raise KeyboardInterrupt   # Ctrl-C while c's batch runs

    monkeypatch.setattr(run_module, "_collect", interrupted)
    said: list[str] = []
    with pytest.raises(KeyboardInterrupt):
        fit_fleet(src, out, client=client, model_dir=None, resume=True, progress=False,
                  echo=said.append)
    assert "c" not in set(read_fleet(out)["household"])
    manifest = json.loads((out / "_manifest.json").read_text())
    assert (manifest["complete"], completeness(out)) != (True, None), (said, manifest)


# --- 8. a batch whose worker failed is fitted again by --resume -----------------------------


def test_resume_refits_a_batch_whose_worker_failed(tmp_path, nights, monkeypatch):
    """A batch whose task failed (a worker lost, killed by the OOM killer, KilledWorker) is
    written as ``error`` rows "worker failed" and counted done: the manifest says complete,
    and ``--resume`` skips those households for good — though the run never fitted them and
    :mod:`.results.previous` itself treats such a row as passing."""
    from distributed import Client, LocalCluster

    import impctl.fleet.run as run_module

    src = tmp_path / "in"
    src.mkdir()
    _normal_only(nights[1], src / "a.csv")
    real = run_module.fit_batch

    def lost(*_a, **_k):
        raise RuntimeError("worker tcp://127.0.0.1:1 lost")   # what a lost worker raises

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address="127.0.0.1:0") as cluster, Client(cluster) as c:
        monkeypatch.setattr(run_module, "fit_batch", lost)
        fit_fleet(src, tmp_path / "F", client=c, model_dir=None, progress=False, echo=quiet)
        first = read_fleet(tmp_path / "F").set_index("household").loc["a"]
        assert (first["status"], first["reason"]) == ("error", "worker failed")
        monkeypatch.setattr(run_module, "fit_batch", real)
        fit_fleet(src, tmp_path / "F", client=c, model_dir=None, resume=True,
                  progress=False, echo=quiet)
    row = read_fleet(tmp_path / "F").set_index("household").loc["a"]
    assert (row["status"], row["reason"]) != ("error", "worker failed"), (
        "--resume kept the lost worker's placeholder row")
