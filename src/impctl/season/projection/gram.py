"""The gains' Gram products SSᵀ, SGᵀ, GGᵀ from the structure of their shapes.

Most of the season model's X is the gains' family: each shape (night, day, a day's sun, a knot
of the slow gain, the household electricity) s_j gives the column α_j·s_j + β_j·g_j, g_j its
held low-pass (:func:`~.columns.held_lowpass`, τ_mm) and α, β numbers of θ. So that block of
XᵀX is α αᵀ∘SSᵀ + α βᵀ∘SGᵀ + β αᵀ∘GSᵀ + β βᵀ∘GGᵀ, where SSᵀ never changes and SGᵀ, GGᵀ
change with τ_mm alone (:mod:`.normal` assembles XᵀX from them).

SGᵀ and GGᵀ are not formed from dense rows either. A day's sun and a knot are zero outside a
day or two (their *window*); the low-pass of such a shape is zero before its window and, after
it, its last value times ρ^(blocks since), ρ = exp(−block/τ_mm) — within one stretch of the
heat store, where the filter runs. A product of two such rows over the usable blocks is then
the product over the windows plus sums of geometric tails, which reverse first-order filters
give at every block at once: O(m·window + m²) for m shapes instead of O(m²·blocks). Shapes
without a short window (the night and day levels, the household electricity) are kept as
dense rows. Exact, not an approximation: the tests compare it with the dense products. The
same windows and tails give any series' products with the shapes' low-pass
(:func:`cross_products`) and the diagonals alone (:func:`gain_diag`: the columns' scales).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from .columns import Design, gain_coefficients, held_lowpass

Array = NDArray[np.float64]

#: Longest window a shape is handled by its window and tail [s]; longer, as a dense row. A
#: knot of the slow gain spans two days.
WINDOW_MAX_S = 3 * 86400.0


def _rev(x: Array, r: float) -> Array:
    """y(c) = Σ_{t≥c} x(t)·r^(t−c) along the last axis (a reverse first-order filter)."""
    return lfilter([1.0], [1.0, -r], x[..., ::-1], axis=-1)[..., ::-1]


def _after(x: Array, r: float) -> Array:
    """Σ_{t>c} x(t)·r^(t−c) along the last axis: what follows block c, discounted."""
    y = _rev(x, r)
    out = np.zeros_like(y)
    out[..., :-1] = r * y[..., 1:]
    return out


@dataclass
class _Run:
    """One stretch of the heat store (blocks lo…lo + n) and its shapes, fixed for the record.
    The windowed shapes ("local") are in order of their windows' starts."""

    n: int                      # blocks in the stretch
    mask: Array                 # (n,) 1 at a usable block
    used: slice                 # its usable blocks in the order of X's rows
    used_at: NDArray[np.int64]  # their blocks, counted from the stretch's start
    local: NDArray[np.int64]    # shapes handled by their window
    start: NDArray[np.int64]    # each one's window's first block
    end: NDArray[np.int64]      # its last: after it, the low-pass is a geometric tail
    at: NDArray[np.int64]       # (local · width,) the windows' blocks, clipped to the stretch
    used_win: Array             # (local, width) 1 at a usable block inside the stretch
    s_win: Array                # (local, width) the shapes on their windows, 0 past the end
    s_win_used: Array           # the same at usable blocks only
    dense: NDArray[np.int64]    # shapes kept as whole rows
    s_dense: Array              # (dense, n)
    s_dense_at: Array           # (dense, local, width) at the windows' blocks
    # pairs of windows that overlap: i ≤ k in window order, k's window starts `shift` later
    pair_i: NDArray[np.int64]
    pair_k: NDArray[np.int64]
    pair_at: NDArray[np.int64]  # (pairs, width) into i's flattened window, past it → the 0
    # the window functions F_i(end_k) (:func:`_at_ends`): where end_k falls in window i
    end_in: Array               # (local, local) 1 where start_i ≤ end_k < end_i
    end_at: NDArray[np.int64]   # flattened index of y_i(end_k − start_i + 1)
    end_before: NDArray[np.int64]  # start_i − end_k where end_k < start_i, else −1
    end_gap: NDArray[np.int64]  # |end_i − end_k|
    end_later: NDArray[np.bool_]   # end_i ≥ end_k
    order: NDArray[np.int64]    # (local + dense)², flat indices into the shapes' m × m


