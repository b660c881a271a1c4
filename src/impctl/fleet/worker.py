"""What a Dask worker runs: one batch of households → one block of FLEET rows.

Each household goes the way ``impctl fit`` takes its file (:mod:`impctl.fit.household`): the
size guard before reading, the unit checks, the nights cut at gaps and chosen (``max_nights``),
the classes, the fit with the same options, and the check of the finished fit — so a row's
numbers and refusals are ``impctl fit``'s; only the optimiser calls of the batch's households
are merged (:func:`impctl.fit.optim.batch.fit_households`).

The classifiers and torch are loaded once per worker process — by the :class:`Preload` worker
plugin when the worker joins, else at the first batch — and kept in a module-level cache; a
batch never reloads them. Every household's outcome is a row: ``ok``, ``insufficient`` (too few
usable nights: the row says which kind is missing) or ``error`` (too large, unreadable,
implausible units or fit, failed fit: ``reason`` says which, ``error`` is the line
``impctl fit`` prints); nothing a household does stops the batch.
"""

from __future__ import annotations

import os
import socket
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..fit.household import FitOptions
from .inputs import Source, read_sources
from .results.table import empty_row

#: Worker-process cache: model directory → (models, metadata), and how often it was filled.
_MODELS: dict[tuple[str, str | None], tuple[dict, dict]] = {}
_LOADS = {"models": 0, "batches": 0}
_LOCK = threading.Lock()
PRIOR = "prior"


@dataclass(frozen=True)
class Settings:
    """What every batch of one run shares (sent to the workers with each task).

    ``model_dir`` is the classifiers' directory, or :data:`PRIOR` to search the whole prior
    ranges (no classifiers, as ``impctl fit`` does without them).
    """

    model_dir: str
    tz: str = "Europe/Ljubljana"
    options: FitOptions = field(default_factory=FitOptions)


def classifiers_digest(model_dir: str) -> str | None:
    """8 hex digits over the classifiers' metadata file in ``model_dir`` (every training writes
    it anew, with its time); None for :data:`PRIOR` or where there is none."""
    if model_dir == PRIOR:
        return None
    import hashlib
    from pathlib import Path

    from ..classifiers.files.saved import METADATA_FILE

    try:
        data = (Path(model_dir) / METADATA_FILE).read_bytes()
    except OSError:
        return None
    return hashlib.blake2b(data, digest_size=4).hexdigest()


def models(model_dir: str) -> tuple[dict, dict]:
    """The classifiers of ``model_dir``, loaded once per process (thread-safe) and again when
    they were trained anew there (a worker that outlives a run keeps no stale forests)."""
    key = (model_dir, classifiers_digest(model_dir))
    with _LOCK:
        if key not in _MODELS:
            from ..classifiers.files.saved import load_classifiers

            for old in [k for k in _MODELS if k[0] == model_dir]:
                del _MODELS[old]
            _MODELS[key] = load_classifiers(model_dir)
            _LOADS["models"] += 1
        return _MODELS[key]


def preload(model_dir: str) -> None:
    """Import torch, the fit and the season model, pin torch to one thread, load the
    classifiers, and read Parquet through the C library's allocator."""
    import pyarrow as pa
    import torch

    # Arrow's default pool (mimalloc or jemalloc) keeps the memory of each batch's read, backed by
    # transparent huge pages: a worker's RSS then wandered by ±50 MB from batch to batch and
    # crept up. With the system allocator, trimmed after each batch, it stays flat.
    if pa.default_memory_pool().backend_name != "system":
        pa.set_memory_pool(pa.system_memory_pool())

    from ..fit.optim import batch  # noqa: F401  (imports the fit)
    from ..season import fit  # noqa: F401  (and the season model: 0.5 s)

    torch.set_num_threads(1)
    if model_dir != PRIOR:
        models(model_dir)


