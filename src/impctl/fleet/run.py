"""``impctl fleet fit``: households in batches on a Dask cluster, FLEET.parquet batch by batch.

The client discovers the households (:mod:`.inputs`), drops those already in FLEET.parquet when
resuming, and submits one Dask task per batch (:func:`.worker.fit_batch`); workers read their
own households' files, so INPUT and the model directory must be reachable under the same paths
on every worker (a shared file system on a multi-machine cluster). As batches finish, the client
writes each one as its own part of FLEET.parquet (:mod:`.results.table`), updates the
manifest (:mod:`.results.manifest`: households expected and done — an interrupted run reads as
partial) and the progress bar (households done, failed, rate).

Before anything starts, the places are checked: ``out`` must lie outside INPUT (and INPUT
outside ``out``: parts written there would be households of the next run), be new, empty or —
with ``resume`` — a FLEET dataset of the same INPUT and options; the scheduler address must
read as one. One run at a time writes an ``out`` (:mod:`.results.lock`). Every refusal is one
line and says what to do instead.

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
from ..fit.household import FitOptions
from .inputs import Source, discover, layout_note
from .results.lock import LOCK_FILE, holding
from .results.manifest import MANIFEST_FILE, Manifest, read_manifest, recount, write_manifest
from .results.table import (
    WORKER_FAILED,
    done_households,
    drop_failed_parts,
    empty_row,
    new_run_id,
    write_part,
)
from .worker import PRIOR, Preload, Settings, classifiers_digest, fit_batch

DEFAULT_BATCH = 64


@dataclass
class FleetRun:
    """What a run did: households found / skipped (resume) / fitted per status, wall time [s],
    households whose IMP fit (or, their nights all unchanged, whole row) was carried over from
    ``previous``."""

    found: int = 0
    skipped: int = 0
    counts: dict[str, int] = field(default_factory=lambda: {"ok": 0, "insufficient": 0,
                                                             "error": 0})
    wall_s: float = 0.0
    workers: int = 0
    reused: int = 0      # households whose IMP fit came from ``previous``
    unchanged: int = 0   # … and whose nights were all the same: the whole row
    changed: int = 0     # households whose heat loss changed (``season_changed``)
    notes: list[str] = field(default_factory=list)

    @property
    def fitted(self) -> int:
        return sum(self.counts.values())


def resolve_models(model_dir: str | Path | None) -> tuple[str, str | None]:
    """(model dir for the workers, or PRIOR; a note when falling back to the prior ranges).

    An explicitly given directory that holds no usable classifiers is bad input; the default
    directory without them means "search the prior ranges", as ``impctl fit`` does.
    """
    from ..classifiers.files.saved import default_model_dir, load_classifiers

    # what the workers (and impctl fit) load: the compact forests, else the pickled ones
    if model_dir is not None:
        load_classifiers(model_dir)  # raises InputError naming the directory
        return str(Path(model_dir).resolve()), None
    try:
        load_classifiers(None)
    except InputError as exc:
        return PRIOR, (f"no classification ({exc.problem}); floor_area, c_f and u_walls are "
                       "searched over their whole prior ranges")
    return str(default_model_dir().resolve()), None


#: Environment of the local cluster's worker processes (set before they start).
WORKER_ENV = {"MALLOC_ARENA_MAX": "2"}
#: Dask settings of the local cluster's workers. The statistical profiler samples every
#: worker's stack every 10 ms for a dashboard a batch run never opens; with every core running
#: a worker it took about 4 % of the throughput (2 workers on 2 cores, 448 households: 12.35 →
#: 12.9 households/s without it). A separate ``dask worker`` reads the same from
#: ``DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED=False`` (docs/how-to/fleet-dask.md).
WORKER_CONFIG = {"distributed.worker.profile.enabled": False}


def _client(scheduler: str | None, workers: int | None):
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(check_scheduler(scheduler), timeout="20s"), None
        except (OSError, ValueError) as exc:
            raise InputError(f"cannot reach the Dask scheduler ({exc})",
                             place="--scheduler") from None
    # Two malloc arenas per worker: with glibc's default (8 per core) the worker's threads
    # (event loop, task thread) fragment the batched fit's heap over several arenas and its
    # resident memory kept growing over a run (476 → 564 MB over 32 batches; with 2 arenas
    # 485 → 506 MB, +6 MB after the first half; same speed — README "Fleets"). glibc reads
    # it when a process starts: Dask's pre-spawn environment, not the worker's own.
    import dask

    # the nannies hand their own Dask settings to the workers they start
    with dask.config.set({**{f"distributed.nanny.pre-spawn-environ.{k}": v
                             for k, v in WORKER_ENV.items()}, **WORKER_CONFIG}):
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                               processes=True, dashboard_address="127.0.0.1:0",
                               silence_logs=logging.ERROR)
    return Client(cluster), cluster


def _chunks(items: list[Source], size: int) -> list[list[Source]]:
    return [items[i:i + size] for i in range(0, len(items), size)]


def check_scheduler(address: str) -> str:
    """``address`` if it reads as a Dask scheduler's (``tcp://HOST:PORT``, or tls/ws/wss/ucx),
    else InputError naming ``--scheduler`` (before anything is started or written)."""
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address, strict=True)
        if scheme not in ("tcp", "tls", "ws", "wss", "ucx"):
            raise ValueError(f"unknown scheme {scheme!r}")
        host, port = parse_host_port(location)
        if not host or not 0 < int(port) < 65536:
            raise ValueError("no host, or a port outside 1–65535")
    except (ValueError, TypeError) as exc:
        raise InputError(f"{address!r} is not a Dask scheduler address ({exc}); give "
                         "tcp://HOST:PORT, e.g. tcp://127.0.0.1:8786", place="--scheduler"
                         ) from None
    return address


def _inside(inner: Path, outer: Path) -> bool:
    return inner == outer or outer in inner.parents


def check_places(input_path: str | Path, out: str | Path, report: str | Path | None = None
                 ) -> None:
    """Refuse an output folder that overlaps the input (parts written into it would be read
    as households by the next run, and a run could read its own output) or the report folder
    (its HTML and PNG files inside a FLEET dataset make it unreadable)."""
    src, dst = Path(input_path).resolve(), Path(out).resolve()
    if _inside(dst, src) or _inside(src, dst):
        where = ("is INPUT itself" if src == dst else "is inside INPUT" if _inside(dst, src)
                 else "contains INPUT")
        raise InputError(f"{where} ({src}): the FLEET parts would be read as households by "
                         f"the next run; give a folder outside it, e.g. --out "
                         f"{src.parent / (src.stem + '-FLEET.parquet')}", out, "--out")
    if report is not None:
        rep = Path(report).resolve()
        if _inside(rep, dst) or _inside(dst, rep):
            raise InputError("overlaps --out: the report's files inside a FLEET dataset make "
                             "it unreadable; give another folder", report, "--report")


def _start_manifest(out: Path, input_path, sources: list[Source], done: set[str],
                    options: dict, resume: bool) -> Manifest:
    """The manifest of this run: a new one, or the one being resumed (same input, same
    options — else the dataset would mix two different fits)."""
    found = {s.household for s in sources}
    source = str(Path(input_path).resolve())
    old = read_manifest(out) if resume else None
    if old is not None:
        changed = sorted(k for k in {*options, *old.options}
                         if options.get(k) != old.options.get(k))
        if old.input != source or changed:
            what = (f"input {old.input}" if old.input != source else
                    ", ".join(f"{k} {old.options.get(k)!r}" for k in changed))
            raise InputError(f"was fitted with {what}; resume it with the same input and "
                             "options, or give a new --out", out)
        old.households, old.done = len(found), len(found & done)
        old.expected = sorted(found)
        return old
    return Manifest(input=source, options=options, households=len(found),
                    done=len(found & done), expected=sorted(found))


def _check_out(out: Path, input_path: str | Path, resume: bool) -> None:
    """``out`` must be new, empty, or — with ``resume`` — a FLEET dataset of this input. The
    advice given never leads into a refusal: ``--resume`` is suggested only where it works."""
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a FLEET dataset folder", out)
    if not out.exists() or not any(p.name != LOCK_FILE for p in out.iterdir()):
        return
    foreign = [p.name for p in out.iterdir() if not (
        p.name == MANIFEST_FILE or p.name.startswith(".")
        or (p.name.startswith("part-") and p.suffix == ".parquet"))]
    if foreign:
        more = f" and {len(foreign) - 1} more" if len(foreign) > 1 else ""
        raise InputError(f"exists and is not a FLEET dataset (it holds {foreign[0]}{more}); "
                         "give a new --out", out)
    old = read_manifest(out)
    if old is not None and old.input != str(Path(input_path).resolve()):
        raise InputError(f"holds the FLEET dataset of another input ({old.input}); give a new "
                         "--out, or remove it first", out)
    if not resume:
        status = f" ({old.status(out).split(' (')[0]})" if old is not None else ""
        raise InputError(f"exists{status}: pass --resume to continue it, or remove it first",
                         out)
    import pyarrow.parquet as pq

    from .results.table import SCHEMA

    part = next(out.glob("part-*.parquet"), None)
    if part is not None and pq.read_schema(part).names != SCHEMA.names:
        # parts of two layouts in one dataset: a reader takes one layout and drops or
        # empties the other's columns
        raise InputError("was written by another impctl version (its columns differ): give a "
                         "new --out", out)
    if part is not None:
        import pyarrow.dataset as ds

        from .results.table import version

        written = set(ds.dataset(sorted(out.glob("part-*.parquet")), format="parquet")
                      .to_table(columns=["impctl_version"]).column(0).to_pylist())
        other = sorted(str(v) for v in written - {version()})
        if other:
            # rows of two codes in one dataset: resumed, the rest would be another code's fit
            raise InputError(f"was written by another impctl version ({other[0]}, this is "
                             f"{version()}): give a new --out", out)
    if old is None and any(out.glob("part-*.parquet")):
        raise InputError("holds FLEET parts but no manifest, so the options its rows were "
                         "fitted with are not known: give a new --out", out)


def fit_fleet(
    input_path: str | Path,
    out: str | Path,
    *,
    model_dir: str | Path | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    tz: str = "Europe/Ljubljana",
    options: FitOptions | None = None,
    resume: bool = False,
    previous: str | Path | None = None,
    batch_size: int = DEFAULT_BATCH,
    progress: bool = True,
    echo: Callable[[str], None] = print,
    client=None,
) -> FleetRun:
    """Fit every household of ``input_path`` into the FLEET dataset ``out`` (module docstring).

    ``options``: what decides a household's numbers, as ``impctl fit``'s options (default:
    its defaults; a night gain declared for every household among them). ``client``: an
    existing ``distributed.Client`` to run on (left open), instead of ``scheduler`` or a local
    cluster. ``out/_manifest.json`` says how many households are expected and how many have a
    row (:mod:`.results.manifest`), after every batch. ``previous``: the last run's FLEET
    dataset — a household whose IMP nights are unchanged keeps its IMP fit from there and its
    season search starts where that run's ended (:mod:`.results.previous`).

    Raises
    ------
    InputError
        Unreadable INPUT, ``out`` overlapping it, ``out`` already there without ``resume`` (or
        not a FLEET dataset, or fitted from another input or with other options), unusable
        ``model_dir``, a malformed or unreachable scheduler, a ``previous`` that is not a
        FLEET dataset (or is ``out``). Households with bad data are rows, not errors.
    KeyboardInterrupt
        Ctrl-C: the batches written stay, the manifest says "partial" (a line says how to
        resume).
    """
    started = time.perf_counter()
    out = Path(out)
    options = options if options is not None else FitOptions()
    if scheduler:
        check_scheduler(scheduler)
    if previous is not None and Path(previous).resolve() == out.resolve():
        raise InputError("is --out itself: give the last run's FLEET dataset and a new --out",
                         previous, "--previous")
    check_places(input_path, out)
    _check_out(out, input_path, resume)  # before the lock's file goes into a folder
    with holding(out):
        _check_out(out, input_path, resume)  # again: another run may have written since
        if batch_size < 1:
            raise InputError("must be >= 1", place="batch size")
        sources = discover(input_path)
        run = FleetRun(found=len(sources))
        layout = layout_note(sources, batch_size)
        if layout:
            run.notes.append(layout)
            echo(f"note: {layout}")
        if resume:
            drop_failed_parts(out)   # a lost worker's batch is fitted again
        done = done_households(out) if resume else set()
        todo = [s for s in sources if s.household not in done]
        run.skipped = len(sources) - len(todo)
        resolved, note = resolve_models(model_dir)
        from .results.table import version

        # what the rows depend on beyond the input: a resumed or a --previous dataset must agree on
        # all of it — the classifiers trained anew in the same folder, impctl's own code too
        decided = {**options.as_dict(), "tz": tz, "model_dir": resolved,
                   "classifiers": classifiers_digest(resolved), "impctl_version": version()}
        manifest = _start_manifest(out, input_path, sources, done, decided, resume)
        if note:
            run.notes.append(note)
            echo(f"note: {note}")
        last: dict[str, dict] = {}
        if previous is not None:
            from .results.previous import previous_rows

            last, said = previous_rows(previous, decided, version())
            run.notes.append(said)
            echo(f"note: {said}")
        if run.skipped:
            echo(f"resume: {run.skipped} of {len(sources)} households already in {out}")
        if not todo:
            write_manifest(out, manifest)
            run.wall_s = time.perf_counter() - started
            return run
        settings = Settings(model_dir=resolved, tz=tz, options=options)
        own, cluster = client is None, None
        if own:
            client, cluster = _client(scheduler, workers)
        futures = []
        try:
            # the workers of our own local cluster each keep to a CPU of their own
            client.register_plugin(Preload(settings.model_dir, len(cluster.workers)
                                           if cluster is not None else 0))
            run.workers = len(client.scheduler_info().get("workers", {}))
            run_id = new_run_id()
            manifest.runs.append(run_id)
            write_manifest(out, manifest)
            # A small fleet is cut finer, so that every worker gets about two batches.
            size = max(1, min(batch_size, -(-len(todo) // (2 * max(1, run.workers)))))
            batches = _chunks(todo, size)
            futures = [client.submit(fit_batch, b, settings,
                                     {s.household: last[s.household] for s in b
                                      if s.household in last} or None, pure=False,
                                     key=f"impctl-fleet-{run_id}-{i}", priority=-i)
                       for i, b in enumerate(batches)]
            index = {f.key: i for i, f in enumerate(futures)}
            _collect(futures, index, batches, out, run_id, run, progress, manifest)
        except KeyboardInterrupt:
            for f in futures:
                f.cancel()
            if (out / MANIFEST_FILE).exists():
                # Ctrl-C may land between a part's rename and the manifest's rewrite.
                write_manifest(out, recount(out, manifest))
                echo(f"interrupted: {manifest.status(out)}")
            raise
        finally:
            if own:
                client.close()
                if cluster is not None:
                    cluster.close()
        run.wall_s = time.perf_counter() - started
        return run


def _collect(futures, index, batches, out: Path, run_id: str, run: FleetRun,
             progress: bool, manifest: Manifest) -> None:
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
                    row.update(reason=WORKER_FAILED, error=f"{type(exc).__name__}: {exc}")
                    rows.append(row)
            write_part(out, run_id, i, rows)
            # a lost worker's rows are not done: --resume fits them again
            manifest.done += sum(r.get("reason") != WORKER_FAILED for r in rows)
            write_manifest(out, manifest)
            for row in rows:
                run.counts[row["status"]] = run.counts.get(row["status"], 0) + 1
                run.reused += bool(row.get("imp_fit_reused"))
                run.unchanged += bool(row.get("nights_unchanged"))
                run.changed += bool(row.get("season_changed"))
            future.release()
            bar.set_postfix(ok=run.counts["ok"], insufficient=run.counts["insufficient"],
                            failed=run.counts["error"], refresh=False)
            bar.update(len(rows))
    finally:
        bar.close()