def _layout(d: Design) -> list[_Run]:
    """The stretches' windows and dense rows (what depends on the record alone)."""
    block_s = d.rec.per_block * d.rec.step_s
    cap = max(2, int(WINDOW_MAX_S / block_s))
    used = np.flatnonzero(d.blocks)
    m = d.gains_b.shape[0]
    out = []
    for lo, hi in d.block_runs:
        x = d.gains_b[:, lo:hi]
        n = hi - lo
        nz = x != 0
        has = nz.any(axis=1)
        first = np.argmax(nz, axis=1)
        last = n - 1 - np.argmax(nz[:, ::-1], axis=1)
        span = last - first + 2         # the window holds the block after the shape's last
        local = np.flatnonzero(has & (span <= cap))
        local = local[np.argsort(first[local], kind="stable")]
        dense = np.flatnonzero(has & (span > cap))
        nl = len(local)
        width = int(span[local].max()) if nl else 1
        start = first[local]
        end = np.minimum(start + width - 1, n - 1)
        pos = start[:, None] + np.arange(width)
        inside = (pos < n).astype(float)
        at = np.minimum(pos, n - 1).ravel()
        mask = d.blocks[lo:hi].astype(float)
        s_win = np.take_along_axis(x[local], np.minimum(pos, n - 1), axis=1) * inside
        # overlapping windows (sorted by start: a band)
        pi, pk, pat = [], [], []
        for lag in range(nl):
            shift = start[lag:] - start[: nl - lag]
            near = np.flatnonzero(shift < width)
            if not len(near):
                break
            i = near
            v = np.arange(width)[None, :] + shift[near][:, None]
            pi.append(i)
            pk.append(i + lag)
            pat.append(np.where(v < width, i[:, None] * width + v, nl * width))
        j = end[None, :] - start[:, None] + 1
        u0, u1 = np.searchsorted(used, [lo, hi])
        rows = np.r_[local, dense]
        out.append(_Run(
            n, mask, slice(int(u0), int(u1)), used[u0:u1] - lo, local, start, end, at,
            inside * mask[at].reshape(nl, width), s_win, s_win * mask[at].reshape(nl, width),
            dense, x[dense],
            np.take(x[dense], at, axis=1).reshape(len(dense), nl, width),
            np.concatenate(pi) if pi else np.zeros(0, int),
            np.concatenate(pk) if pk else np.zeros(0, int),
            np.concatenate(pat) if pat else np.zeros((0, width), int),
            ((j >= 1) & (end[None, :] < end[:, None])).astype(float),
            (np.arange(nl)[:, None] * width + np.clip(j, 0, width - 1)).ravel(),
            np.where(j <= 0, 1 - j, -1),
            np.abs(end[:, None] - end[None, :]),
            end[:, None] >= end[None, :],
            (rows[:, None] * m + rows[None, :]).ravel()))
    return out


@dataclass
class _Filtered:
    """A stretch's low-passed shapes at one τ_mm: windows, tails and dense rows."""

    g_win_used: Array   # (local, width) the low-pass on the windows, at usable blocks only
    tail: Array         # (local,) its value at the window's end
    g_dense: Array      # (dense, n)


@dataclass
class GainGram:
    """SSᵀ, SGᵀ, GGᵀ of the shapes over the usable blocks at one τ_mm."""

    tau_mm_s: float
    rho: float
    ss: Array
    sg: Array           # sg[i, k] = s_i · g_k
    gg: Array
    runs: list[_Filtered]


def _at_ends(y: Array, run: _Run, powers: Array) -> Array:
    """F[i, k] = Σ_{t in window i, t > end_k} x_i(t)·ρ^(t − end_k), from y = :func:`_rev` of
    x over the windows: 0 from window i's end on, geometric before its start."""
    nl = len(run.local)
    inside = np.take(y.ravel(), run.end_at).reshape(nl, nl) * run.end_in * powers[1]
    before = y[:, :1] * np.where(run.end_before >= 0, powers[np.maximum(run.end_before, 0)], 0.0)
    return inside + before


def gain_gram(tau_mm: float, d: Design) -> GainGram:
    """SSᵀ, SGᵀ and GGᵀ at ``tau_mm`` [s] (module docstring), remembered for the next calls."""
    return d.cached(("gram", tau_mm), lambda: _gain_gram(tau_mm, d))


