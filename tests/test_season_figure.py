"""bench/season.py's figure, run as a command: the error against the owner nights drawn from a
saved run (``--from-json``) and after a small run whose 0-night point is the IMP fit alone on
the same households; a saved JSON it cannot draw is one line, exit status 2, nothing written."""

from __future__ import annotations

import json
import math
import os
import stat
import subprocess
import sys
from pathlib import Path

import matplotlib.image
import pytest

SEASON = Path(__file__).resolve().parents[1] / "bench" / "season.py"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _quantity(median_pct: float) -> dict:
    return {"median_pct": median_pct, "median_ci": [0.8 * median_pct, 1.2 * median_pct],
            "p90_pct": 3 * median_pct, "p90_ci": [2.5 * median_pct, 3.5 * median_pct],
            "coverage": 0.93, "half_width_pct": 2 * median_pct}


def _saved(owner_nights: tuple[int, ...]) -> dict:
    """A small saved run as bench/season.py --json writes it (the rows are not drawn)."""
    summary = []
    for n in owner_nights:
        row = {"owner_nights": n, "households": 4, "fitted": 4, "fit_s_median": 1.0,
               "HLC": _quantity(12.0 / (1 + n / 7)), "tau": _quantity(10.0),
               "C_m": _quantity(14.0)}
        row["signature"] = (None if n == 0 else
                            {"median_pct": 25.0, "median_ci": [20.0, 30.0], "p90_pct": 90.0,
                             "n": 4})
        summary.append(row)
    return {"rows": [], "summary": summary,
            "args": {"households": 4, "seed": 7, "variant": "realistic", "nights": 30,
                     "owner_nights": ",".join(map(str, owner_nights))}}


def _run(*args: str, timeout_s: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SEASON), *args], capture_output=True, text=True,
                          timeout=timeout_s, cwd=SEASON.parent.parent)


def _is_png(path: Path) -> tuple[int, int]:
    assert path.read_bytes()[:8] == PNG_MAGIC
    height, width = matplotlib.image.imread(path).shape[:2]
    return width, height


@pytest.mark.parametrize("owner_nights, published", [((0, 7, 14), False), ((7, 14, 28), True)])
def test_figure_from_a_saved_run(tmp_path: Path, owner_nights, published) -> None:
    saved = tmp_path / "saved.json"
    saved.write_text(json.dumps(_saved(owner_nights)))
    out = tmp_path / "curve.png"
    done = _run("--from-json", str(saved), "--figure", str(out))
    assert done.returncode == 0, done.stderr
    width, height = _is_png(out)
    assert width > 1000 and height > 600
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o666 & ~umask   # a plain new file's mode
    assert f"figure written to {out}" in done.stdout
    # without its own 0-night point the figure draws bench/fit.py's, and says so
    assert ("bench/fit.py's figure of record" in done.stdout) is published
    assert sorted(p.name for p in tmp_path.iterdir()) == ["curve.png", "saved.json"]


def _drop(data: dict, *path) -> dict:
    target = data
    for key in path[:-1]:
        target = target[key]
    del target[path[-1]]
    return data


@pytest.mark.parametrize("broken, place", [
    (_drop(_saved((7, 14)), "summary"), "no key 'summary'"),
    (_drop(_saved((7, 14)), "summary", 1, "tau", "p90_ci"), "summary[1].tau.p90_ci: missing"),
    (_drop(_saved((7, 14)), "args", "seed"), "args: no key 'seed'"),
])
def test_a_saved_run_without_what_the_figure_needs_is_refused(tmp_path: Path, broken,
                                                                place: str) -> None:
    saved = tmp_path / "saved.json"
    saved.write_text(json.dumps(broken))
    out = tmp_path / "curve.png"
    out.write_bytes(b"the figure before")
    done = _run("--from-json", str(saved), "--figure", str(out))
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert lines == [f"bench/season.py: {saved}: {place}"] or (
        len(lines) == 1 and lines[0].startswith(f"bench/season.py: {saved}: {place}"))
    assert out.read_bytes() == b"the figure before"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["curve.png", "saved.json"]


