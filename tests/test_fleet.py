"""``impctl fleet fit`` against a separately started Dask scheduler and worker processes on
loopback, ``impctl flex``, --resume, bad households, the report; and the default local cluster
on a Parquet dataset with a ``household`` column."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from cli_fixtures import run_impctl
from dask_fixtures import dask_cluster
from fleet_fixtures import HOUSES

from impctl.imp import write_nights


def run_cli(*args: str) -> subprocess.CompletedProcess:
    # in this process: the tests check the output; the fits run in the Dask workers' processes
    return run_impctl(*args)


@pytest.fixture(scope="module")
def models(trained_models) -> Path:
    return trained_models.out


@pytest.fixture(scope="module")
def nights(two_fleet_households):
    return two_fleet_households


def _frame(nights) -> pd.DataFrame:
    rows = []
    for n in nights:
        stamps = n.start + pd.to_timedelta(n.time_s, unit="s")
        rows.append(pd.DataFrame({"timestamp": stamps.tz_convert("UTC"), "t_air": n.t_air_c,
                                  "t_out": n.t_out_c, "q_hc": n.q_hc_w, "night": n.night_id,
                                  "kind": n.kind}))
    return pd.concat(rows, ignore_index=True)


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory, nights) -> Path:
    d = tmp_path_factory.mktemp("fleet")
    write_nights(nights[0], d / "house-a.csv")
    _frame(nights[1]).to_parquet(d / "house-b.parquet")         # a Parquet NIGHTS file
    (d / "broken.csv").write_text("timestamp,t_air\n2026-01-01T00:00:00Z,oops\n")
    write_nights([n for n in nights[0] if n.kind == "normal"], d / "no-cooling.csv")
    return d


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory):
    """A Dask scheduler and a worker with two processes, started as separate programs."""
    with dask_cluster(tmp_path_factory.mktemp("dask"), 2, {"OMP_NUM_THREADS": "1"}) as (
            address, _):
        yield address


@pytest.fixture(scope="module")
def fleet_run(tmp_path_factory, fleet_dir, models, scheduler):
    out = tmp_path_factory.mktemp("out")
    done = run_cli("fleet", "fit", str(fleet_dir), "--out", str(out / "FLEET.parquet"),
                   "--scheduler", scheduler, "--model-dir", str(models), "--batch-size", "2",
                   "--report", str(out / "report"))
    assert done.returncode == 0, done.stderr
    return out, done


def test_every_household_gets_a_row_saying_what_happened(fleet_run):
    out, done = fleet_run
    assert "4 households: 4 fitted now (2 ok, 1 insufficient, 1 error)" in done.stdout
    assert "on 2 workers" in done.stdout
    # the progress bar: households done, failed, and the rate
    assert "4/4" in done.stderr and "failed=1" in done.stderr
    assert "household/s" in done.stderr or "s/household" in done.stderr
    fleet = pd.read_parquet(out / "FLEET.parquet").set_index("household")
    assert sorted(fleet.index) == ["broken", "house-a", "house-b", "no-cooling"]
    assert fleet.loc["broken", "status"] == "error"
    assert "broken.csv" in fleet.loc["broken", "error"]
    assert fleet.loc["no-cooling", "status"] == "insufficient"
    assert "no usable constrained night" in fleet.loc["no-cooling", "reason"]
    # the line impctl fit prints for the same file
    assert "too little data to fit: missing a constrained night" in \
        fleet.loc["no-cooling", "error"]
    for h in ("house-a", "house-b"):
        row = fleet.loc[h]
        assert row["status"] == "ok" and row["nights_used"] == 5
        assert row["hlc_w_per_k_low"] < row["hlc_w_per_k"] < row["hlc_w_per_k_high"]
        assert row["coast_h_low"] <= row["coast_h"] <= row["coast_h_high"]
        assert row["rebound_kwh"] > 0
        assert row["floor_area_class"] and row["c_f_class"] and row["u_walls_class"]
    truth = dict(zip(["house-a", "house-b"], np.asarray(HOUSES.hlc_w_per_k), strict=True))
    for h, hlc in truth.items():
        # these ideal houses have no night gains, the fleet's fits assume the default 250 W:
        # house-a's HLC is +8.6 % in its true class without the population prior, +10.1 %
        # with it (issue 14, h14z); its interval holds the truth either way
        assert fleet.loc[h, "hlc_w_per_k"] == pytest.approx(hlc, rel=0.12)
        assert fleet.loc[h, "hlc_w_per_k_low"] <= hlc <= fleet.loc[h, "hlc_w_per_k_high"]


def test_workers_load_the_classifiers_once(fleet_run, scheduler):
    from distributed import Client

    from impctl.fleet.worker import worker_state

    with Client(scheduler, timeout="10s") as client:
        states = client.run(worker_state)
    assert len(states) == 2
    # four households on two workers are cut into four batches (at least two per worker);
    # every household classified, models loaded once per worker process (by the plugin),
    # never per batch or household
    assert sum(s["batches"] for s in states.values()) == 4
    assert all(s["model_loads"] == 1 for s in states.values())


def test_a_household_matches_impctl_fit_on_the_same_file(fleet_run, fleet_dir, models,
                                                         tmp_path):
    out, _ = fleet_run
    done = run_cli("fit", "--nights", str(fleet_dir / "house-a.csv"), "--model-dir",
                   str(models), "--json", str(tmp_path / "fit.json"))
    assert done.returncode == 0, done.stderr
    fit = json.loads((tmp_path / "fit.json").read_text())
    row = pd.read_parquet(out / "FLEET.parquet").set_index("household").loc["house-a"]
    for key, col in (("hlc", "hlc_w_per_k"), ("c_m", "c_m_j_per_k"), ("tau", "tau_h")):
        assert row[col] == pytest.approx(fit["lumped"][key]["value"], rel=1e-4)
        assert row[f"{col}_low"] == pytest.approx(fit["lumped"][key]["low"], rel=1e-3)
        assert row[f"{col}_high"] == pytest.approx(fit["lumped"][key]["high"], rel=1e-3)
    flex = fit["flexibility"]
    assert {"coast_h", "coast_h_low", "coast_h_high", "rebound_kwh"} <= set(flex)
    assert row["coast_h"] == pytest.approx(flex["coast_h"], rel=1e-3)
    assert row["rebound_kwh"] == pytest.approx(flex["rebound_kwh"], rel=1e-3)
    # impctl flex reads both the fit JSON and the fleet row, and agrees with them
    by_json = run_cli("flex", str(tmp_path / "fit.json"), "--json")
    by_row = run_cli("flex", str(out / "FLEET.parquet"), "--household", "house-a", "--json")
    assert by_json.returncode == 0 and by_row.returncode == 0, by_json.stderr + by_row.stderr
    a = json.loads(by_json.stdout)["fit"]
    b = json.loads(by_row.stdout)["house-a"]
    assert a["coast_h"] == pytest.approx(b["coast_h"], rel=1e-3) and a["coast_h"] > 0
    colder = json.loads(run_cli("flex", str(tmp_path / "fit.json"), "--json", "--t-out",
                                "-10").stdout)["fit"]
    assert colder["coast_h"] < a["coast_h"]
    bad = run_cli("flex", str(out / "FLEET.parquet"), "--household", "no-cooling")
    assert bad.returncode == 2 and "has no fit" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1


def test_report_shows_distributions_and_failures(fleet_run):
    out, _ = fleet_run
    page = (out / "report" / "fleet_report.html").read_text()
    assert "Failures by reason" in page and "broken" in page and "unreadable input" in page
    assert "needing more nights" in page and "no-cooling" in page
    assert page.count("<img") == 2
    for png in ("fig_fleet_distributions.png", "fig_fleet_intervals.png"):
        assert (out / "report" / png).stat().st_size > 5000


def test_resume_refits_only_what_is_missing(fleet_run, fleet_dir, models, scheduler):
    out, _ = fleet_run
    target = out / "FLEET.parquet"
    again = run_cli("fleet", "fit", str(fleet_dir), "--out", str(target), "--scheduler",
                    scheduler, "--model-dir", str(models))
    assert again.returncode == 2 and "--resume" in again.stderr  # nothing overwritten
    parts = sorted(target.glob("part-*.parquet"))
    assert len(parts) == 4
    holding_a = next(p for p in parts if "house-a" in set(pd.read_parquet(p)["household"]))
    holding_a.unlink()  # as if the run had been interrupted before this batch
    resumed = run_cli("fleet", "fit", str(fleet_dir), "--out", str(target), "--scheduler",
                      scheduler, "--model-dir", str(models), "--resume", "--batch-size", "2")
    assert resumed.returncode == 0, resumed.stderr
    assert "1 fitted now (1 ok" in resumed.stdout and "3 already in" in resumed.stdout
    fleet = pd.read_parquet(target)
    assert sorted(fleet["household"]) == ["broken", "house-a", "house-b", "no-cooling"]
    nothing = run_cli("fleet", "fit", str(fleet_dir), "--out", str(target), "--scheduler",
                      scheduler, "--model-dir", str(models), "--resume")
    assert nothing.returncode == 0 and "0 fitted now" in nothing.stdout


def test_local_cluster_on_a_parquet_dataset(tmp_path, nights, monkeypatch):
    from impctl.fleet import fit_fleet, read_fleet

    monkeypatch.setenv("IMPCTL_MODEL_DIR", str(tmp_path / "no-models"))  # → prior ranges
    frame = _frame(nights[1])
    frame["household"] = "only"
    frame.to_parquet(tmp_path / "all.parquet")
    run = fit_fleet(tmp_path / "all.parquet", tmp_path / "F.parquet", workers=1,
                    model_dir=None, progress=False, echo=lambda _: None)
    assert run.counts == {"ok": 1, "insufficient": 0, "error": 0} and run.workers == 1
    row = read_fleet(tmp_path / "F.parquet").iloc[0]
    assert row["household"] == "only" and row["status"] == "ok"


def _profiler_enabled() -> bool:
    import dask

    return bool(dask.config.get("distributed.worker.profile.enabled"))


def test_local_cluster_workers_run_with_two_malloc_arenas_and_no_profiler():
    """The default cluster's worker processes start with MALLOC_ARENA_MAX=2 (their memory
    stays flat over a run; README "Fleets") and without Dask's statistical profiler (it
    samples every 10 ms for a dashboard nobody reads): read from the real worker processes."""

    from impctl.fleet.run import _client

    client, cluster = _client(None, 1)
    try:
        seen = client.run(os.environ.get, "MALLOC_ARENA_MAX")
        profiling = client.run(_profiler_enabled)
        pids = client.run(os.getpid)
    finally:
        client.close()
        cluster.close()
    assert list(seen.values()) == ["2"], seen
    assert list(profiling.values()) == [False], profiling
    assert _profiler_enabled()  # this process's default: the setting is the workers' own
    assert os.getpid() not in pids.values()  # a separate process, not this one


def _thread_cpus() -> list[list[int]]:
    return [sorted(os.sched_getaffinity(int(t))) for t in os.listdir("/proc/self/task")]


def test_local_cluster_workers_each_keep_to_a_cpu_of_their_own():
    """With the fleet's plugin, each worker process of the default cluster runs every thread
    on one CPU, a different one per worker (a batch's threads hand over hundreds of times a
    second: on one core their caches stay warm); with more workers than CPUs nothing is
    pinned. Read from the real worker processes."""
    from impctl.fleet.run import _client
    from impctl.fleet.worker import PRIOR, Preload, pin_to_cpu

    allowed = sorted(os.sched_getaffinity(0))
    assert pin_to_cpu(0, len(allowed) + 1) is None   # oversubscribed: left to the kernel
    assert sorted(os.sched_getaffinity(0)) == allowed
    n = min(2, len(allowed))
    client, cluster = _client(None, n)
    try:
        client.register_plugin(Preload(PRIOR, len(cluster.workers)))
        seen = client.run(_thread_cpus)
    finally:
        client.close()
        cluster.close()
    per_worker = [{tuple(c) for c in threads} for threads in seen.values()]
    assert all(len(cpus) == 1 and len(next(iter(cpus))) == 1 for cpus in per_worker), seen
    assert len({next(iter(cpus)) for cpus in per_worker}) == n, seen


def test_bad_input_is_one_line_and_exit_2(tmp_path, fleet_dir):
    missing = run_cli("fleet", "fit", str(tmp_path / "nope"), "--out", str(tmp_path / "F"))
    assert missing.returncode == 2 and "no such file" in missing.stderr
    bad_models = run_cli("fleet", "fit", str(fleet_dir), "--out", str(tmp_path / "F"),
                         "--model-dir", str(tmp_path))
    assert bad_models.returncode == 2 and "no trained models" in bad_models.stderr
    assert not (tmp_path / "F").exists()


def test_a_parquet_file_with_empty_string_cells_reads_as_the_csv(tmp_path, nights):
    """Null cells of a Parquet file's text columns are the CSV's empty cells (pandas writes an
    unset label as null): the same nights, not a label "None" or a night split at "nan"."""
    from impctl.fleet.inputs import discover, read_sources

    (tmp_path / "csv").mkdir()
    (tmp_path / "pq").mkdir()
    write_nights(nights[0], tmp_path / "csv" / "h.csv")
    frame = _frame(nights[0])
    frame["label"] = pd.Series([None] * len(frame), dtype=object)
    frame.to_parquet(tmp_path / "pq" / "h.parquet")
    assert pd.read_parquet(tmp_path / "pq" / "h.parquet")["label"].isna().all()
    csv, pq = (read_sources(discover(tmp_path / d), "Europe/Ljubljana")["h"]
               for d in ("csv", "pq"))
    assert not isinstance(pq, Exception), pq
    assert [(n.night_id, n.kind, n.label) for n in pq] == [
        (n.night_id, n.kind, n.label) for n in csv]
    assert all(n.label == "" for n in pq)


def test_a_dataset_of_large_row_groups_gets_a_note_on_its_layout(tmp_path, nights):
    """A worker's filter on ``household`` skips Parquet row groups only whole: row groups far
    larger than a batch's rows are said, with the layout that reads less."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from impctl.fleet.inputs import discover, layout_note

    one = _frame(nights[0])
    table = pa.Table.from_pandas(pd.concat(
        [one.assign(household=f"h{i:02d}") for i in range(20)], ignore_index=True),
        preserve_index=False)
    pq.write_table(table, tmp_path / "big.parquet")                  # one row group
    pq.write_table(table, tmp_path / "small.parquet", row_group_size=len(one))
    note = layout_note(discover(tmp_path / "big.parquet"), batch_size=1)
    assert note is not None and f"about {20 * len(one):,} rows" in note
    assert "sorted by household" in note
    assert layout_note(discover(tmp_path / "small.parquet"), batch_size=1) is None
    # a folder of files (one household each) has nothing to say
    folder = tmp_path / "files"
    folder.mkdir()
    write_nights(nights[0], folder / "h.csv")
    assert layout_note(discover(folder), batch_size=1) is None


