"""The season model's interval constants from raw-interval runs (``bench/season.py
--calibrate``), pooled over the runs given.

Per quantity and for each sandwich scale on a grid, the smallest model-error floor [log units]
whose interval — z₉₅·√((scale·se)² + floor²) — covers at least :data:`MIN_COVERAGE` of the
households at EVERY owner-night count of every variant (plain, household electricity measured)
of the runs; of those pairs, the one with the narrowest
median half-width. Every count, not the counts pooled: the sandwich part shrinks with the
nights and what the model leaves out of a house does not, so a pooled 95 % hides too-narrow
intervals at 56 nights behind too-wide ones at 7. 92 % per count, not 95: the target band is
90–97 %, and each count's coverage of a few hundred households scatters by 1–2 points.
"""

from __future__ import annotations

import json
import math

import numpy as np

#: Coverage each owner-night count must reach on the calibration households [-].
MIN_COVERAGE = 0.92
#: Scales tried [-].
SCALES = tuple(np.round(np.arange(1.0, 6.01, 0.25), 2))
Z95 = 1.959964
QUANTITIES = {"hlc_w_per_k": "HLC", "tau_h": "tau", "c_m_j_per_k": "C_m"}


def arrays(rows: list[dict], truth: dict, variant: str = "realistic"
           ) -> dict[str, tuple[np.ndarray, ...]]:
    """Per quantity (|log error|, raw log standard error, group: the variant and the owner
    nights) of the fitted rows."""
    out = {}
    for k in QUANTITIES:
        ok = [r for r in rows if r["status"] == "ok" and r.get(k) is not None
              and math.isfinite(r[k]) and math.isfinite(r["se"][k])]
        out[k] = (np.abs(np.log([r[k] / truth[k][r["household"]] for r in ok])),
                  np.array([r["se"][k] for r in ok]),
                  np.array([f"{variant} {r['owner_nights']}" for r in ok]))
    return out


def pooled(parts: list[dict]) -> dict[str, tuple[np.ndarray, ...]]:
    """Several runs' :func:`arrays` as one set."""
    return {k: tuple(np.concatenate([p[k][i] for p in parts]) for i in range(3))
            for k in QUANTITIES}


def _floor(err: np.ndarray, se: np.ndarray, scale: float) -> float:
    """The smallest floor with :data:`MIN_COVERAGE` coverage (bisection, log units)."""
    lo, hi = 0.0, 2.0
    for _ in range(50):
        mid = (lo + hi) / 2
        cover = np.mean(err <= Z95 * np.hypot(scale * se, mid))
        lo, hi = (lo, mid) if cover >= MIN_COVERAGE else (mid, hi)
    return hi


def calibrate(data: dict[str, tuple[np.ndarray, ...]]) -> dict[str, tuple]:
    """Per quantity (scale, floor, median half-width) by the module's rule, printed with each
    count's coverage."""
    out = {}
    for k, name in QUANTITIES.items():
        err, se, cnt = data[k]
        counts = sorted(set(cnt.tolist()), key=lambda g: (g.split()[0], int(g.split()[1])))
        pairs = []
        for scale in SCALES:
            floor = max(_floor(err[cnt == c], se[cnt == c], scale) for c in counts)
            pairs.append((float(scale), floor, float(np.median(Z95 * np.hypot(scale * se,
                                                                              floor)))))
        best = min(pairs, key=lambda p: p[2])
        half = Z95 * np.hypot(best[0] * se, best[1])
        per = ", ".join(f"{c}: {100 * np.mean(err[cnt == c] <= half[cnt == c]):.0f} %"
                        for c in counts)
        print(f"{name:>4}: scale {best[0]:.2f}, floor {best[1]:.3f} (log units), median "
              f"half-width {100 * best[2]:.1f} % over {len(err)} fits; coverage by variant "
              f"and owner nights: {per}")
        out[name] = best
    return out


def from_saved(paths: list[str]) -> dict[str, tuple]:
    """:func:`calibrate` on saved ``--calibrate --json`` runs, pooled (their truth drawn again
    from each run's seed)."""
    from impctl.population.households import sample_households

    parts = []
    for path in paths:
        with open(path, encoding="utf-8") as fh:
            saved = json.load(fh)
        a = saved["args"]
        if not a.get("calibrate"):
            raise SystemExit(f"bench/season.py: {path}: not a --calibrate run (no raw "
                             "intervals)")
        houses = sample_households(a["households"], seed=a["seed"])
        truth = {k: np.asarray(getattr(houses, k), float) for k in QUANTITIES}
        parts.append(arrays(saved["rows"], truth, a["variant"]))
        print(f"{path}: {a['households']} households, seed {a['seed']}, owner nights "
              f"{a['owner_nights']}, {a['variant']}")
    return calibrate(pooled(parts))
