"""Flexibility from FLEET rows (``impctl flex FLEET.parquet``): the fitted houses re-simulated
at other conditions, vectorised over the households."""

from __future__ import annotations

from pathlib import Path

from ...errors import InputError
from .table import PARAM_COLUMNS


def fleet_flexibility(path: str | Path, households: list[str] | None = None,
                      **conditions) -> dict:
    """household → :class:`impctl.flex.Flexibility` for the ``ok`` rows of a FLEET dataset.

    Raises
    ------
    InputError
        Not a FLEET dataset, an unknown household, or one that has no fit (its status).
    """
    import pandas as pd

    from ...flex import SwitchOff, flexibility_many, switch_off_from_fit
    from ...flex.switch_off import ASSUMED_COLUMN, COLUMNS, from_columns
    from ...model import HouseParameters

    try:
        table = pd.read_parquet(path)
    except (OSError, ValueError) as exc:
        raise InputError(f"not a FLEET.parquet ({str(exc).splitlines()[0]})", path) from None
    needed = {"household", "status", "tau_h_low", "tau_h_high", "ach_vent_per_h",
              "ach_infl_per_h", *PARAM_COLUMNS.values()}
    missing = sorted(needed - set(table.columns))
    if missing:
        raise InputError(f"not a FLEET.parquet (no column {', '.join(missing)})", path)
    table["household"] = table["household"].astype(str)
    table = table.drop_duplicates("household", keep="last").set_index("household")
    if households:
        unknown = [h for h in households if h not in table.index]
        if unknown:
            raise InputError(f"no household {', '.join(unknown)}", path)
        table = table.loc[households]
        bad = table[table["status"] != "ok"]
        if len(bad):
            h = bad.index[0]
            raise InputError(f"household {h} has no fit (status {bad['status'].iloc[0]}: "
                             f"{bad['error'].iloc[0]})", path)
    table = table[table["status"] == "ok"]
    if table.empty:
        raise InputError("no fitted household (status ok)", path)
    houses = HouseParameters(
        **{name: table[col].to_numpy(float) for name, col in PARAM_COLUMNS.items()},
        ach_vent=table["ach_vent_per_h"].to_numpy(float),
        ach_infl=table["ach_infl_per_h"].to_numpy(float))
    # the fit's switch-off terms (FLEET files written before they were stored: none)
    rows = table.reindex(columns=[*COLUMNS, ASSUMED_COLUMN]).astype(float).to_dict("records")
    terms = SwitchOff.stack([switch_off_from_fit({"nuisance": from_columns(r)}) for r in rows])
    flex = flexibility_many(houses, table["tau_h_low"].to_numpy(float),
                            table["tau_h_high"].to_numpy(float), switch_off=terms,
                            **conditions)
    return dict(zip(table.index, flex, strict=True))