def _gain_gram(tau_mm: float, d: Design) -> GainGram:
    low = d.cached(("lowpassed", tau_mm), lambda: _make_lowpassed(tau_mm, d))
    rho = low.rho
    m = d.gains_b.shape[0]
    ss = d.once("gram_ss", lambda: _outer_used(d))
    sg, gg = np.zeros(m * m), np.zeros(m * m)
    for run, fl in zip(d.once("gram_layout", lambda: _layout(d)), low.runs, strict=True):
        nl, nd = len(run.local), len(run.dense)
        powers = rho ** np.arange(run.n + 1)
        gw, tail, g_dense, e = fl.g_win_used, fl.tail, fl.g_dense, run.end
        # over the windows' overlaps
        gw0 = np.r_[gw.ravel(), 0.0]
        g_i = np.take(gw0, run.pair_at)
        s_i = np.take(np.r_[run.s_win_used.ravel(), 0.0], run.pair_at)
        g_k, s_k = gw[run.pair_k], run.s_win_used[run.pair_k]
        o_gg = np.zeros((nl, nl))
        o_gg[run.pair_i, run.pair_k] = o_gg[run.pair_k, run.pair_i] = np.einsum(
            "pw,pw->p", g_i, g_k)
        o_sg = np.zeros((nl, nl))
        o_sg[run.pair_k, run.pair_i] = np.einsum("pw,pw->p", g_i, s_k)    # s_k · g_i
        o_sg[run.pair_i, run.pair_k] = np.einsum("pw,pw->p", s_i, g_k)    # s_i · g_k
        # and after: the tails
        tails_w = _after(run.mask, rho * rho)[e]      # Σ_{t>c} M(t) ρ^(2(t−c)) at each end
        q_end = _at_ends(_rev(gw, rho), run, powers)                          # Q_i(c_k)
        ps_end = _at_ends(_rev(run.s_win_used, rho), run, powers)             # PS_i(c_k)
        decay = np.take(powers, run.end_gap)
        t_k_at_i = tail[None, :] * decay * np.where(run.end_later, tails_w[:, None],
                                                    tails_w[None, :])
        t_k_at_i += np.where(run.end_later, 0.0, q_end.T)                     # T_k(c_i)
        blk_gg = np.empty((nl + nd, nl + nd))
        blk_sg = np.empty((nl + nd, nl + nd))
        blk_gg[:nl, :nl] = o_gg + tail[None, :] * q_end + tail[:, None] * t_k_at_i
        blk_sg[:nl, :nl] = o_sg + tail[None, :] * ps_end
        if nd:
            gd_at = np.take(g_dense, run.at, axis=1).reshape(nd, nl, -1)
            gd_after = _after(g_dense * run.mask, rho)
            sd_after = _after(run.s_dense * run.mask, rho)
            gg_dl = np.einsum("dkw,kw->dk", gd_at, gw) + tail[None, :] * gd_after[:, e]
            blk_gg[nl:, :nl] = gg_dl
            blk_gg[:nl, nl:] = gg_dl.T
            blk_gg[nl:, nl:] = (g_dense * run.mask) @ g_dense.T
            blk_sg[nl:, :nl] = (np.einsum("dkw,kw->dk", run.s_dense_at, gw)
                                + tail[None, :] * sd_after[:, e])
            blk_sg[:nl, nl:] = np.einsum("kw,dkw->kd", run.s_win_used, gd_at)
            blk_sg[nl:, nl:] = (run.s_dense * run.mask) @ g_dense.T
        gg[run.order] += blk_gg.ravel()
        sg[run.order] += blk_sg.ravel()
    return GainGram(tau_mm, rho, ss, sg.reshape(m, m), gg.reshape(m, m), low.runs)


def gain_diag(tau_mm: float, d: Design) -> tuple[Array, Array]:
    """The diagonals of SGᵀ and GGᵀ at ``tau_mm`` [s] (each shape with its own low-pass: the
    gains' columns' scales), without the products between shapes; the full Gram's when it is
    remembered."""
    full = d.remembered(("gram", tau_mm))
    if full is not None:
        return np.diagonal(full.sg), np.diagonal(full.gg)
    return d.cached(("gram diag", tau_mm), lambda: _gain_diag(tau_mm, d))


