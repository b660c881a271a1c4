"""Diagnosis of the emitter's cost on the gateway's nights (issue 14, branch h14e).

Run:  .venv/bin/python bench/_fit_emitter_diag.py record --households 20 --row only:emitter
      .venv/bin/python bench/_fit_emitter_diag.py fit --row only:emitter [-v] [--only 0,5]
          [--kinds normal] [--variant k=v,…]…

``record`` simulates a row of ``bench/fit_budget.py`` (same households, realism, recorded
stops; row specs as there, plus ``ROW/field+field``: those fields of the ``sensors`` section
as the full house has them, e.g. ``only:emitter/t_air_noise_k+t_air_quantum_k``) and stores
every household's nights and class ranges as the fit receives them
(/tmp/h14e/nights_<row>.pkl). ``fit`` refits them with the bench's ``NightFit`` options plus
each ``--variant`` (``NightFit`` keywords, or the diagnostic switches of :func:`_switches`),
``--kinds`` keeping only those nights, and prints median / P90 |error| (signed median) %,
coverage and the same per emitter type; ``-v`` per household the signed errors, the
nuisance terms, the likelihood-ratio drop χ² and the constrained nights' fitted hours.
Seconds per variant instead of a full bench: a ranking on 20 households, not a measurement.
"""

from __future__ import annotations

import argparse
import os
import pickle
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))

import fit  # noqa: E402
import fit_budget as fb  # noqa: E402
from _fit_protocol import ACH  # noqa: E402
from fit import VAL_SEED, run_step  # noqa: E402

from impctl.fit.estimator import NightFit  # noqa: E402
from impctl.population.households import sample_households  # noqa: E402
from impctl.population.realism import sample_params  # noqa: E402

OUT = Path(os.environ.get("H14E_DIAG_DIR", "/tmp/h14e"))


def _path(row: str) -> Path:
    return OUT / f"nights_{row.replace(':', '_').replace('+', '_').replace('/', '_')}.pkl"


def record(n: int, row: str) -> None:
    houses = sample_households(n, seed=VAL_SEED)
    full = sample_params(n, VAL_SEED)
    base_row, _, fields = row.partition("/")   # e.g. only:emitter/t_air_lag_s+meter_noise
    params, gains = fb.ablate(full, set(fb.GROUPS) - fb.groups_on(base_row))
    for name in filter(None, fields.split("+")):   # one sensor field as the full house has it
        params = params.with_section("sensors", **{name: getattr(full.sensors, name)})
    captured = []
    base = fit.NightFit

    class Capture(base):
        def fit(self, nights, ranges=None):
            captured.append((list(nights), ranges))
            return super().fit(nights, ranges)

    fit.NightFit = Capture
    try:
        with fb.recorded_stops(full):
            res = run_step(houses, 300.0, "true",
                           fb.fit_args((row, params, gains), None if gains else 0.0))
    finally:
        fit.NightFit = base
    kinds = np.asarray(full.emitter.kind)
    data = [{"house": res["truth"][i], "nights": captured[i][0], "ranges": captured[i][1],
             "kind": int(np.broadcast_to(kinds, (n,))[i]), "gain_w": None if gains else 0.0}
            for i in range(n)]
    OUT.mkdir(exist_ok=True)
    with open(_path(row), "wb") as f:
        pickle.dump(data, f)
    print(f"stored {len(data)} households in {_path(row)}")


def _value(v: str):
    for cast in (int, float):
        try:
            return cast(v)
        except ValueError:
            pass
    return {"True": True, "False": False, "None": None}.get(v, v)


def _switches(kw: dict) -> None:
    """Diagnostic switches of ``--variant`` that are not ``NightFit`` options, applied by
    patching the fit's modules (each run resets them first): ``bound_<nuisance>=lo:hi`` (a
    nuisance term's bounds), ``force_nuisance=1`` (keep the nuisance terms whatever the
    likelihood-ratio test says), ``no_lag_extra=1`` (drop C_e·dT_air/dt from the held
    nights' emitter lag), ``low_start=f`` (the first start's nuisance terms at fraction f of
    their boxes instead of the centre). Popped from ``kw``."""
    import impctl.fit._statement as stmt
    import impctl.fit.layout as lay_mod
    import impctl.fit.ode.node as node
    import impctl.fit.optim.problem as prob
    from impctl.fit import selection
    from impctl.fit.ode.parameters import NUISANCE_BOUNDS

    NUISANCE_BOUNDS.update(_BOUNDS)
    stmt.nuisance_check, prob.build_rows, lay_mod.starts = _ORIGINAL
    for k in [k for k in kw if k.startswith("bound_")]:
        lo, hi = str(kw.pop(k)).split(":")
        NUISANCE_BOUNDS[k[6:]] = (float(lo), float(hi))
    if kw.pop("no_lag_extra", False):
        def rows_no_extra(*a, **k):
            rm = node.build_rows(*a, **k)
            rm.lag_extra = None
            return rm
        prob.build_rows = rows_no_extra
    low = kw.pop("low_start", None)
    if low is not None:
        def low_starts(s, seed):
            u = _ORIGINAL[2](s, seed)
            u[0, 7:] = float(np.log(low / (1 - low)))
            return u
        lay_mod.starts = low_starts
    if kw.pop("force_nuisance", False):
        def forced(result, lay, best_simple, n_nuisance):
            _, check = selection.nuisance_check(result, lay, best_simple, n_nuisance)
            return selection.best_of(result, lay, 0), check | {"selected": True}
        stmt.nuisance_check = forced