def test_a_run_fits_the_imp_nights_alone_at_0_owner_nights(tmp_path: Path) -> None:
    """Two households, 16 nights (the campaign's 8 planned nights every other night): the
    0-night row is the IMP fit on the households' own IMP nights, drawn on the curve."""
    saved, out = tmp_path / "run.json", tmp_path / "curve.png"
    done = _run("--households", "2", "--nights", "16", "--owner-nights", "0", "--workers", "1",
                "--json", str(saved), "--figure", str(out), timeout_s=300)
    assert done.returncode == 0, done.stderr
    data = json.loads(saved.read_text())
    rows = [r for r in data["rows"] if r["owner_nights"] == 0]
    # a household without a valid constrained night is fitted on its normal nights, marked
    assert [r["status"] for r in rows] == ["ok", "ok"]
    # the 6 normal nights, and a valid constrained night or two where the campaign got one
    assert all((r["imp_nights"] in (7, 8)) if r["identified"] else (r["imp_nights"] == 6)
               for r in rows)
    assert all(math.isnan(r["signature_hlc_w_per_k"]) for r in rows)
    (zero,) = data["summary"]
    assert zero["owner_nights"] == 0 and zero["fitted"] == 2 and zero["signature"] is None
    assert zero["unidentified"] == sum(not r["identified"] for r in rows)
    assert all(math.isfinite(zero[q]["median_pct"]) for q in ("HLC", "tau", "C_m"))
    assert "bench/fit.py's figure of record" not in done.stdout
    _is_png(out)


def _run_with_truth(seed: int, errors_pct: list[float], covered: bool) -> dict:
    """A saved run whose households' HLC is off by ``errors_pct`` (τ and C_m exact), each
    interval around the truth or beside it, with the true values it was scored against."""
    true_hlc = [100.0 + 10 * i for i in range(len(errors_pct))]
    rows = []
    for h, (t, e) in enumerate(zip(true_hlc, errors_pct, strict=True)):
        est = t * (1 + e / 100)
        lo, hi = (0.5 * t, 2 * t) if covered else (1.5 * t, 2 * t)
        rows.append({"household": h, "owner_nights": 28, "status": "ok", "fit_s": 0.5,
                     "hlc_w_per_k": est, "hlc_w_per_k_low": lo, "hlc_w_per_k_high": hi,
                     "tau_h": 40.0, "tau_h_low": 30.0, "tau_h_high": 50.0,
                     "c_m_j_per_k": 2e7, "c_m_j_per_k_low": 1e7, "c_m_j_per_k_high": 3e7,
                     "signature_hlc_w_per_k": 1.5 * t})
    saved = _saved((28,))
    saved["args"]["seed"] = seed
    saved["args"].update(imp="all")
    saved["rows"] = rows
    n = len(rows)
    saved["truth"] = {"hlc_w_per_k": true_hlc, "tau_h": [40.0] * n, "c_m_j_per_k": [2e7] * n,
                      "meter_gain": [0.0] * n}
    return saved


def test_saved_runs_of_other_seeds_pool_into_one_table(tmp_path: Path) -> None:
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps(_run_with_truth(1, [10.0, 20.0], covered=True)))
    b.write_text(json.dumps(_run_with_truth(2, [30.0, 40.0], covered=False)))
    done = _run("--pool", f"{a},{b}")
    assert done.returncode == 0, done.stderr
    assert "4 households pooled from 2 runs (realistic plant, seeds 1, 2" in done.stdout
    (hlc,) = [line.split() for line in done.stdout.splitlines()
              if line.split()[:2] == ["28", "HLC"]]
    # the median of all four errors, and the coverage of all four intervals
    cov = hlc.index("50.0%")
    assert float(hlc[2]) == pytest.approx(25.0)
    # half-widths 75/1.1, 75/1.2, 25/1.3, 25/1.4 % of the estimate: median 40.9 %, 1.64 × the
    # median error, and the ratio's bootstrap interval around it
    half, ratio = float(hlc[cov + 1]), float(hlc[cov + 2])
    assert half == pytest.approx((75 / 1.2 + 25 / 1.3) / 2, abs=0.05)
    assert ratio == pytest.approx(half / 25.0, abs=0.01)
    low, high = float(hlc[cov + 3].strip("[,")), float(hlc[cov + 4].strip("]"))
    assert low <= ratio <= high and low < high
    (sig,) = [line.split() for line in done.stdout.splitlines() if line.split()[1:2] == ["sig"]]
    assert float(sig[2]) == pytest.approx(50.0)

    b.write_text(json.dumps(_drop(json.loads(b.read_text()), "truth")))
    done = _run("--pool", f"{a},{b}")
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"bench/season.py: {b}: truth: was saved without the true values (run it again with "
        "this bench)"]
    other = _run_with_truth(3, [5.0], covered=True)
    other["args"]["variant"] = "p_house"
    b.write_text(json.dumps(other))
    done = _run("--pool", f"{a},{b}")
    assert done.returncode == 2 and "other settings than the first run's" in done.stderr
