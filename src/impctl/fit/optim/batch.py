"""Many households in one batched Levenberg–Marquardt call (the fleet's inner loop).

:func:`fit_households` fits each household with exactly :class:`~impctl.fit.NightFit`'s own
procedure — the same preparation, starts, class check, refits, intervals and validation — but
every optimiser call of every household in the batch is merged into ONE call of
:func:`impctl.fit.optim.lm.levenberg_marquardt`, as the single fit already merges its starts and
nights. A single fit spends most of its time in Python overhead on small tensors; merged, the
same work is a few large tensor operations, so a household costs much less in a batch than alone
(``bench/fleet.py``).

How: each household runs ``NightFit.fit`` in its own thread with the optimiser step replaced by
:class:`_BatchFit._optimise`, which hands its problem to a :class:`_Rendezvous` and waits; the
household threads take turns (one runs, from its start or its last result to its next problem
or its end), which halves a batch's CPU against letting them all run at once. When
every household still running is waiting, the rendezvous merges their problems — nights
concatenated (grids padded to the longest), problem, night and group indices offset — solves
them together and hands each household its slice back. Problems stay independent in the merged
call (per-problem damping, per-problem convergence, and each household stops at the iteration
where it would stop alone: ``units`` of :func:`~impctl.fit.optim.lm.levenberg_marquardt`), so each
household's numbers equal its single fit up to rounding; problems that are done are no longer
evaluated, so a household that converges early costs nothing while the slowest one finishes.
Every night keeps its own sample times, so households of any sampling share a call; shorter
nights are padded with zero-length steps.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass, field, fields

import torch

from ...imp.night import NightSamples
from ..estimator import NightFit, stop_units
from ..ode.packing import PackedNights
from ..prior import PriorSlices, with_class_probabilities
from . import lm
from ._alloc import retain_freed_memory


class _BatchFit(NightFit):
    """A NightFit whose Levenberg–Marquardt calls go through a shared rendezvous."""

    _rendezvous: _Rendezvous | None = None
    _household = 0   # position in the batch: the merged call's order

    def _optimise(self, rows, u0, t_m0, groups) -> lm.LMResult:
        if self.optimizer != "lm" or self._rendezvous is None:
            return super()._optimise(rows, u0, t_m0, groups)
        return self._rendezvous.solve(_Problem(self._ctx, rows, u0, t_m0, groups, self.max_iter,
                                               self._household))


@dataclass
class _Problem:
    ctx: lm.Context
    rows: lm.Rows
    u0: torch.Tensor
    t_m0: torch.Tensor
    groups: torch.Tensor
    max_iter: int
    household: int = 0
    result: lm.LMResult | None = None
    error: BaseException | None = None
    done: threading.Event = field(default_factory=threading.Event)


class _Rendezvous:
    """Collects the optimiser problems of all running households and solves them together."""

    def __init__(self, n_running: int):
        # The main thread waits here for every running household to hand in a problem; each
        # household waits on its own problem's event. One condition for both woke every
        # waiting household at each hand-in to check its own flag: a batch's threads woken
        # n² times a round.
        self._server = threading.Condition()
        # One household thread runs at a time (it holds the baton from its start or its last
        # merged result to its next problem or its end). Torch releases the GIL in every
        # tensor operation; with dozens of runnable threads each release became a handoff
        # between them: millions of futex calls and a third of a batch's CPU in the kernel.
        self._baton = threading.Lock()
        self._running = n_running
        self._pending: list[_Problem] = []
        self.merged_calls = 0

    def start(self) -> None:
        """A household thread begins: wait for the baton."""
        self._baton.acquire()

    def solve(self, problem: _Problem) -> lm.LMResult:
        with self._server:
            self._pending.append(problem)
            self._baton.release()
            self._server.notify()
        problem.done.wait()
        self._baton.acquire()
        if problem.error is not None:
            raise problem.error
        assert problem.result is not None
        return problem.result

    def finished(self) -> None:
        with self._server:
            self._running -= 1
            self._baton.release()
            self._server.notify()

    def serve(self) -> None:
        """Run merged solves until every household has finished (call from the main thread)."""
        while True:
            with self._server:
                self._server.wait_for(lambda: len(self._pending) == self._running)
                if self._running == 0:
                    return
                batch, self._pending = self._pending, []
            # in household order, not in the order the threads arrived: where a problem sits
            # in the merged tensors can change the last bit of its rounding, and a household
            # on a flat loss surface carries that further (run to run up to 1e-2 before)
            batch.sort(key=lambda p: p.household)
            for group in _compatible_groups(batch):
                _solve_group(group)
                self.merged_calls += 1
            for p in batch:
                p.done.set()


def _compatible_groups(problems: list[_Problem]) -> list[list[_Problem]]:
    """Problems that can share one call: the same settings and parameter layout. Each night
    keeps its own sample times (``PackedNights.grid_s`` is per night), so nights of any
    sampling merge; a shorter night is padded the way
    :func:`~impctl.fit.ode.packing.pack_nights` pads it."""
    groups: dict[tuple, list[_Problem]] = {}
    for p in problems:
        groups.setdefault(_settings(p), []).append(p)
    return list(groups.values())


def _settings(p: _Problem) -> tuple:
    # not the prior: each problem keeps its own in the merged call (prior.PriorSlices)
    return (p.ctx.ach_vent, p.ctx.ach_infl, p.ctx.ridge, p.ctx.solver, p.ctx.gain_prior,
            p.max_iter,
            p.ctx.packed.timestamps,
            tuple(p.u0.shape[1:]), tuple(p.rows.box.shape[1:]),
            p.ctx.packed.power_ok is None, p.ctx.packed.emitter_lag)


def _pad(x: torch.Tensor, k: int) -> torch.Tensor:
    """(N, K0) → (N, k) holding the last column (what pack_nights does past a night's end)."""
    if x.shape[1] == k:
        return x
    return torch.cat([x, x[:, -1:].expand(-1, k - x.shape[1])], dim=1)


def _merge_packed(parts: Sequence[PackedNights]) -> PackedNights:
    k = max(p.grid_s.shape[1] for p in parts)
    cols = {}
    for f in fields(PackedNights):
        name = f.name
        if name in ("night_ids", "kinds"):
            cols[name] = [x for p in parts for x in getattr(p, name)]
        elif name in ("timestamps", "emitter_lag"):   # equal within a group (_settings)
            cols[name] = getattr(parts[0], name)
        elif name == "q_mean_w":
            cols[name] = torch.cat([p.q_mean_w for p in parts])
        elif name == "gain_w":
            cols[name] = (None if all(p.gain_w is None for p in parts) else torch.cat([
                torch.zeros(p.n_nights, dtype=p.q_mean_w.dtype) if p.gain_w is None
                else p.gain_w for p in parts]))
        elif name.endswith("_slope"):  # zero-length padded intervals have no slope
            cols[name] = torch.cat([torch.cat([getattr(p, name), torch.zeros(
                p.n_nights, k - p.grid_s.shape[1], dtype=getattr(p, name).dtype)], 1)
                for p in parts])
        elif name in ("mask", "last"):
            cols[name] = torch.cat([torch.cat([getattr(p, name), torch.zeros(
                p.n_nights, k - p.grid_s.shape[1], dtype=torch.bool)], 1) for p in parts])
        elif name == "next_node":
            cols[name] = torch.cat([torch.cat([p.next_node, torch.arange(p.grid_s.shape[1], k)
                                               .expand(p.n_nights, -1)], 1) for p in parts])
        elif name == "power_ok":
            cols[name] = None if parts[0].power_ok is None else torch.cat([torch.cat(
                [p.power_ok, torch.ones(p.n_nights, k - p.grid_s.shape[1], dtype=torch.bool)],
                1) for p in parts])
        else:  # grid_s and the values: hold the last node, as pack_nights does
            cols[name] = torch.cat([_pad(getattr(p, name), k) for p in parts])
    return PackedNights(**cols)


def _solve_group(group: list[_Problem]) -> None:
    if len(group) == 1:
        _solve_alone(group[0])
        return
    packed = _merge_packed([p.ctx.packed for p in group])
    k = packed.grid_s.shape[1]
    first = group[0].ctx
    problem, night, groups, units, owner = [], [], [], [], []
    p_off = n_off = g_off = u_off = 0
    for i, p in enumerate(group):
        owner.append(torch.full((p.rows.n_problems,), i, dtype=torch.long))
        problem.append(p.rows.problem + p_off)
        night.append(p.rows.night + n_off)
        groups.append(p.groups + g_off)
        units.append(stop_units(p.groups) + u_off)
        u_off = int(units[-1].max()) + 1
        p_off += p.rows.n_problems
        n_off += p.ctx.packed.n_nights
        g_off += int(p.groups.max()) + 1
    ctx = lm.Context(packed, first.ach_vent, first.ach_infl, first.ridge, first.solver,
                     PriorSlices(tuple(p.ctx.prior for p in group), torch.cat(owner))
                     if any(p.ctx.prior is not None for p in group) else None,
                     gain_prior=first.gain_prior)
    rows = lm.Rows(
        torch.cat(problem), torch.cat(night), torch.cat([p.rows.row_type for p in group]),
        torch.cat([_pad(p.rows.phi_w, k) for p in group]),
        torch.cat([_pad(p.rows.phi_in_w, k) for p in group]),
        torch.cat([p.rows.scale for p in group]), torch.cat([p.rows.box for p in group]), p_off)
    try:
        res = lm.levenberg_marquardt(ctx, rows, torch.cat([p.u0 for p in group]),
                                     torch.cat([p.t_m0 for p in group]),
                                     groups=torch.cat(groups), units=torch.cat(units),
                                     max_iter=group[0].max_iter)
    except Exception:  # noqa: BLE001 — one household's singular system must not sink the rest
        for p in group:
            _solve_alone(p)
        return
    p_off = r_off = 0
    for p in group:
        n_p, n_r = p.rows.n_problems, len(p.t_m0)
        ps, rs = slice(p_off, p_off + n_p), slice(r_off, r_off + n_r)
        p.result = lm.LMResult(res.u[ps], res.t_m0[rs], res.loss[ps], res.cov_u[ps],
                               res.fisher_u[ps], int(res.iterations[ps].max()),
                               res.converged[ps], list(res.history),
                               terms=None if res.terms is None else
                               res.terms.take(rs).trimmed(p.ctx.packed.grid_s.shape[1]))
        p_off, r_off = p_off + n_p, r_off + n_r


def _solve_alone(p: _Problem) -> None:
    try:
        p.result = lm.levenberg_marquardt(p.ctx, p.rows, p.u0, p.t_m0, groups=p.groups,
                                          units=stop_units(p.groups), max_iter=p.max_iter)
    except Exception as exc:  # noqa: BLE001 — handed to the household's own thread
        p.error = exc


@dataclass
class BatchStats:
    """What a batch cost: households, merged optimiser calls, wall time [s]."""

    households: int
    merged_calls: int
    wall_s: float


def fit_households(
    nights: Sequence[Sequence[NightSamples]],
    ranges: Sequence[dict[str, tuple[float, float]] | None],
    probabilities: Sequence[dict | None] | None = None,
    **params,
) -> tuple[list[NightFit | BaseException], BatchStats]:
    """Fit many households together; per household the result of ``NightFit(**params).fit``.

    Parameters
    ----------
    nights : per household, its nights (as for :meth:`NightFit.fit`)
    ranges : per household, the class ranges of floor_area, c_f, u_walls (or None: prior)
    probabilities : per household, the classifiers' class probabilities (or None): the
        population prior mixes the classes by them, as ``impctl fit`` does
        (:func:`~impctl.fit.prior.with_class_probabilities`)
    **params : NightFit constructor parameters, the same for every household

    Returns
    -------
    results : per household the fitted estimator, or the exception its fit raised (an
        :class:`~impctl.errors.InputError` for unusable nights) — one household never stops
        the others
    stats : :class:`BatchStats`
    """
    import time

    if len(nights) != len(ranges):
        raise ValueError("nights and ranges must have one entry per household")
    started = time.perf_counter()
    rendezvous = _Rendezvous(len(nights))
    results: list[NightFit | BaseException] = [RuntimeError("not run")] * len(nights)

    def run(i: int) -> None:
        rendezvous.start()
        est = None
        try:   # whatever fails, the household leaves the rendezvous (else the batch waits)
            est = _BatchFit(**params)
            if probabilities is not None:
                est.prior = with_class_probabilities(est.prior, probabilities[i])
            est._rendezvous = rendezvous
            est._household = i
            results[i] = est.fit(nights[i], ranges[i])
        except BaseException as exc:  # noqa: BLE001 — reported per household
            results[i] = exc
        finally:
            if est is not None:
                est._rendezvous = None
            rendezvous.finished()

    retain_freed_memory()
    threads_before = torch.get_num_threads()
    torch.set_num_threads(1)  # NightFit.fit saves and restores this per thread; keep it fixed
    workers = [threading.Thread(target=run, args=(i,), daemon=True) for i in range(len(nights))]
    try:
        for t in workers:
            t.start()
        rendezvous.serve()
        for t in workers:
            t.join()
    finally:
        torch.set_num_threads(threads_before)
    return results, BatchStats(len(nights), rendezvous.merged_calls,
                               time.perf_counter() - started)