def _originals():
    import impctl.fit._statement as stmt
    import impctl.fit.layout as lay_mod
    import impctl.fit.optim.problem as prob
    from impctl.fit.ode.parameters import NUISANCE_BOUNDS

    return dict(NUISANCE_BOUNDS), (stmt.nuisance_check, prob.build_rows, lay_mod.starts)


_BOUNDS, _ORIGINAL = _originals()


def refit(row: str, variant: str, verbose: bool, only: list[int] | None,
          kinds: tuple[str, ...] = ("constrained", "normal")) -> None:
    with open(_path(row), "rb") as f:
        data = pickle.load(f)
    kw = {k: _value(v) for k, v in (x.split("=", 1) for x in variant.split(",") if x)}
    _switches(kw)
    errs, times = [], []
    for i, d in enumerate(data):
        if only and i not in only:
            continue
        gain = {} if d["gain_w"] is None else {"night_gain_w": d["gain_w"]}
        nights = [x for x in d["nights"] if x.kind in kinds]
        f = NightFit(normal_model="demand", n_starts=4, ach_vent=ACH[0], ach_infl=ACH[1],
                     min_night_h=3.0, **(gain | kw)).fit(nights, d["ranges"])
        h = d["house"]
        e = [100 * (f.lumped_[k].value / t - 1) for k, t in (
            ("hlc", h.hlc_w_per_k), ("tau", h.tau_h), ("c_m", h.c_m_j_per_k))]
        cov = [f.lumped_[k].low <= t <= f.lumped_[k].high for k, t in (
            ("hlc", h.hlc_w_per_k), ("tau", h.tau_h), ("c_m", h.c_m_j_per_k))]
        errs.append(e + cov + [d["kind"]])
        times.append(f.fit_time_s_)
        if verbose:
            nu = {k: (v or {}).get("value") or 0.0 for k, v in f.nuisance_.items()}
            cons = [(float(x.time_s[-1] - x.time_s[0]) / 3600) for x in f.nights_
                    if x.kind == "constrained"]
            print(f"{i:3d} {'UF' if d['kind'] else 'RA'} HLC {e[0]:+6.1f} τ {e[1]:+6.1f} "
                  f"C_m {e[2]:+6.1f} | kept {f.nuisance_check_.get('selected')} "
                  f"em {nu.get('emitter_w', 0):5.0f} W {nu.get('emitter_tau_h', 0):4.2f} h "
                  f"fur {nu.get('furniture_j_per_m2k', 0):6.0f} "
                  f"sh {nu.get('emitter_share', 0):.2f} "
                  f"χ² {f.nuisance_check_.get('chi2', 0):7.1f} | cons h "
                  + " ".join(f"{c:.1f}" for c in cons), flush=True)
    a = np.asarray(errs, float)
    med = [np.median(np.abs(a[:, j])) for j in range(3)]
    sgn = [np.median(a[:, j]) for j in range(3)]
    p90 = [np.percentile(np.abs(a[:, j]), 90) for j in range(3)]
    cov = [100 * a[:, 3 + j].mean() for j in range(3)]
    print(f"{row} [{variant or 'default'}] n={len(a)}: "
          + " | ".join(f"{k} {m:.1f} / {p:.1f} ({s:+.1f})" for k, m, p, s in zip(
              ("HLC", "τ", "C_m"), med, p90, sgn, strict=True))
          + f" | cov {cov[0]:.0f}/{cov[1]:.0f}/{cov[2]:.0f} | fit {np.median(times):.2f} s"
          + "".join(f" | {name} n={int(m.sum())}: " + " / ".join(
              f"{np.median(np.abs(a[m, j])):.1f} ({np.median(a[m, j]):+.1f})" for j in range(3))
              for name, m in (("radiators", a[:, 6] == 0), ("underfloor", a[:, 6] == 1))
              if m.any()), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=("record", "fit"))
    ap.add_argument("--households", type=int, default=20)
    ap.add_argument("--row", default="only:emitter")
    ap.add_argument("--variant", action="append", default=None)
    ap.add_argument("--only", default="")
    ap.add_argument("-v", action="store_true")
    ap.add_argument("--kinds", default="constrained,normal")
    args = ap.parse_args()
    torch.set_num_threads(1)
    if args.mode == "record":
        record(args.households, args.row)
    else:
        only = [int(x) for x in args.only.split(",") if x]
        for v in args.variant or [""]:
            refit(args.row, v, args.v, only or None, tuple(args.kinds.split(",")))


if __name__ == "__main__":
    main()