def worker_state() -> dict:
    """This process's counters (for tests and the bench): pid, model loads, batches, RSS [MB]."""
    import psutil

    rss = psutil.Process().memory_info().rss / 2**20
    return {"pid": os.getpid(), "model_loads": _LOADS["models"], "batches": _LOADS["batches"],
            "rss_mb": rss}


try:
    from distributed.diagnostics.plugin import WorkerPlugin
except ImportError:  # pragma: no cover — distributed is a dependency
    WorkerPlugin = object  # type: ignore[misc,assignment]


def pin_to_cpu(index: int, n_workers: int) -> int | None:
    """Keep every thread of this process on one CPU: the ``index``-th of the CPUs this
    process may use, for worker ``index`` of ``n_workers`` on one machine. Returns the CPU, or
    None where there are fewer CPUs than workers (or the system cannot pin).

    Why: a batch's household threads hand a baton to each other hundreds of times a second
    (:mod:`impctl.fit.optim.batch`); unpinned, the kernel may wake the next one on another
    core, its caches cold. On two cores, the default cluster's 1,000 households took 12 %
    less wall time with its two workers pinned (decision record 0018)."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    cpus = sorted(os.sched_getaffinity(0))
    if not 0 <= index < n_workers <= len(cpus):
        return None
    cpu = cpus[index]
    # affinity is per thread: set it on every thread already running; later ones inherit it
    for tid in os.listdir("/proc/self/task"):
        try:
            os.sched_setaffinity(int(tid), {cpu})
        except OSError:   # a thread that has just ended
            pass
    return cpu


class Preload(WorkerPlugin):  # type: ignore[misc,valid-type]
    """Dask worker plugin: :func:`preload` when a worker starts (or joins later); with
    ``pin_workers`` (the number of workers of a local cluster, named 0…), each worker kept
    on a CPU of its own (:func:`pin_to_cpu`)."""

    def __init__(self, model_dir: str, pin_workers: int = 0):
        self.model_dir = model_dir
        self.pin_workers = pin_workers
        self.name = f"impctl-fleet-preload-{model_dir}"

    def setup(self, worker) -> None:  # noqa: D401 — Dask's hook
        preload(self.model_dir)
        if self.pin_workers and isinstance(worker.name, int):
            pin_to_cpu(worker.name, self.pin_workers)


_NEEDS = {"constrained": "no usable constrained night (it carries τ)",
          "normal": "no usable normal night with heat power (it carries HLC and C_m)"}


def fit_batch(sources: list[Source], settings: Settings,
              previous: dict[str, dict] | None = None) -> list[dict]:
    """Fit one batch of households; one FLEET row (a dict, :mod:`.results.table`) per
    household. ``previous``: the last run's rows of households of this batch
    (:mod:`.results.previous`) — where a household's IMP nights are unchanged, its IMP columns
    are carried over and its season search starts where that run's ended; where all its nights
    are, its whole row."""
    from ..fit.household import choose_nights
    from ..imp.night import split_owner
    from .results.previous import carry_over, nights_digests, theta_start

    started, cpu = time.perf_counter(), time.process_time()
    preload(settings.model_dir)
    _LOADS["batches"] += 1
    # No FLEET column reads the paper's per-night fits, and the joint fit does not depend on
    # them (they stop on their own: fit.layout.stop_units): skipping them saves ~10 % of
    # a batch.
    params = {**settings.options.estimator_params(), "per_night": False}
    rows: dict[str, dict] = {}
    todo: list[tuple] = []
    names = {s.household: _source_name(s) for s in sources}
    for household, nights in read_sources(sources, settings.tz).items():
        row = rows[household] = empty_row(household)
        if isinstance(nights, InputError):
            row.update(status="error", reason=getattr(nights, "reason", "unreadable input"),
                       error=str(nights))
            continue
        imp = {id(n) for n in split_owner(nights)[0]}
        digest, whole = nights_digests(nights, lambda n, imp=imp: id(n) in imp)
        row["nights_digest"] = whole
        last = (previous or {}).get(household)
        if last is not None and last.get("imp_nights_digest") == digest:
            unchanged = last.get("nights_digest") == whole
            carry_over(row, last, whole=unchanged)
            if not unchanged:
                _season(row, nights, theta_start(last), last.get("season_emitter"))
            continue
        row.update(imp_nights_digest=digest, imp_fit_reused=False, nights_unchanged=False)
        _season(row, nights)
        chosen = choose_nights(nights, settings.options.max_nights)
        row.update(nights_used=len(chosen.chosen),
                   nights_constrained=sum(n.kind == "constrained" for n in chosen.chosen),
                   nights_normal=sum(n.kind == "normal" for n in chosen.chosen),
                   nights_skipped=len(chosen.skipped))
        if chosen.missing:
            row.update(status="insufficient",
                       reason=" and ".join(_NEEDS[k] for k in chosen.missing),
                       error=str(chosen.too_little(names[household])))
            continue
        classes = _classify(chosen.cut, settings)
        row.update({f"{k}_class": v for k, v in classes.labels.items()})
        todo.append((chosen.nights, classes, names[household], row))
    if todo:
        _fit_todo(todo, params)
    # The batched fit keeps its freed heap during the batch (fewer page faults); once its
    # fits are gone (_fit_todo returned) the heap goes back, so a worker's memory stays flat
    # over the run (bench/fleet.py).
    from ..fit.optim._alloc import release_freed_memory

    del todo
    release_freed_memory()
    share = (time.perf_counter() - started) / max(1, len(rows))
    cpu_share = (time.process_time() - cpu) / max(1, len(rows))
    state = worker_state()
    for row in rows.values():
        row.update(batch_size=len(sources), wall_s_per_household=share,
                   cpu_s_per_household=cpu_share,
                   worker=f"{socket.gethostname()}:{state['pid']}",
                   worker_rss_mb=state["rss_mb"])
    return [rows[s.household] for s in sources]


def _season(row: dict, nights: list, start: tuple | None = None,
            start_emitter: str | None = None) -> None:
    """The season model's columns of a household with owner nights (empty without); its search
    only from ``start`` (θ of the last run's fit, whose emitter was ``start_emitter``) when
    given."""
    import math

    from ..season.emitter import tau_e_max_s
    from ..season.fit import fit_nights
    from .results.table import THETA_COLUMNS

    fit, note = fit_nights(nights, start=start, start_bound_s=None if start is None
                           else tau_e_max_s(start_emitter))
    row["season_note"] = note
    if fit is None:
        return
    row["season_warm_start"] = fit.warm_start
    row["season_emitter"] = fit.emitter
    # the fit JSON's source (declared | measured: … | assumed: …), its first word
    row["season_emitter_source"] = fit.emitter_dict()["source"].split(":")[0]
    row["season_defrost_draw_source"] = fit.defrost_by()
    row.update(zip(THETA_COLUMNS, fit.theta, strict=True))
    for k in ("hlc_w_per_k", "tau_h", "c_m_j_per_k"):
        row[f"season_{k}"] = fit.values[k]
        row[f"season_{k}_low"], row[f"season_{k}_high"] = fit.low[k], fit.high[k]
    row["season_owner_nights"] = fit.owner_nights
    c = fit.change
    row["season_changed"] = None if c is None else bool(c.changed)
    if c is not None and c.changed:
        import datetime as dt

        row["season_changed_since"] = dt.date.fromisoformat(c.since_date)
        row["season_change_w_per_k"] = c.delta_hlc_w_k
        row["season_change_w_per_k_low"] = c.low_w_k
        row["season_change_w_per_k_high"] = c.high_w_k
        row["season_change_nights_after"] = c.nights_after
    sig = fit.signature_hlc_w_per_k
    row["season_signature_hlc_w_per_k"] = sig if math.isfinite(sig) else None


def _classify(nights, settings: Settings):
    """The household's classes (:func:`impctl.fit.household.household_classes`, with this
    worker's classifiers), or the whole prior ranges without classifiers (as ``impctl fit``)."""
    from ..fit.household import household_classes, prior_classes

    if settings.model_dir == PRIOR:
        return prior_classes("no classifiers")
    return household_classes(nights, loaded=models(settings.model_dir))


def _source_name(s: Source) -> str:
    """The name errors give a household: its file, or its rows of a dataset."""
    return s.path if s.kind != "dataset" else f"{s.path} (household {s.household})"


def _fit_todo(todo: list[tuple], params: dict) -> None:
    """Fit the households of ``todo`` together and fill in their rows (nothing else is kept)."""
    from ..fit.household import fit_refusal
    from ..fit.optim.batch import fit_households

    results, _ = fit_households([t[0] for t in todo], [t[1].ranges for t in todo],
                                [t[1].probabilities for t in todo], **params)
    fitted = []
    for (*_, name, row), res in zip(todo, results, strict=True):
        if isinstance(res, InputError):
            row.update(status="insufficient", reason="no usable night", error=str(res))
        elif isinstance(res, BaseException):
            row.update(status="error", reason=f"fit failed ({type(res).__name__})",
                       error=f"{type(res).__name__}: {res}")
        elif (refusal := fit_refusal(res, name)) is not None:
            # a fit no house gives: impctl fit refuses it, so no numbers here either
            row.update(status="error", reason=refusal.reason, error=str(refusal))
        else:
            _fill(row, res)
            fitted.append((row, res))
    _flexibility(fitted)


def _fill(row: dict, fit) -> None:
    from .results.table import LUMPED_COLUMNS, PARAM_COLUMNS

    row.update(status="ok", reason=None, error=None)
    for key, col in LUMPED_COLUMNS.items():
        est = fit.lumped_[key]
        row[col], row[f"{col}_low"], row[f"{col}_high"] = est.value, est.low, est.high
        row[f"{col}_determined"] = bool(est.determined)
    for name, value in fit.parameters_.items():
        row[PARAM_COLUMNS[name]] = float(value)
    row["ach_vent_per_h"], row["ach_infl_per_h"] = fit.ach_vent, fit.ach_infl
    from ..flex.switch_off import to_columns

    row.update(to_columns(getattr(fit, "nuisance_", None)))
    row["night_gain_source"] = (getattr(fit, "night_gain_", None) or {}).get("source")
    row["class_contradicted"] = bool(fit.class_check_.get("rejected", False))
    row["needs_more_nights"] = not all(e.determined for e in fit.lumped_.values())
    row["loss"] = float(fit.loss_)
    val = (fit.validation_ or {}).get("mean") or {}
    row["eps_pct"] = val.get("eps_pct")


def _flexibility(fitted: list[tuple[dict, object]]) -> None:
    """coast_h, rebound_kwh for all fitted households of the batch in one vectorised run."""
    if not fitted:
        return
    from ..flex import SwitchOff, flexibility_many, switch_off_from_fit
    from ..model import HouseParameters

    try:
        houses = HouseParameters.stack([HouseParameters(
            **fit.parameters_, ach_vent=fit.ach_vent, ach_infl=fit.ach_infl)
            for _, fit in fitted])
        tau = np.array([[f.lumped_["tau"].low, f.lumped_["tau"].high] for _, f in fitted])
        # the fit's switch-off terms, read as the fit JSON's flexibility block reads them
        terms = SwitchOff.stack([switch_off_from_fit({"nuisance": getattr(f, "nuisance_", None)})
                                 for _, f in fitted])
        flex = flexibility_many(houses, tau[:, 0], tau[:, 1], switch_off=terms)
    except InputError:
        return  # a fitted house the model refuses: the flexibility columns stay empty
    for (row, _), f in zip(fitted, flex, strict=True):
        row.update(coast_h=f.coast_h, coast_h_low=f.coast_h_low, coast_h_high=f.coast_h_high,
                   rebound_kwh=f.rebound_kwh, switch_off_drop_k=f.switch_off_drop_k)
