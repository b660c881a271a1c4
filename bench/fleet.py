"""Benchmark of ``impctl fleet fit``: wall time, CPU per household, throughput per worker count,
batch vs alone, memory per worker, and where a batch's CPU goes.

Run:  .venv/bin/python bench/fleet.py [--households 1000] [--data DIR] [--throughput 128]
          [--alone 16] [--batch-size 64] [--plant realistic|iso] [--profile 16]
          [--copies N] [--skip-full | --full-only]
      .venv/bin/python bench/fleet.py --sample 10 [--ranges true] [--dump F] [--against F]

(``--throughput`` households are cut into batches of at most ``--batch-size``, at least two per
worker.)

Fleet input (``--plant realistic``, the default): every household on the **realistic plant**
(:mod:`impctl.plant`, as ``bench/fit.py --plant realistic``): ``sample_households(seed=20260)``
with realism options from ``impctl.population.realism.sample_params``, the IMP schedule of
``impctl.population.imp_run.synth`` (two spin-up days, 2 constrained + 6 normal nights,
simulated at 60 s), logged as the gateway logs it — room and outdoor sensors (lag, noise,
offsets, quantisation), the heat meter's interval means — cut into 5-minute rows, T quantised
to 0.1 °C. ``--plant iso`` uses the ideal 5R1C with 5 % power noise instead (the bench before
issue 16). Written once as one Parquet dataset with a ``household`` column, sorted by household
in row groups of 65,536 rows (reused from ``--data`` when it is there).

Measured:
1. throughput [households/s] and CPU-s per household on 1 and 2 worker processes
   (``--throughput`` households);
2. per household, fitted alone (``NightFit.fit``, one thread) vs in a batch
   (``impctl.fit.optim.batch.fit_households``, one thread), ``--alone`` households;
3. the whole fleet with the default local cluster (one worker process per core), wall clock
   from the command's start (cluster start-up and worker preload included) to the last row,
   and the worker time outside the batches split into the workers' own CPU there (start,
   imports, preload, Dask), time not on a core, and this process's CPU (client, scheduler,
   nannies, FLEET writes); ``--copies N`` runs it on the households N times under new ids
   (``--households 1000 --copies 10``: the 10,000-household figure);
4. resident memory of each worker after each batch (the FLEET ``worker_rss_mb`` column): first,
   median and last batch — flat means no growth over the run;
5. ``--profile N``: one worker's batch of N households run in this process
   (:func:`impctl.fleet.worker.fit_batch`), its CPU split by phase (thread CPU time of each
   phase, nested phases inside their parents);
6. ``--sample B``: B batches spread over the whole fleet fitted in this process
   (``fit_households``, as a worker fits them, without Dask): CPU-s per household, with the
   whole prior ranges or each house's true classes (``--ranges true``, the path with
   classifiers: a third more problems and the class check); ``--dump``/``--against`` compare
   every fitted number with another commit's run.
No classifiers are used (the whole prior ranges, as without ``impctl train``), so the figures
are the fit's; classification adds ~1 ms per household.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from impctl.fleet.run import DEFAULT_BATCH

SEED = 20260


def make_fleet(n: int, path: Path, plant: str = "realistic") -> Path:
    """n households' nights as one Parquet dataset (cached)."""
    from impctl.population.households import sample_households
    from impctl.population.imp_run.synth import (
        imp_schedule,
        run_schedule,
        run_schedule_plant,
        sample_nights,
    )
    from impctl.population.realism import sample_params

    target = path / f"fleet-{plant}-{n}-rg65536.parquet"
    if target.exists():
        return target
    t0 = time.perf_counter()
    frames = []
    houses = sample_households(n, seed=SEED)
    for lo in range(0, n, 250):  # simulate in slices to bound memory
        k = min(250, n - lo)
        sub = type(houses)(**{f: np.broadcast_to(np.asarray(v, float), (n,))[lo:lo + k]
                              for f, v in houses.as_dict().items()})
        sched = imp_schedule(k, seed=SEED + lo)
        if plant == "realistic":
            # the meter has its own noise and gain error: no extra power noise
            sim, sp = run_schedule_plant(sub, sched, sample_params(k, SEED + lo), seed=SEED + lo)
            noise = 0.0
        else:
            sim, sp = run_schedule(sub, sched)
            noise = 0.05
        for i in range(k):
            for night in sample_nights(sim, sp, sched, i, sample_step_s=300.0,
                                       power_noise=noise, seed=lo + i):
                stamps = night.start + pd.to_timedelta(night.time_s, unit="s")
                frames.append(pd.DataFrame({
                    "household": f"h{lo + i:05d}", "timestamp": stamps.tz_convert("UTC"),
                    "t_air": night.t_air_c, "t_out": night.t_out_c, "q_hc": night.q_hc_w,
                    "night": night.night_id, "kind": night.kind}))
    path.mkdir(parents=True, exist_ok=True)
    tmp = path / f".{target.name}.tmp"
    # sorted by household in row groups of 65,536 rows: the layout the how-to gives (a batch
    # decodes only the row groups of its own households)
    pd.concat(frames, ignore_index=True).to_parquet(tmp, index=False, row_group_size=65_536)
    os.replace(tmp, target)
    print(f"generated {n} households ({plant} plant) in {time.perf_counter() - t0:.0f} s "
          f"→ {target}")
    return target


