"""Benchmark of ``impctl fleet fit --scheduler`` on a cluster of separate programs: throughput
on 1 and 2 worker processes, the ratio, and each worker's peak resident memory.

Run:  .venv/bin/python bench/fleet_cluster.py [--households 448] [--data DIR]
          [--workers 1,2] [--batch-size 64] [--model-dir DIR] [--pin]

For every worker count W, as on a real cluster: ``dask scheduler`` and ``dask worker
--nworkers W --nthreads 1`` (``MALLOC_ARENA_MAX=2``, Dask's profiler off, as
docs/how-to/fleet-dask.md starts them)
are started as separate programs on loopback TCP (with ``--pin``: one ``taskset -c I dask
worker --nworkers 1`` per worker, each kept on a CPU of its own, as the how-to shows), the
fleet is fitted through the scheduler's address (:func:`impctl.fleet.fit_fleet` with
``scheduler=``, as ``impctl fleet fit --scheduler`` does), and the programs are stopped.
Measured per run:

* wall time of the fit, from the call to the last FLEET part (the plugin that loads torch in
  each worker included; the cluster's own start is not), households/s and households/hour;
* the steady rate: each worker's households after its first finished batch over the time to
  its last, summed over the workers (from the FLEET parts' modification times and ``worker``
  column) — the throughput once every worker runs, which a fleet of tens of thousands sees;
  the start it leaves out is printed beside it;
* CPU-s per household in the workers' batches (the FLEET ``cpu_s_per_household`` column);
* peak resident memory of each worker process [MB]: the kernel's high-water mark (``VmHWM``
  of ``/proc/PID/status``), read just before the cluster stops.

Then the throughput ratio of each worker count against the first one given; a count given more
than once (``--workers 1,2,1,2``, interleaved so that the machine's drift falls on both) counts
with the median of its runs. Input: the realistic-plant
fleet of ``bench/fleet.py`` (8 nights of 5-minute rows per household; generated once and kept
in ``--data``). Without ``--model-dir`` the fits search the whole prior ranges (no classifiers,
as ``bench/fleet.py``). The machine's other load skews the ratio: keep it quiet while this runs
(the load average is printed before and after each run).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import shlex
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from benchlib.fleet_rates import steady_rate

from impctl.fleet.run import DEFAULT_BATCH

DASK = str(Path(sys.executable).with_name("dask"))
#: The worker programs' environment, as the how-to starts them.
WORKER_ENV = {"MALLOC_ARENA_MAX": "2", "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def cluster(workers: int, logs: Path, pin: bool = False):
    """Scheduler and worker programs, ready (all workers registered); stopped on exit."""
    from distributed import Client

    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, **WORKER_ENV}
    logs.mkdir(parents=True, exist_ok=True)
    procs = []
    try:
        procs.append(subprocess.Popen(
            [DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
            stdout=subprocess.DEVNULL, stderr=open(logs / "scheduler.log", "w"),  # noqa: SIM115
            env=env, start_new_session=True))
        worker = [DASK, "worker", address, "--nthreads", "1", "--no-dashboard",
                  "--host", "127.0.0.1"]
        cpus = sorted(os.sched_getaffinity(0))   # --pin: at most one worker per CPU (main)
        starts = ([["taskset", "-c", str(cpus[i]), *worker, "--nworkers", "1"]
                   for i in range(workers)] if pin else [[*worker, "--nworkers", str(workers)]])
        for i, argv in enumerate(starts):
            procs.append(subprocess.Popen(
                argv, stdout=subprocess.DEVNULL,
                stderr=open(logs / f"worker-{i}.log", "w"),  # noqa: SIM115
                env=env, start_new_session=True))
        deadline = time.monotonic() + 180
        while True:
            try:
                with Client(address, timeout="5s") as client:
                    client.wait_for_workers(workers, timeout=180)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(1)
        yield address
    finally:
        for p in reversed(procs):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGTERM)
        for p in reversed(procs):
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def _peak_rss_mb() -> float:
    """This process's peak resident memory [MB] (run in each worker by ``client.run``)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def run(data: Path, workers: int, batch: int, model_dir: Path | None, work: Path,
        turn: int = 0, pin: bool = False) -> dict:
    from distributed import Client

    from impctl.fleet import fit_fleet

    out = work / f"FLEET-{turn}-{workers}w.parquet"
    with cluster(workers, work / f"logs-{turn}-{workers}w", pin) as address:
        load = os.getloadavg()[0]
        t0, t0_wall = time.perf_counter(), time.time()
        result = fit_fleet(data, out, scheduler=address, model_dir=model_dir,
                           batch_size=batch, progress=False, echo=lambda s: None)
        wall = time.perf_counter() - t0
        with Client(address, timeout="10s") as client:
            peaks = client.run(_peak_rss_mb)
            pids = client.run(os.getpid)
    fleet = pd.read_parquet(out)
    rate = result.fitted / wall
    return {"workers": result.workers, "households": result.fitted, "counts": result.counts,
            "wall_s": wall, "rate": rate, "steady": steady_rate(out, t0_wall),
            "cpu_s": fleet["cpu_s_per_household"].mean(),
            "peaks": {pids[w]: peaks[w] for w in peaks}, "load_before": load,
            "load_after": os.getloadavg()[0]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=448,
                    help="fleet size (the default takes about a minute on one worker)")
    ap.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "impctl-bench")
    ap.add_argument("--workers", default="1,2", help="worker counts to run, comma-separated")
    ap.add_argument("--batch-size", type=int, default=DEFAULT_BATCH,
                    help="households per task [default: impctl fleet fit's]")
    ap.add_argument("--model-dir", type=Path, default=None,
                    help="classifiers [default: none — the whole prior ranges]")
    ap.add_argument("--pin", action="store_true",
                    help="one worker program per CPU under taskset (each on a CPU of its own)")
    args = ap.parse_args()
    if args.pin and max(int(w) for w in args.workers.split(",")) > len(os.sched_getaffinity(0)):
        # two workers on one CPU is not what --pin measures (impctl pins nothing then either)
        ap.error(f"--pin: at most {len(os.sched_getaffinity(0))} workers here (one per CPU)")
    if args.model_dir is None:
        os.environ["IMPCTL_MODEL_DIR"] = str(args.data / "no-models")  # → the prior ranges
    sys.path.insert(0, str(Path(__file__).parent))
    from fleet import make_fleet

    data = make_fleet(args.households, args.data)
    counts = [int(w) for w in args.workers.split(",")]
    print(f"command: {shlex.join([Path(sys.executable).name, *sys.argv])}")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"input {data} ({args.households} households, 8 nights of 5-minute rows each)")
    results = []
    with tempfile.TemporaryDirectory(prefix="fleet-cluster-") as tmp:
        for turn, w in enumerate(counts):
            r = run(data, w, args.batch_size, args.model_dir, Path(tmp), turn, args.pin)
            results.append(r)
            peaks = ", ".join(f"{mb:.0f}" for mb in r["peaks"].values())
            print(f"{r['workers']} worker(s): {r['households']} households {r['counts']} in "
                  f"{r['wall_s']:.1f} s wall → {r['rate']:.2f} households/s = "
                  f"{r['rate'] * 3600:,.0f} households/hour (first batch after "
                  f"{r['steady'][1]:.1f} s, then {r['steady'][0]:.2f} households/s); "
                  f"{r['cpu_s']:.3f} CPU-s per "
                  f"household in the batches; peak RSS per worker [MB]: {peaks}; load average "
                  f"{r['load_before']:.1f} before, {r['load_after']:.1f} after")
    # a count given more than once (1,2,1,2: interleaved, so that a drift of the machine
    # falls on both) is summarised by the median of its runs
    def median(key, w):
        return float(np.median([r[key] if key == "rate" else r[key][0]
                                for r in results if r["workers"] == w]))

    rate = {w: median("rate", w) for w in dict.fromkeys(r["workers"] for r in results)}
    if len(rate) > 1:
        base, *others = rate
        for w in others:
            runs = sum(r["workers"] == w for r in results)
            print(f"throughput {w} against {base} worker(s): {rate[w] / rate[base]:.2f}× "
                  f"from the call to the last batch, "
                  f"{median('steady', w) / median('steady', base):.2f}× once every worker "
                  f"runs (median rates of {runs} and "
                  f"{sum(r['workers'] == base for r in results)} runs)")
    best = max(rate, key=rate.get)
    print(f"10,000 households at {rate[best]:.2f} households/s: "
          f"{10_000 / rate[best] / 60:.1f} min")


if __name__ == "__main__":
    main()