@dataclass
class _Lowpassed:
    """The shapes' low-pass at one τ_mm without their products (:func:`cross_products`
    needs no more)."""

    rho: float
    runs: list[_Filtered]


def lowpassed(tau_mm: float, d: Design) -> GainGram | _Lowpassed:
    """The full Gram at ``tau_mm`` when it is remembered, else the low-pass alone."""
    full = d.remembered(("gram", tau_mm))
    if full is not None:
        return full
    return d.cached(("lowpassed", tau_mm), lambda: _make_lowpassed(tau_mm, d))


def _make_lowpassed(tau_mm: float, d: Design) -> _Lowpassed:
    block_s = d.rec.per_block * d.rec.step_s
    rho = math.exp(-block_s / tau_mm)
    f = tau_mm / block_s * (1.0 - rho)
    runs = []
    for run in d.once("gram_layout", lambda: _layout(d)):
        nl = len(run.local)
        gw, tail = np.zeros((nl, 1)), np.zeros(nl)
        if nl:
            # the windows: the filter starts from the stretch's first value (as
            # held_lowpass) or from rest when the window opens later (the shape was 0 before)
            x = run.s_win
            z0 = np.where(run.start == 0, x[:, 0], 0.0)
            z = lfilter([1.0 - rho], [1.0, -rho], x, axis=1, zi=(rho * z0)[:, None])[0]
            prev = np.concatenate([z0[:, None], z[:, :-1]], axis=1)
            g_win = x + (prev - x) * f
            tail = g_win[np.arange(nl), run.end - run.start]
            gw = g_win * run.used_win
        runs.append(_Filtered(gw, tail, held_lowpass(run.s_dense, tau_mm, block_s,
                                                     [(0, run.n)])))
    return _Lowpassed(rho, runs)


def _gain_diag(tau_mm: float, d: Design) -> tuple[Array, Array]:
    low = lowpassed(tau_mm, d)
    m = d.gains_b.shape[0]
    sg, gg = np.zeros(m), np.zeros(m)
    for run, fl in zip(d.once("gram_layout", lambda: _layout(d)), low.runs, strict=True):
        if len(run.local):   # the windows, then each one's tail after it
            tails_w = _after(run.mask, low.rho * low.rho)[run.end]
            gw = fl.g_win_used
            np.add.at(gg, run.local, np.einsum("kw,kw->k", gw, gw) + fl.tail ** 2 * tails_w)
            np.add.at(sg, run.local, np.einsum("kw,kw->k", run.s_win_used, gw))
        if len(run.dense):
            g = fl.g_dense
            np.add.at(gg, run.dense, np.einsum("dn,dn->d", g * run.mask, g))
            np.add.at(sg, run.dense, np.einsum("dn,dn->d", run.s_dense * run.mask, g))
    return sg, gg


def gain_sum_sq(theta: tuple[float, ...], d: Design) -> Array:
    """Each gains' column's sum of squares over the usable blocks at ``theta`` (in the order
    of :func:`~.columns.gain_family`): the diagonal of its block of XᵀX."""
    ss = np.diagonal(d.once("gram_ss", lambda: _outer_used(d)))
    sg, gg = gain_diag(theta[0], d)
    a, b = gain_coefficients(theta, d)
    return a * a * ss + 2.0 * a * b * sg + b * b * gg


def _outer_used(d: Design) -> Array:
    s = d.gains_b[:, d.blocks]
    return s @ s.T


def cross_products(gram: GainGram | _Lowpassed, d: Design, rows: Array) -> Array:
    """rows·Gᵀ: products of series over the usable blocks with every shape's low-pass."""
    m = d.gains_b.shape[0]
    out = np.zeros((len(rows), m))
    for run, fl in zip(d.once("gram_layout", lambda: _layout(d)), gram.runs, strict=True):
        r = np.zeros((len(rows), run.n))
        r[:, run.used_at] = rows[:, run.used]
        r_at = np.take(r, run.at, axis=1).reshape(len(rows), len(run.local), -1)
        out[:, run.local] += (np.einsum("qkw,kw->qk", r_at, fl.g_win_used)
                              + fl.tail[None, :] * _after(r, gram.rho)[:, run.end])
        if len(run.dense):
            out[:, run.dense] += r @ fl.g_dense.T
    return out
