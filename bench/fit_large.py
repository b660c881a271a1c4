"""`impctl fit` on a long log: wall time, peak memory and progress (issue 12).

Run:  .venv/bin/python bench/fit_large.py [--days 695] [--step-min 5] [--keep DIR]

Writes a NIGHTS.csv of ``--days`` days of 5-minute samples (the built-in 150 m² house over the
built-in winter weather, heating held at 21 °C, every 4th night switched off 22:00–05:00; no
night/kind columns, so nights are cut from the 22:00–05:00 windows as for a logger's export):
695 days are 200,160 rows and 695 nights, the file of the issue. Then runs
``impctl fit --nights FILE`` in a subprocess and prints its wall time, its peak RSS (VmHWM,
from ``resource.getrusage(RUSAGE_CHILDREN)``), its exit status, how many progress lines it
printed on stderr, and its first output lines.

Measured on the 2-core machine, other work running (``python bench/fit_large.py``):

* before issue 12 (all 695 nights fitted jointly): exit 0, 233.5 s, peak RSS 1,123 MB, no
  progress line;
* after (``--max-nights`` 30 by default, progress lines): exit 0, 25.8 s, 443 MB;
* ``--days 2000`` (576,000 rows, 24.4 MB, just under the 25 MB limit): 47.4 s, 531 MB.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from impctl.model import default_house, simulate
from impctl.weather import winter_weather


def write_log(path: Path, days: int, step_min: float) -> int:
    step_s = 60.0 * step_min
    t_out = winter_weather(days=days, step_s=step_s, seed=3)
    idx = t_out.index
    minute = idx.hour * 60 + idx.minute
    night_start = idx.normalize() - pd.to_timedelta((minute < 5 * 60).astype(int), unit="D")
    night_no = ((night_start - idx[0].normalize()).days).to_numpy()
    off = ((minute >= 22 * 60) | (minute < 5 * 60)) & (night_no % 4 == 1)
    setpoint = np.where(off, np.nan, 21.0)
    sim = simulate(default_house(), t_out.to_numpy(), step_s, setpoint_c=setpoint,
                   t_m_init_c=21.0)
    rng = np.random.default_rng(0)
    frame = pd.DataFrame({
        "timestamp": [t.isoformat() for t in idx],
        "t_air": np.round(sim.t_air_c, 1), "t_out": np.round(t_out.to_numpy(), 1),
        "q_hc": np.round(np.maximum(sim.phi_hc_w * (1 + 0.05 * rng.standard_normal(len(idx))),
                                    0.0), 1)})
    frame.to_csv(path, index=False)
    return len(frame)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=695)
    ap.add_argument("--step-min", type=float, default=5.0)
    ap.add_argument("--keep", type=Path, help="Write the file here and keep it.")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = (args.keep or Path(tmp)) / "nights_large.csv"
        path.parent.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        rows = write_log(path, args.days, args.step_min)
        print(f"wrote {rows:,} rows ({path.stat().st_size / 1e6:.1f} MB) in "
              f"{time.perf_counter() - t0:.1f} s")
        cmd = [sys.executable, "-c", "from impctl.cli import main; main()", "fit",
               "--nights", str(path), "--model-dir", str(Path(tmp) / "no-models")]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        err = proc.stderr.splitlines()
        print(f"command: {' '.join(['impctl', *cmd[3:]])}")
        print(f"exit {proc.returncode}, wall {wall:.1f} s, peak RSS {peak_mb:.0f} MB, "
              f"{len(err)} stderr lines")
        for line in err[:6] + (["…"] + err[-3:] if len(err) > 9 else err[6:]):
            print(f"  stderr: {line[:160]}")
        for line in proc.stdout.splitlines()[:4]:
            print(f"  stdout: {line[:160]}")


if __name__ == "__main__":
    main()
