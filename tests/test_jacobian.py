"""The analytic Jacobian of the night rows (impctl.fit.optim.jacobian) against forward
differences and against backprop through the solver."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
import torch

from impctl.fit.ode.node import ROW_AIR, ROW_DEMAND
from impctl.fit.ode.packing import pack_nights
from impctl.fit.ode.parameters import DTYPE, NUISANCE_BOUNDS, PHYSICAL_BOUNDS, bounds_tensor
from impctl.fit.optim import jacobian, lm
from impctl.imp.night import NightSamples

ACH = (0.0, 0.3)
NAMES = ("loss", "jtj", "g", "c", "d", "gm", "r")


def _night(night_id, kind, t_s, t_air, t_out, q) -> NightSamples:
    return NightSamples(night_id, kind, pd.Timestamp("2026-01-10 22:00", tz="UTC"),
                        np.asarray(t_s, float), np.asarray(t_air, float),
                        np.asarray(t_out, float), np.asarray(q, float))


def _problem(kind: int, layout: str):
    """Two problems, each with a constrained and a normal night, rows all of ``kind``."""
    t = np.arange(0, 6 * 3600 + 1, 300.0)
    cons = _night("c", "constrained", t, 21 - 0.3 * t / 3600 + 0.05 * np.sin(t / 900),
                  2.0 - 0.1 * t / 3600, np.zeros(len(t)))
    norm = _night("n", "normal", t[:-6], np.full(len(t) - 6, 22.0), 1 + 0.2 * t[:-6] / 3600,
                  3000 - 50 * t[:-6] / 3600 + 80 * np.cos(t[:-6] / 1200))
    packed = pack_nights([cons, norm], [0.0, 0.0])
    if layout == "night gains":
        packed = dataclasses.replace(packed, gain_w=torch.tensor([40.0, -25.0], dtype=DTYPE))
    box = (bounds_tensor(PHYSICAL_BOUNDS) if layout == "seven"
           else bounds_tensor(PHYSICAL_BOUNDS, NUISANCE_BOUNDS))
    n = len(box)
    night = torch.tensor([0, 1, 0, 1])
    phi = torch.where(night[:, None] == 1, packed.q_w[night], 0.0)
    phi_in = torch.where(night[:, None] == 1, packed.q_in_w[night], 0.0)
    rows = lm.Rows(torch.tensor([0, 0, 1, 1]), night, torch.full((4,), kind), phi, phi_in,
                   torch.tensor([1 / 0.05, 1 / 80.0, 1 / 0.05, 1 / 80.0], dtype=DTYPE),
                   box[None].repeat(2, 1, 1), 2)
    u = torch.tensor(np.random.default_rng(kind).normal(0.0, 0.8, (2, n)), dtype=DTYPE)
    m = torch.tensor([19.0, 21.0, 18.5, 20.5], dtype=DTYPE)
    return lm.Context(packed, *ACH), rows, u, m


@pytest.mark.parametrize("kind", [ROW_AIR, ROW_DEMAND])
@pytest.mark.parametrize("layout", ["seven", "nuisance", "night gains"])
def test_analytic_terms_match_forward_differences(kind, layout):
    ctx, rows, u, m = _problem(kind, layout)
    fd = jacobian.row_terms(ctx, rows, u, m)
    an = jacobian.analytic_row_terms(ctx, rows, u, m, kind == ROW_DEMAND)
    assert an is not None
    for name, a, b in zip(NAMES, fd, an, strict=True):
        if name in ("loss", "r"):   # the residuals are the same arithmetic
            assert torch.equal(a, b), name
        else:                       # forward differences' truncation, ≈ 1e-7
            assert float((a - b).abs().max()) <= 1e-5 * float(a.abs().max()), name


@pytest.mark.parametrize("kind", [ROW_AIR, ROW_DEMAND])
def test_analytic_gradient_is_backprops(kind):
    """Jᵀr is the loss gradient to ≈ 1e-9 (forward differences only to ≈ 1e-7)."""
    ctx, rows, u, m = _problem(kind, "nuisance")
    loss, gu, gm = lm.loss_gradient(ctx, rows, u, m)
    an = jacobian.analytic_row_terms(ctx, rows, u, m, kind == ROW_DEMAND)
    g = torch.zeros_like(u).index_add_(0, rows.problem, an[2])
    data = gu - 2 * ctx.ridge * u
    # the numbers' own derivatives are central differences on small tensors; the rest exact
    assert float((2 * g - data).abs().max()) <= 1e-8 * float(data.abs().max())
    fd = torch.zeros_like(u).index_add_(0, rows.problem, jacobian.row_terms(ctx, rows, u, m)[2])
    assert float((2 * fd - data).abs().max()) > 1e-8 * float(data.abs().max())
    assert torch.allclose(2 * an[5], gm, rtol=1e-9)


def test_rk4_and_the_emitter_lag_take_forward_differences():
    ctx, rows, u, m = _problem(ROW_DEMAND, "nuisance")
    rk4 = dataclasses.replace(ctx, solver="rk4")
    assert jacobian.analytic_row_terms(rk4, rows, u, m, True) is None
    lag = dataclasses.replace(ctx, packed=dataclasses.replace(ctx.packed, emitter_lag=True))
    assert jacobian.analytic_row_terms(lag, rows, u, m, True) is None
