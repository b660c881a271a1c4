"""``impctl fleet fit --previous``: the next morning's run of a fleet starts from the last one.

The run's short realistic winter (``winter_season``: two households, the IMP campaign and the
owner's nights between). Yesterday's run sees every night but the last owner night; today's
sees them all — household 0 with the same IMP nights (its IMP fit is carried over, its season
search starts where yesterday's ended), household 1 with one IMP night fewer (fitted afresh).
Real parts: a local Dask cluster of one worker process, Parquet datasets on disk.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pyarrow.parquet as pq
import pytest
from cli_fixtures import run_impctl

from impctl.errors import InputError
from impctl.fit.household import FitOptions
from impctl.fleet import fit_fleet, read_fleet
from impctl.fleet.results.table import CARRIED_COLUMNS, ROW_COLUMNS, THETA_COLUMNS
from impctl.imp.files.nights_csv import read_nights, write_nights
from impctl.population.season_run.nights import household_nights
from impctl.season.fit import fit_nights

TZ = "Europe/Ljubljana"


@pytest.fixture(scope="module")
def client():
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address="127.0.0.1:0") as cluster, Client(cluster) as c:
        yield c


def _last_owner(nights):
    return max((n for n in nights if n.kind == "owner"), key=lambda n: n.start)


@pytest.fixture(scope="module")
def mornings(tmp_path_factory, winter_season, client):
    root = tmp_path_factory.mktemp("mornings")
    yesterday, today = root / "yesterday", root / "today"
    yesterday.mkdir()
    today.mkdir()
    for i in range(2):
        nights = household_nights(winter_season, i)
        last = _last_owner(nights)
        write_nights([n for n in nights if n is not last], yesterday / f"house-{i}.csv")
        if i == 1:   # an IMP night less (its IMP fit done again), the emitter declared
            imp = [n for n in nights if n.kind == "normal"]
            nights = [dataclasses.replace(n, emitter="underfloor") for n in nights
                      if n is not imp[-1]]
        write_nights(nights, today / f"house-{i}.csv")
    first = fit_fleet(yesterday, root / "F1.parquet", client=client, progress=False,
                      echo=lambda _: None)
    said: list[str] = []
    second = fit_fleet(today, root / "F2.parquet", client=client, progress=False,
                       previous=root / "F1.parquet", echo=said.append)
    return root, first, second, said


def _rows(path):
    return read_fleet(path).set_index("household")


def test_an_unchanged_household_keeps_its_imp_fit_and_warm_starts_its_season(mornings):
    root, first, second, said = mornings
    f1, f2 = _rows(root / "F1.parquet"), _rows(root / "F2.parquet")
    assert first.reused == 0 and not f1["imp_fit_reused"].any()
    assert (f1["status"] == "ok").all() and np.isfinite(f1[list(THETA_COLUMNS)].to_numpy()).all()
    assert second.reused == 1 and any("2 of 2 households" in s for s in said)
    a, b = f1.loc["house-0"], f2.loc["house-0"]
    assert bool(b["imp_fit_reused"]) and bool(b["season_warm_start"])
    assert not bool(b["nights_unchanged"]) and b["nights_digest"] != a["nights_digest"]
    for col in CARRIED_COLUMNS:   # the IMP fit as yesterday's, column by column
        assert (a[col] == b[col]) or (a[col] != a[col] and b[col] != b[col]), col
    # the season model saw the new owner night: one more than yesterday, and where a full
    # search on today's nights ends
    assert b["season_owner_nights"] == a["season_owner_nights"] + 1
    cold, _ = fit_nights(read_nights(root / "today" / "house-0.csv", TZ))
    assert b["season_owner_nights"] == cold.owner_nights
    for k in ("hlc_w_per_k", "tau_h", "c_m_j_per_k"):
        assert b[f"season_{k}"] == pytest.approx(cold.values[k], rel=0.01)


def test_a_household_with_a_changed_imp_night_is_fitted_afresh(mornings):
    root, *_ = mornings
    f1, f2 = _rows(root / "F1.parquet"), _rows(root / "F2.parquet")
    a, b = f1.loc["house-1"], f2.loc["house-1"]
    assert b["status"] == "ok" and not bool(b["imp_fit_reused"])
    assert not bool(b["season_warm_start"])
    assert b["imp_nights_digest"] != a["imp_nights_digest"]
    assert b["nights_normal"] == a["nights_normal"] - 1
    # the file declares its emitter (known): the season model's bound is the installer's
    assert (a["season_emitter"], a["season_emitter_source"]) == ("underfloor", "measured")
    assert (b["season_emitter"], b["season_emitter_source"]) == ("underfloor", "declared")
    # the positive-only meter's defrosts, read from the files' flow and return temperatures
    assert a["season_defrost_draw_source"] == b["season_defrost_draw_source"] \
        == "flow-return spread"


def test_the_same_nights_again_keep_the_whole_row(mornings, client):
    """Run on today's nights again from today's FLEET (a gateway that sent no new night, or the
    same run twice): every row as it was, nothing fitted."""
    root, *_ = mornings
    run = fit_fleet(root / "today", root / "F4.parquet", client=client, progress=False,
                    previous=root / "F2.parquet", echo=lambda _: None)
    assert run.unchanged == run.reused == 2
    f2, f4 = _rows(root / "F2.parquet"), _rows(root / "F4.parquet")
    assert f4["nights_unchanged"].all() and f4["imp_fit_reused"].all()
    for col in ROW_COLUMNS:
        for h in f2.index:
            a, b = f2.loc[h, col], f4.loc[h, col]
            assert (a == b) or (a != a and b != b), (h, col)
    assert (f4["nights_digest"] == f2["nights_digest"]).all()
    assert not f2["nights_unchanged"].any()   # yesterday's run had one night less


def test_a_previous_run_with_other_options_is_not_used(mornings, client):
    root, *_ = mornings
    said: list[str] = []
    run = fit_fleet(root / "today", root / "F3.parquet", client=client, progress=False,
                    previous=root / "F1.parquet", options=FitOptions(night_gain_w=120.0),
                    echo=said.append)
    assert run.reused == 0 and any("other options (night_gain_w)" in s for s in said)
    assert not _rows(root / "F3.parquet")["imp_fit_reused"].any()


def test_a_previous_that_is_not_a_fleet_or_is_out_is_one_line_and_exit_2(mornings, tmp_path):
    root, *_ = mornings
    (tmp_path / "junk").mkdir()
    res = run_impctl("fleet", "fit", str(root / "today"), "--out", str(tmp_path / "F.parquet"),
                     "--previous", str(tmp_path / "junk"), "--quiet")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "junk" in res.stderr and "not a FLEET dataset" in res.stderr
    res = run_impctl("fleet", "fit", str(root / "today"), "--out", str(root / "F1.parquet"),
                     "--previous", str(root / "F1.parquet"), "--resume", "--quiet")
    assert res.returncode == 2 and "is --out itself" in res.stderr
    assert not (tmp_path / "F.parquet").exists()


def test_resuming_a_dataset_of_other_columns_is_refused(mornings, tmp_path):
    root, *_ = mornings
    out = tmp_path / "OLD.parquet"
    out.mkdir()
    old = pq.read_table(next((root / "F1.parquet").glob("part-*.parquet")))
    pq.write_table(old.drop(["imp_nights_digest"]), out / "part-0000-000000.parquet")
    with pytest.raises(InputError, match="another impctl version"):
        fit_fleet(root / "yesterday", out, resume=True, progress=False, echo=lambda _: None)
    assert len(list(out.iterdir())) == 1   # nothing written


def test_one_pass_gives_each_digest_as_its_nights_alone_give_it(winter_season):
    """The IMP nights' and all nights' digests from one pass over the nights are the digests of
    each set alone (a FLEET written before the one pass stays usable as ``--previous``), and a
    changed sample changes them."""
    from impctl.fleet.results.previous import nights_digest, nights_digests
    from impctl.imp.night import split_owner

    nights = household_nights(winter_season, 0)
    imp = {id(n) for n in split_owner(nights)[0]}
    assert 0 < len(imp) < len(nights)
    some, every = nights_digests(nights, lambda n: id(n) in imp)
    assert some == nights_digest([n for n in nights if id(n) in imp])
    assert every == nights_digest(nights) != some
    owner = next(n for n in nights if n.kind == "owner")
    moved = [dataclasses.replace(n, q_hc_w=n.q_hc_w + 1e-9) if n is owner else n for n in nights]
    again = nights_digests(moved, lambda n: id(n) in imp)
    assert again[0] == some and again[1] != every


def test_rows_of_other_code_are_not_carried_over(mornings, tmp_path):
    """Between two releases the code can change under the same version number (a checkout, an
    editable install): the FLEET rows' version carries a digest of the code, and a row of
    other code is fitted afresh."""
    import shutil
    from pathlib import Path

    import impctl
    from impctl.fleet.results.previous import previous_rows
    from impctl.fleet.results.table import source_digest, version

    package = Path(impctl.__file__).resolve().parent
    copy = tmp_path / "impctl"
    shutil.copytree(package, copy, ignore=shutil.ignore_patterns("__pycache__"))
    assert version().endswith("+src." + source_digest(copy))
    module = copy / "season" / "fit.py"
    module.write_text(module.read_text() + "\n# a change\n")
    assert source_digest(copy) != source_digest(package)

    root, *_ = mornings
    decided = _manifest_options(root / "F1.parquet")
    kept, _ = previous_rows(root / "F1.parquet", decided, version())
    assert set(kept) == {"house-0", "house-1"}
    other = version().rsplit("+src.", 1)[0] + "+src." + source_digest(copy)
    kept, said = previous_rows(root / "F1.parquet", decided, other)
    assert kept == {} and "0 of 2 households" in said


def _manifest_options(path):
    from impctl.fleet.results.manifest import read_manifest

    return read_manifest(path).options
