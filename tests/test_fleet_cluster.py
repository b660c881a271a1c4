"""``impctl fleet fit --scheduler`` on a cluster as it runs on real machines: ``dask scheduler``
and ``dask worker`` started as separate programs over TCP (loopback), one worker process with
one thread — the FLEET table equals the default local cluster's, row for row, number for
number; the batches ran in the separate worker; the cluster is left running for the next
run, and its programs end cleanly."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import psutil
import pytest
from cli_fixtures import run_impctl
from dask_fixtures import dask_cluster

from impctl.imp import write_nights
from impctl.model import HouseParameters
from impctl.population.imp_run.synth import imp_schedule, run_schedule, sample_nights

HOUSES = HouseParameters(
    floor_area=np.array([120.0, 170.0, 95.0]), wall_height=np.array([2.6, 2.7, 2.5]),
    walls_area=np.array([160.0, 200.0, 130.0]), windows_area=np.array([25.0, 30.0, 18.0]),
    c_f=np.array([2.2, 1.2, 1.6]), u_walls=np.array([0.5, 0.9, 0.35]),
    u_windows=np.array([1.3, 1.8, 1.1]), ach_vent=np.zeros(3), ach_infl=np.full(3, 0.01))
#: What differs between two runs of the same fit: who ran it, how long, when, with what memory.
RUN_COLUMNS = ["worker", "worker_rss_mb", "wall_s_per_household", "cpu_s_per_household",
               "fitted_at"]


def run_cli(*args: str) -> subprocess.CompletedProcess:
    # in this process: the batches run in the Dask workers' processes either way
    return run_impctl(*args)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, trained_models) -> tuple[Path, Path]:
    """(folder of three households' NIGHTS files, trained classifiers)."""
    models = trained_models.out
    sched = imp_schedule(3, n_constrained=2, n_normal=3, seed=5)
    sim, sp = run_schedule(HOUSES, sched)
    folder = tmp_path_factory.mktemp("fleet")
    for i in range(3):
        write_nights(sample_nights(sim, sp, sched, i, sample_step_s=900.0, seed=i),
                     folder / f"house-{i}.csv")
    return folder, models


def _running(process: psutil.Process) -> bool:
    """Still running (an exited process whose parent has not reaped it yet is not)."""
    try:
        return process.status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def _table(out: Path) -> pd.DataFrame:
    table = pd.read_parquet(out).sort_values("household").reset_index(drop=True)
    return table.drop(columns=RUN_COLUMNS)


def test_a_separate_scheduler_and_worker_give_the_local_clusters_table(inputs, tmp_path):
    folder, models = inputs
    common = ("--model-dir", str(models), "--batch-size", "2", "--quiet")
    local = run_cli("fleet", "fit", str(folder), "--out", str(tmp_path / "LOCAL.parquet"),
                    "--workers", "1", *common)
    assert local.returncode == 0, local.stderr
    assert "3 households: 3 fitted now (3 ok" in local.stdout and "on 1 workers" in local.stdout

    # as the how-to starts a worker machine's programs: no thread settings of our own
    with dask_cluster(tmp_path / "dask", 1, {"MALLOC_ARENA_MAX": "2"}) as (address, procs):
        remote = run_cli("fleet", "fit", str(folder), "--out",
                         str(tmp_path / "REMOTE.parquet"), "--scheduler", address, *common)
        assert remote.returncode == 0, remote.stderr
        assert "3 households: 3 fitted now (3 ok" in remote.stdout
        assert "on 1 workers" in remote.stdout
        # the batches ran in the `dask worker` program's worker process, not in the CLI's
        workers = psutil.Process(procs[1].pid).children(recursive=True)
        worker_pids = {p.pid for p in workers}
        ran_in = {int(w.rsplit(":", 1)[1])
                  for w in pd.read_parquet(tmp_path / "REMOTE.parquet")["worker"]}
        assert ran_in and ran_in <= worker_pids
        # an existing cluster is used, not shut down: still there for the next run
        from distributed import Client

        with Client(address, timeout="10s") as client:
            assert len(client.scheduler_info()["workers"]) == 1
    assert all(p.poll() is not None for p in procs)
    _, alive = psutil.wait_procs(workers, timeout=30)
    assert not [p for p in alive if _running(p)]

    a, b = _table(tmp_path / "LOCAL.parquet"), _table(tmp_path / "REMOTE.parquet")
    assert list(a["household"]) == ["house-0", "house-1", "house-2"]
    assert (a["status"] == "ok").all() and a["hlc_w_per_k"].notna().all()
    pd.testing.assert_frame_equal(a, b, check_exact=True)
