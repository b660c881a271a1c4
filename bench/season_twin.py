"""The season model on two real buildings: the Annex 58 twin houses N2 and O5.

Run:  .venv/bin/python bench/season_twin.py [--data ../shared/realdata/twinhouse]
          [--write-nights DIR]

Each house's whole measured series (``{N2,O5}_auto.csv``, 10-min instants, 21 Aug – 30 Sep
2013) becomes one season as a gateway would record it: the experiment's labelled nights
(``{N2,O5}_labelled.csv``: held at 30 or 25 °C → ``normal``, from a switch-off and free-float
→ ``constrained``) are the IMP nights, every other row is the owner's record (kind ``owner``,
one record per uninterrupted run of rows) — the co-heating days, the pseudo-random heat
pulses (ROLBS) and the free-float days alike: the season model reads any row, held or not.
The season model is fitted as ``impctl season`` fits it (the houses are empty, but the model's
gain levels stay free: they also take the sensors' offsets and, here, the heat the attic and
cellar exchange with the ground floor). Printed against the references of the data's README,
derived from the same data independently of impctl: HLC by co-heating (N2 126.4 ± 19.6, O5
114.1 ± 18.2 W/K), τ by the free-float decay (127, 116 h), C = HLC·τ (57.8, 47.6 MJ/K).

Two houses are a check, not a training set: nothing in the model is set on them.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = {"N2": {"hlc_w_per_k": 126.4, "tau_h": 127.0, "c_m_j_per_k": 57.8e6},
             "O5": {"hlc_w_per_k": 114.1, "tau_h": 116.0, "c_m_j_per_k": 47.6e6}}
TZ = "Etc/GMT-1"  # CET without daylight saving, as measured


def season_file(data: Path, house: str) -> pd.DataFrame:
    """The house's season as NIGHTS rows (module docstring)."""
    whole = pd.read_csv(data / f"{house}_auto.csv")
    imp = pd.read_csv(data / f"{house}_labelled.csv")
    owner = whole[~whole["timestamp"].isin(imp["timestamp"])].copy()
    # one record per uninterrupted run of owner rows (the IMP nights cut the series)
    gap = ~whole["timestamp"].isin(imp["timestamp"])
    run = (gap != gap.shift()).cumsum()[gap]
    owner["night"] = [f"owner-{r}" for r in run]
    owner = owner[owner.groupby("night")["timestamp"].transform("size") > 1]
    owner["setpoint"], owner["kind"] = float("nan"), "owner"
    return pd.concat([imp, owner[imp.columns]]).sort_values("timestamp", kind="stable")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared/realdata/twinhouse")
    ap.add_argument("--write-nights", type=Path, default=None,
                    help="also write each house's season as NIGHTS.csv here")
    args = ap.parse_args(argv)
    from impctl.fit.household import read_household
    from impctl.season.fit import fit_nights

    print(f"$ python bench/season_twin.py {' '.join(argv if argv is not None else sys.argv[1:])}")
    print("| house | owner / IMP nights | HLC [W/K] (error) | τ [h] (error) | C_m [MJ/K] "
          "(error) | signature HLC | fit s |")
    print("|---|---|---|---|---|---|---|")
    tmp = tempfile.TemporaryDirectory()
    where = args.write_nights or Path(tmp.name)
    where.mkdir(parents=True, exist_ok=True)
    for house, ref in REFERENCE.items():
        out = where / f"season-{house}.csv"
        season_file(args.data, house).to_csv(out, index=False)
        nights = read_household(out, TZ)  # the product's own reader and its checks
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a warning here is a bug, not noise
            fit, note = fit_nights(nights)
        took = time.perf_counter() - t0
        if fit is None:
            print(f"| {house} | — | {note} | | | | |")
            continue
        cells = []
        for key, scale in (("hlc_w_per_k", 1.0), ("tau_h", 1.0), ("c_m_j_per_k", 1e-6)):
            v, lo, hi = fit.values[key], fit.low[key], fit.high[key]
            inside = "in" if lo <= ref[key] <= hi else "**out**"
            cells.append(f"{v * scale:.1f} [{lo * scale:.1f}, {hi * scale:.1f}] "
                         f"({100 * (v / ref[key] - 1):+.1f} %, ref. {inside})")
        print(f"| {house} | {fit.owner_nights} / {fit.imp_nights} | " + " | ".join(cells)
              + f" | {fit.signature_hlc_w_per_k:.1f} | {took:.1f} |")


if __name__ == "__main__":
    main()
