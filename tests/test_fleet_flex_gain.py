"""FLEET.parquet keeps whether the night gain was the fit's assumption or fitted, so the coast
of a fleet row states it as the fit JSON's coast does (a real Parquet file, read back)."""

from __future__ import annotations

import pandas as pd

from impctl.fleet.results.table import empty_row, to_table
from impctl.flex.switch_off import ASSUMED_COLUMN, from_columns, switch_off_from_fit, to_columns


def _nuisance(assumed: bool) -> dict:
    gain = {"value": 250.0, "low": 80.0, "high": 420.0, "bounds": [0.0, 500.0]}
    if assumed:
        gain["assumed"] = True
    return {"night_gain_w": gain, "emitter_tau_h": None, "furniture_j_per_m2k": None}


def test_assumed_gain_survives_the_fleet_table(tmp_path):
    import pyarrow.parquet as pq

    rows = []
    for name, assumed in (("a", True), ("f", False), ("n", None)):
        row = empty_row(name)
        row.update(to_columns(None if assumed is None else _nuisance(assumed)))
        rows.append(row)
    path = tmp_path / "part.parquet"
    pq.write_table(to_table(rows), path)
    table = pd.read_parquet(path).set_index("household")
    assert table.loc["a", ASSUMED_COLUMN] is True or table.loc["a", ASSUMED_COLUMN] == 1
    assert not table.loc["f", ASSUMED_COLUMN]
    assert pd.isna(table.loc["n", ASSUMED_COLUMN])   # no gain used: empty, not False
    cols = [c for c in table.columns if c.startswith(("night_gain", "emitter_tau",
                                                      "furniture_j"))]
    back = table[cols].astype(float).to_dict("index")
    assumed = switch_off_from_fit({"nuisance": from_columns(back["a"])})
    fitted = switch_off_from_fit({"nuisance": from_columns(back["f"])})
    none = switch_off_from_fit({"nuisance": from_columns(back["n"])})
    assert "night_gain_w" in assumed.documented     # named as the assumption
    assert "night_gain_w" not in fitted.documented  # a fitted gain stays "fitted"
    assert none.documented == () and assumed.night_gain_w[0] == 250.0
