"""``impctl fleet fit``: households in batches on a Dask cluster, FLEET.parquet batch by batch.

The client discovers the households (:mod:`.inputs`), drops those already in FLEET.parquet when
resuming, and submits one Dask task per batch (:func:`.worker.fit_batch`); workers read their
own households' files, so INPUT and the model directory must be reachable under the same paths
on every worker (a shared file system on a multi-machine cluster). As batches finish, the client
writes each one as its own part of FLEET.parquet (:mod:`.table`) and updates a progress bar
(households done, failed, rate).

Cluster: by default a ``distributed.LocalCluster`` of worker *processes* (one thread each —
torch is pinned to one thread per process) on this machine, started and stopped with the run;
with ``scheduler="tcp://HOST:8786"`` an existing cluster (``dask scheduler`` + ``dask worker``)
is used and left running. The :class:`.worker.Preload` plugin loads torch and the classifiers
once per worker process.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from .inputs import Source, discover
from .table import done_households, empty_row, new_run_id, write_part
from .worker import PRIOR, Preload, Settings, fit_batch

DEFAULT_BATCH = 16


@dataclass
class FleetRun:
    """What a run did: households found / skipped (resume) / fitted per status, wall time [s]."""

    found: int = 0
    skipped: int = 0
    counts: dict[str, int] = field(default_factory=lambda: {"ok": 0, "insufficient": 0,
                                                             "error": 0})
    wall_s: float = 0.0
    workers: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def fitted(self) -> int:
        return sum(self.counts.values())


def resolve_models(model_dir: str | Path | None) -> tuple[str, str | None]:
    """(model dir for the workers, or PRIOR; a note when falling back to the prior ranges).

    An explicitly given directory that holds no usable classifiers is bad input; the default
    directory without them means "search the prior ranges", as ``impctl fit`` does.
    """
    from ..classifiers.saved import default_model_dir, load_models

    if model_dir is not None:
        load_models(model_dir)  # raises InputError naming the directory
        return str(Path(model_dir).resolve()), None
    try:
        load_models(None)
    except InputError as exc:
        return PRIOR, (f"no classification ({exc.problem}); floor_area, c_f and u_walls are "
                       "searched over their whole prior ranges")
    return str(default_model_dir().resolve()), None


#: Environment of the local cluster's worker processes (set before they start).
WORKER_ENV = {"MALLOC_ARENA_MAX": "2"}


def _client(scheduler: str | None, workers: int | None):
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout="20s"), None
        except OSError as exc:
            raise InputError(f"cannot reach the Dask scheduler ({exc})",
                             place="--scheduler") from None
    # Two malloc arenas per worker: with glibc's default (8 per core) the worker's threads
    # (event loop, task thread) fragment the batched fit's heap over several arenas and its
    # resident memory kept growing over a run (476 → 564 MB over 32 batches; with 2 arenas
    # 485 → 506 MB, +6 MB after the first half; same speed — README "Fleets"). glibc reads
    # it when a process starts: Dask's pre-spawn environment, not the worker's own.
    import dask

    with dask.config.set({f"distributed.nanny.pre-spawn-environ.{k}": v
                          for k, v in WORKER_ENV.items()}):
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                               processes=True, dashboard_address="127.0.0.1:0",
                               silence_logs=logging.ERROR)
    return Client(cluster), cluster


def _chunks(items: list[Source], size: int) -> list[list[Source]]:
    return [items[i:i + size] for i in range(0, len(items), size)]


def fit_fleet(
    input_path: str | Path,
    out: str | Path,
    *,
    model_dir: str | Path | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    tz: str = "Europe/Ljubljana",
    timestamps: str = "instant",
    resume: bool = False,
    batch_size: int = DEFAULT_BATCH,
    progress: bool = True,
    echo: Callable[[str], None] = print,
    client=None,
    night_gain_w: float | None = None,
    night_gain_sd_w: float | None = None,
) -> FleetRun:
    """Fit every household of ``input_path`` into the FLEET dataset ``out`` (module docstring).

    ``client``: an existing ``distributed.Client`` to run on (left open), instead of
    ``scheduler`` or a local cluster. ``night_gain_w``, ``night_gain_sd_w``: a night gain
    declared for every household [W] (None: not declared; ``impctl fit --night-gain-w``).

    Raises
    ------
    InputError
        Unreadable INPUT, ``out`` already there without ``resume``, unusable ``model_dir``,
        unreachable scheduler. Households with bad data are rows, not errors.
    """
    started = time.perf_counter()
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a FLEET dataset folder", out)
    if out.exists() and any(out.iterdir()) and not resume:
        raise InputError("exists: pass --resume to continue it, or remove it first", out)
    if batch_size < 1:
        raise InputError("must be >= 1", place="batch size")
    sources = discover(input_path)
    run = FleetRun(found=len(sources))
    done = done_households(out) if resume else set()
    todo = [s for s in sources if s.household not in done]
    run.skipped = len(sources) - len(todo)
    resolved, note = resolve_models(model_dir)
    if note:
        run.notes.append(note)
        echo(f"note: {note}")
    if run.skipped:
        echo(f"resume: {run.skipped} of {len(sources)} households already in {out}")
    if not todo:
        run.wall_s = time.perf_counter() - started
        return run
    settings = Settings(model_dir=resolved, tz=tz, timestamps=timestamps,
                        night_gain_w=night_gain_w, night_gain_sd_w=night_gain_sd_w)
    own = client is None
    if own:
        client, cluster = _client(scheduler, workers)
    futures = []
    try:
        client.register_plugin(Preload(settings.model_dir))
        run.workers = len(client.scheduler_info().get("workers", {}))
        run_id = new_run_id()
        # A small fleet is cut finer, so that every worker gets about two batches.
        size = max(1, min(batch_size, -(-len(todo) // (2 * max(1, run.workers)))))
        batches = _chunks(todo, size)
        futures = [client.submit(fit_batch, b, settings, pure=False,
                                 key=f"impctl-fleet-{run_id}-{i}", priority=-i)
                   for i, b in enumerate(batches)]
        index = {f.key: i for i, f in enumerate(futures)}
        _collect(futures, index, batches, out, run_id, run, progress)
    except KeyboardInterrupt:
        for f in futures:
            f.cancel()
        raise
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
    run.wall_s = time.perf_counter() - started
    return run


def _collect(futures, index, batches, out: Path, run_id: str, run: FleetRun,
             progress: bool) -> None:
    from distributed import as_completed
    from tqdm import tqdm

    bar = tqdm(total=sum(len(b) for b in batches), unit="household", desc="fleet fit",
               disable=not progress, file=sys.stderr, dynamic_ncols=True,
               mininterval=0.5 if sys.stderr.isatty() else 5.0)
    try:
        for future in as_completed(futures):
            i = index[future.key]
            try:
                rows = future.result()
            except Exception as exc:  # a lost worker, a crash outside the per-household guard
                rows = []
                for s in batches[i]:
                    row = empty_row(s.household)
                    row.update(reason="worker failed", error=f"{type(exc).__name__}: {exc}")
                    rows.append(row)
            write_part(out, run_id, i, rows)
            for row in rows:
                run.counts[row["status"]] = run.counts.get(row["status"], 0) + 1
            future.release()
            bar.set_postfix(ok=run.counts["ok"], insufficient=run.counts["insufficient"],
                            failed=run.counts["error"], refresh=False)
            bar.update(len(rows))
    finally:
        bar.close()