def test_a_batch_reads_only_the_row_groups_holding_its_households(tmp_path, nights):
    """A batch of many households (64 here, the default) skips every row group that holds none
    of them — by the groups' statistics, which pyarrow does not use for a membership test of
    that many values — and reads exactly its households' rows."""
    import pyarrow as pa
    import pyarrow.dataset as ds
    import pyarrow.parquet as pq

    from impctl.fleet.inputs import _read_parquet, discover, households_filter

    one = _frame(nights[0])
    table = pa.Table.from_pandas(pd.concat(
        [one.assign(household=f"h{i:03d}") for i in range(256)], ignore_index=True),
        preserve_index=False)
    path = tmp_path / "fleet.parquet"
    pq.write_table(table, path, row_group_size=64 * len(one))       # four row groups
    batch = [s.household for s in discover(path)][64:128]
    dataset = ds.dataset(path, format="parquet")
    groups = next(dataset.get_fragments()).split_by_row_group(
        households_filter(batch, dataset.schema.field("household").type))
    assert len(groups) == 1
    frame = _read_parquet(str(path), batch)
    assert sorted(set(frame["household"])) == sorted(batch)
    assert len(frame) == 64 * len(one)


def test_a_dataset_whose_household_column_is_categorical_reads_its_households(tmp_path,
                                                                               nights):
    """pandas writes a categorical column as a Parquet dictionary: its households are read as
    from a plain text column (the filter compares the dictionary's values)."""
    from impctl.fleet.inputs import discover, read_sources

    one = _frame(nights[0])
    frame = pd.concat([one.assign(household=f"h{i:02d}") for i in range(3)], ignore_index=True)
    frame["household"] = frame["household"].astype("category")
    frame.to_parquet(tmp_path / "fleet.parquet", index=False)
    plain = tmp_path / "plain"
    plain.mkdir()
    write_nights(nights[0], plain / "h01.csv")
    sources = discover(tmp_path / "fleet.parquet")
    assert [s.household for s in sources] == ["h00", "h01", "h02"]
    got = read_sources([s for s in sources if s.household == "h01"], "Europe/Ljubljana")
    want = read_sources(discover(plain), "Europe/Ljubljana")["h01"]
    assert list(got) == ["h01"] and not isinstance(got["h01"], Exception), got
    assert [(n.night_id, n.kind, len(n.time_s)) for n in got["h01"]] == [
        (n.night_id, n.kind, len(n.time_s)) for n in want]