def copies(data: Path, n: int) -> Path:
    """The households of ``data`` ``n`` times, each copy under new ids (``c0h00000`` …), sorted
    by household in row groups of 65,536 rows (cached beside ``data``): a 10,000-household run
    from 1,000 simulated ones. The copies' numbers repeat; the fleet's cost does not depend on
    that (every household is read and fitted on its own)."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    target = data.with_name(f"{data.stem}-x{n}.parquet")
    if target.exists():
        return target
    table = pq.read_table(data)
    col = table.schema.get_field_index("household")
    ids = table["household"].cast(pa.string())
    parts = [table.set_column(col, "household",
                              pc.binary_join_element_wise(pa.scalar(f"c{k}"), ids, ""))
             for k in range(n)]
    tmp = target.with_name(f".{target.name}.tmp")
    pq.write_table(pa.concat_tables(parts).sort_by("household"), tmp, row_group_size=65_536)
    os.replace(tmp, target)
    return target


def subset(data: Path, n: int, out: Path) -> Path:
    df = pd.read_parquet(data)
    keep = sorted(df["household"].unique())[:n]
    target = out / f"subset-{n}.parquet"
    df[df["household"].isin(keep)].to_parquet(target, index=False)
    return target


def run_fleet(data: Path, workers: int | None, batch: int, work: Path,
              previous: Path | None = None) -> tuple[float, Path]:
    from impctl.fleet import fit_fleet

    out = work / f"FLEET-{workers or 'default'}-{time.time_ns()}.parquet"
    before = os.times()
    t0 = time.perf_counter()
    run = fit_fleet(data, out, workers=workers, batch_size=batch, progress=True,
                    previous=previous, echo=lambda s: print(s, file=sys.stderr))
    wall = time.perf_counter() - t0
    after = os.times()
    fleet = pd.read_parquet(out)
    cpu = fleet["cpu_s_per_household"].sum()
    # The local cluster's worker processes are this process's children: once the cluster is
    # closed their whole CPU time (imports, preload, Dask, batches) is in os.times().
    children = (after.children_user + after.children_system
                - before.children_user - before.children_system)
    client = after.user + after.system - before.user - before.system
    print(f"  {run.found} households, {run.counts}, {wall:.1f} s wall on {run.workers} "
          f"workers → {run.fitted / wall:.2f} households/s ({3600 * run.fitted / wall:,.0f} an "
          f"hour); worker CPU in the batches "
          f"{cpu:.0f} s = {cpu / max(1, run.fitted):.3f} CPU-s per household; worker time "
          f"outside the batches {wall * run.workers - cpu:.0f} s (load average now "
          f"{os.getloadavg()[0]:.1f})")
    if children > 0:
        print(f"  of the {wall * run.workers - cpu:.0f} worker-seconds outside the batches: "
              f"{children - cpu:.0f} CPU-s in the worker processes outside the batches "
              f"(start, imports, preload, Dask), {wall * run.workers - children:.0f} s not on "
              f"a core (waiting: start-up order, the last batches, other processes); this "
              f"process (client, scheduler, nannies, FLEET writes) used {client:.0f} CPU-s")
    return wall, out


def memory(out: Path) -> None:
    fleet = pd.read_parquet(out)
    print("  resident memory per worker after its batches [MB] (first / median / last, "
          "batches):")
    for worker, rows in fleet.groupby("worker"):
        per_batch = rows.drop_duplicates("worker_rss_mb")["worker_rss_mb"].to_numpy()
        print(f"    {worker}: {per_batch[0]:.0f} / {np.median(per_batch):.0f} / "
              f"{per_batch[-1]:.0f} ({len(per_batch)} batches)")


def batch_vs_alone(data: Path, n: int) -> None:
    import torch

    from impctl.fit.estimator import NightFit
    from impctl.fit.optim.batch import fit_households
    from impctl.fleet.inputs import discover, read_sources

    torch.set_num_threads(1)
    sources = discover(data)[:n]
    nights = list(read_sources(sources, "Europe/Ljubljana").values())
    t0, c0 = time.perf_counter(), time.process_time()
    alone = [NightFit().fit(x, None) for x in nights]
    t_alone, c_alone = (time.perf_counter() - t0) / n, (time.process_time() - c0) / n
    t0, c0 = time.perf_counter(), time.process_time()
    batched, stats = fit_households(nights, [None] * n)
    t_batch, c_batch = (time.perf_counter() - t0) / n, (time.process_time() - c0) / n
    diff = max(abs(b.lumped_[k].value / a.lumped_[k].value - 1) for a, b in
               zip(alone, batched, strict=True) for k in ("hlc", "c_m", "tau"))
    print(f"  alone {t_alone:.3f} s wall / {c_alone:.3f} CPU-s per household; in a batch of "
          f"{n} {t_batch:.3f} s wall / {c_batch:.3f} CPU-s per household ({c_alone / c_batch:.1f}× "
          f"less CPU; {stats.merged_calls} merged optimiser calls); largest relative "
          f"difference of HLC/C_m/τ {diff:.1e}")


def sample(data: Path, n_batches: int, batch: int, ranges: str, dump: Path | None,
           against: Path | None) -> None:
    """``n_batches`` batches spread over the fleet, fitted in this process as a worker fits
    them (``fit_households``, ``per_night=False``, one thread): CPU-s per household, optimiser
    calls; ``--dump`` writes every household's numbers, ``--against``
    compares them with an earlier dump (same command on another commit)."""
    import json

    import torch

    from impctl.fit.optim.batch import fit_households
    from impctl.fleet.inputs import discover, read_sources

    torch.set_num_threads(1)
    sources = discover(data)
    houses = None
    if ranges == "true":
        from benchlib.fit_protocol import true_ranges

        from impctl.population.households import sample_households

        houses = sample_households(len(sources), seed=SEED)
    step = max(batch, len(sources) // n_batches)
    out, cpu, calls, n = {}, 0.0, 0, 0
    for lo in range(0, step * n_batches, step):
        nights = read_sources(sources[lo:lo + batch], "Europe/Ljubljana")
        keys = list(nights)
        box = [None if houses is None else true_ranges(houses.take(int(k[1:]))) for k in keys]
        c0 = time.process_time()
        fits, stats = fit_households([nights[k] for k in keys], box, per_night=False)
        cpu += time.process_time() - c0
        calls += stats.merged_calls
        n += len(keys)
        for k, f in zip(keys, fits, strict=True):
            out[k] = None if isinstance(f, BaseException) else {
                "lumped": {q: [e.value, e.low, e.high] for q, e in f.lumped_.items()},
                "parameters": f.parameters_, "sigma_night": f.sigma_night_, "loss": f.loss_,
                "n_iter": f.n_iter_}
    print(f"  {n} households ({n_batches} batches of {batch}, ranges: {ranges}): "
          f"{cpu / n:.3f} CPU-s per household, {calls} merged optimiser calls "
          f"(load average now {os.getloadavg()[0]:.1f})")
    if dump:
        dump.write_text(json.dumps(out))
    if against:
        old = json.loads(against.read_text())
        flat = lambda d: (np.concatenate([flat(v) for v in d.values()]) if isinstance(d, dict)  # noqa: E731
                          else np.asarray(d, float).ravel())
        diff = max(float(np.max(np.abs(flat(out[k]) - flat(old[k]))
                                / np.maximum(np.abs(flat(old[k])), 1e-300)))
                   for k in out if out[k] is not None)
        print(f"  against {against.name}: largest relative difference of any fitted number "
              f"(HLC/C_m/τ and intervals, parameters, σ per night, loss, iterations) {diff:.1e}")


def profile(data: Path, n: int) -> None:
    """One worker's batch of ``n`` households in this process, its CPU split by phase."""
    import threading

    import torch

    from impctl.fit.checks import selection
    from impctl.fit.ode import solver
    from impctl.fit.optim import batch, jacobian, lm, problem
    from impctl.fit.steps import problems as _problems
    from impctl.fit.steps import statement as _statement
    from impctl.fit.steps import weights as _weights
    from impctl.fleet import worker
    from impctl.fleet.inputs import discover

    torch.set_num_threads(1)
    phases: dict[str, float] = {}
    lock = threading.Lock()
    calls = {"lm": 0}

    def timed(owner, attr: str, name) -> None:
        real = getattr(owner, attr)

        def wrapper(*a, **kw):
            label = name() if callable(name) else name
            t = time.thread_time()
            try:
                return real(*a, **kw)
            finally:
                with lock:
                    phases[label] = phases.get(label, 0.0) + time.thread_time() - t
        setattr(owner, attr, wrapper)

    def lm_call() -> str:
        calls["lm"] += 1
        return {1: "merged LM: 1st call (all starts, with and without the nuisance terms)",
                2: "merged LM: 2nd call (joint refit with fitted σ and tempered prior)"}.get(
            calls["lm"], "merged LM: later refits (households whose nights' σ still moved)")

    timed(worker, "read_sources", "read the households' rows (pyarrow/pandas → nights)")
    timed(worker, "_classify", "classifiers")
    timed(_problems, "prepare_nights", "prepare/cut nights (worker check + fit)")
    timed(batch, "_solve_group", lm_call)
    timed(lm, "_normal_equations", "  in LM: residuals + Jacobian")
    timed(lm, "_trial", "  in LM: residuals + Jacobian")   # the iterations' trial points
    timed(lm, "penalty", "    of which the ridge and the population priors (also in the intervals)")
    timed(problem, "build_rows", "    of which building the rows (5R1C coefficients, inputs)")
    timed(jacobian, "build_rows", "    of which building the rows (5R1C coefficients, inputs)")
    timed(jacobian, "_analytic", "    of which the analytic Jacobian (responses, Gram products)")
    timed(solver.NightODE, "integrate", "    of which integrating (exact discretisation)")
    timed(_statement, "laplace", "Laplace + sandwich intervals, class-check inflation")
    timed(selection, "laplace", "Laplace + sandwich intervals, class-check inflation")
    timed(_statement, "in_sample_validation", "validation / predictions (two row sets)")
    timed(_statement, "used_nights_quality", "night quality")
    timed(_weights, "residual_sigma", "residual σ update")
    timed(_problems, "pack_nights", "pack nights into tensors")
    timed(_problems, "coarsen", "coarsen to 5-min blocks")
    timed(worker, "_flexibility", "flexibility (coast_h, rebound_kwh)")
    sources = discover(data)[:n]
    settings = worker.Settings(model_dir=worker.PRIOR)
    worker.fit_batch(sources[:2], settings)   # imports, first-call costs
    phases.clear()
    calls["lm"] = 0
    t0, c0 = time.perf_counter(), time.process_time()
    rows = worker.fit_batch(sources, settings)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    ok = sum(r["status"] == "ok" for r in rows)
    print(f"  batch of {n} ({ok} ok): {wall:.1f} s wall, {cpu:.2f} CPU-s = {cpu / n:.3f} "
          "CPU-s per household")
    print(f"  {'phase':<76} {'CPU-s':>7} {'share':>6}")
    top = 0.0
    for name, sec in phases.items():
        if not name.startswith(" "):
            top += sec
        print(f"  {name:<76} {sec:7.2f} {100 * sec / cpu:5.1f}%")
    print(f"  {'other (threads, Python glue, tensors outside the phases)':<76} "
          f"{cpu - top:7.2f} {100 * (cpu - top) / cpu:5.1f}%")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--households", type=int, default=1000)
    ap.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "impctl-bench")
    ap.add_argument("--throughput", type=int, default=256,
                    help="households of the throughput runs (0: skip them)")
    ap.add_argument("--alone", type=int, default=16,
                    help="households fitted alone and in one batch (0: skip)")
    ap.add_argument("--batch-size", type=int, default=DEFAULT_BATCH,
                    help="households per task [default: impctl fleet fit's]")
    ap.add_argument("--plant", choices=("realistic", "iso"), default="realistic")
    ap.add_argument("--profile", type=int, default=0, metavar="N",
                    help="split one batch of N households' CPU by phase, then stop")
    ap.add_argument("--sample", type=int, default=0, metavar="BATCHES",
                    help="fit BATCHES batches spread over the fleet in this process, then stop")
    ap.add_argument("--ranges", choices=("prior", "true"), default="prior",
                    help="--sample: whole prior ranges, or each house's true classes")
    ap.add_argument("--dump", type=Path, help="--sample: write every household's numbers")
    ap.add_argument("--against", type=Path, help="--sample: compare with an earlier --dump")
    ap.add_argument("--copies", type=int, default=1, metavar="N",
                    help="the full run on the households N times under new ids "
                         "(--households 1000 --copies 10: 10,000 households)")
    ap.add_argument("--skip-full", action="store_true")
    ap.add_argument("--full-only", action="store_true")
    args = ap.parse_args()
    os.environ.setdefault("IMPCTL_MODEL_DIR", str(args.data / "no-models"))
    print(f"bench/fleet.py on {platform.node()}: {os.cpu_count()} cores, load average "
          f"{os.getloadavg()[0]:.1f}; command: {' '.join(sys.argv)}")
    print(f"plant: {args.plant}; 8 nights (2 constrained + 6 normal) of 5-minute rows per "
          "household; no classifiers (prior ranges)")
    data = make_fleet(args.households, args.data, args.plant)
    if args.sample:
        print(f"\n6. {args.sample} batches across the fleet, in this process (one thread)")
        sample(data, args.sample, args.batch_size, args.ranges, args.dump, args.against)
        return
    if args.profile:
        print(f"\n5. where one batch's CPU goes ({args.profile} households, one thread)")
        profile(data, args.profile)
        return
    work = Path(tempfile.mkdtemp(prefix="impctl-fleet-bench-"))
    try:
        if not args.full_only and args.throughput > 0:
            print(f"\n1. throughput on {args.throughput} households")
            small = subset(data, args.throughput, work)
            for w in (1, 2):
                run_fleet(small, w, args.batch_size, work)
        if not args.full_only and args.alone > 0:
            print(f"\n2. per household alone vs in a batch ({args.alone} households, one "
                  "thread)")
            batch_vs_alone(data, args.alone)
        full = data if args.copies <= 1 else copies(data, args.copies)
        print(f"\n3. {args.households * max(1, args.copies)} households"
              f"{f' ({args.households} × {args.copies} copies)' if args.copies > 1 else ''}, "
              f"default local cluster, batch {args.batch_size} (target: 10,000 in ≤ 120 s)")
        if not args.skip_full:
            wall, out = run_fleet(full, None, args.batch_size, work)
            memory(out)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
