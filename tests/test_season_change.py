"""Has the house changed? The change test on simulated owner nights, ``impctl fit`` and HA.

One short winter of three realistic households simulated once (the IMP campaign every other
night from the first, the owner's nights between, hot water, defrosts, the gains wandering):
the first gets a window left open from its 22nd night on, the others nothing.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
from datetime import datetime

import numpy as np
import pytest
from test_nights_owner import run_cli

from impctl import change
from impctl.imp.files.nights_csv import write_nights
from impctl.mqtt.homeassistant.payloads import fit_payloads
from impctl.plant import PlantCore
from impctl.population.households import sample_households
from impctl.population.realism import sample_params
from impctl.population.season_run.nights import household_nights
from impctl.population.season_run.season import SeasonConfig, simulate_season, step_network

STEP_NIGHT, WINDOW_W_K = 22, 50.0


@pytest.fixture(scope="module")
def season(build_once):
    """40 nights: the step found 11 days after it (the test allows 16), the third house with
    29 nights for its verdict (MIN_NIGHTS 24); each night more costs ~0.5 CPU-s. Simulated
    once per test run."""
    def build():
        houses, params = sample_households(3, seed=31), sample_params(3, 31)
        return simulate_season(houses, params, SeasonConfig(nights=40), seed=31,
                               hlc_step_w_k=[WINDOW_W_K, 0.0, 0.0], step_night=STEP_NIGHT)

    return build_once("season-change-window", build)


def _days(a: str, b: str) -> int:
    return (dt.date.fromisoformat(b) - dt.date.fromisoformat(a)).days


def test_the_plant_step_changes_the_hlc_by_exactly_the_step():
    houses, params = sample_households(50, seed=7), sample_params(50, 7)
    net = PlantCore(houses, params, 0).network

    def hlc(n):
        a = n.h_w + n.h_ms * n.h_em / (n.h_ms + n.h_em)
        return n.h_ve + n.h_is * a / (n.h_is + a)

    for d in (-14.0, 20.0):
        assert hlc(step_network(net, np.full(50, d))) - hlc(net) == pytest.approx(d, abs=1e-9)
    with pytest.raises(ValueError, match="larger than"):
        step_network(net, np.full(50, -1e5))


def test_a_window_left_open_is_found_within_sixteen_nights(season):
    step_date = season.nights[STEP_NIGHT][0]
    rows = change.night_rows(household_nights(season, 0))
    at, found = change.detect_sequence(rows)
    assert at > 0, found
    assert 0 <= _days(step_date, rows.dates[at - 1]) <= 16
    assert abs(_days(step_date, found.since_date)) <= 2
    assert found.low_w_k <= WINDOW_W_K <= found.high_w_k
    # Before the step the same house says nothing.
    before = sum(d < step_date for d in rows.dates)
    assert not change.change_of(rows.head(before)).changed


def test_no_alarm_through_a_cold_spell_and_a_week_away(season):
    nights = household_nights(season, 1)
    rows = change.night_rows(nights)
    assert np.ptp(rows.dt_k) >= 8.0          # the season has its cold and mild spells
    # A week away: seven owner nights the setback and the empty house spoil, labelled.
    owner = [i for i, n in enumerate(nights) if n.kind == "owner"]
    away = set(owner[len(owner) // 2: len(owner) // 2 + 7])
    nights = [dataclasses.replace(n, q_hc_w=0.4 * n.q_hc_w, t_air_c=n.t_air_c - 4.0,
                                  label="away: the owner's week away")
              if i in away else n for i, n in enumerate(nights)]
    at, found = change.detect_sequence(change.night_rows(nights))
    assert at == -1 and not found.changed, found
    assert found.nights < len(rows)           # the labelled nights are not read


def test_impctl_fit_prints_the_change_and_the_json_carries_it(tmp_path, season):
    csv = write_nights(household_nights(season, 0), tmp_path / "nights.csv")
    out = tmp_path / "fit.json"
    res = run_cli("fit", "--nights", str(csv), "--json", str(out),
                  model_dir=tmp_path / "no-models")
    assert res.returncode == 0, res.stderr
    c = json.loads(out.read_text())["season"]["change"]
    assert c["changed"] is True and abs(c["delta_hlc_w_k"] - WINDOW_W_K) <= 15.0
    assert abs(_days(season.nights[STEP_NIGHT][0], c["since_date"])) <= 2
    assert f"changed since {c['since_date']}: heat loss +" in res.stdout
    assert c["nights_after"] >= 1
    assert c["fit_reads"] == "all nights"
    assert "the estimate above still reads the nights before it" in res.stdout


def test_the_fit_json_says_nothing_changed_where_nothing_did(season):
    found = change.detect_change(household_nights(season, 2))
    assert found.nights >= change.MIN_NIGHTS and not found.changed
    c = found.as_dict()
    assert c["changed"] is False and c["since_date"] is None and c["delta_hlc_w_k"] is None


def test_nights_without_the_household_electricity_have_their_own_higher_threshold(season):
    nights = household_nights(season, 2)
    with_house = change.detect_change(nights)
    without = change.detect_change([dataclasses.replace(n, p_house_w=float("nan"))
                                    for n in nights])
    assert change.THRESHOLD_NO_HOUSE > change.THRESHOLD
    assert with_house.as_dict()["threshold"] == change.THRESHOLD
    assert without.as_dict()["threshold"] == change.THRESHOLD_NO_HOUSE
    # Night after night, the gateway without the meter alarms only past its own threshold.
    rows = change.night_rows([dataclasses.replace(n, p_house_w=float("nan"))
                              for n in household_nights(season, 0)])
    for m in range(change.MIN_NIGHTS, len(rows) + 1):
        c = change.change_of(rows.head(m))
        assert c.changed == (c.statistic >= change.THRESHOLD_NO_HOUSE), (m, c)


def test_home_assistant_shows_since_when_the_house_changed():
    created = datetime(2027, 1, 20, 6, tzinfo=dt.UTC)
    season = {"hlc_w_per_k": {"value": 150.0, "low": 130.0, "high": 170.0}, "owner_nights": 40,
              "change": {"changed": True, "since_date": "2027-01-02", "delta_hlc_w_k": 21.5,
                         "lo": 12.0, "hi": 31.0, "nights_after": 14}}
    hlc = fit_payloads((created, [1], {"lumped": {}, "season": season}))["hlc"]
    assert hlc["changed_since"] == "2027-01-02" and hlc["change_w_per_k"] == 21.5
    assert (hlc["change_low"], hlc["change_high"]) == (12.0, 31.0)
    season["change"] = {"changed": False, "since_date": None}
    hlc = fit_payloads((created, [1], {"lumped": {}, "season": season}))["hlc"]
    assert hlc["changed_since"] is None and hlc["change_w_per_k"] is None


def test_the_fleet_says_which_households_changed_and_since_when(tmp_path, season):
    from distributed import Client, LocalCluster

    from impctl.fleet import fit_fleet, read_fleet

    folder = tmp_path / "nights"
    folder.mkdir()
    for i in (0, 1):
        write_nights(household_nights(season, i), folder / f"house-{i}.csv")
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address="127.0.0.1:0") as cluster, Client(cluster) as client:
        run = fit_fleet(folder, tmp_path / "FLEET.parquet", client=client, progress=False,
                        echo=lambda _: None)
    assert run.changed == 1
    rows = read_fleet(tmp_path / "FLEET.parquet").set_index("household")
    opened, kept = rows.loc["house-0"], rows.loc["house-1"]
    assert bool(opened["season_changed"]) is True
    assert isinstance(opened["season_changed_since"], dt.date)   # a date column, not text
    assert abs(_days(season.nights[STEP_NIGHT][0],
                     opened["season_changed_since"].isoformat())) <= 2
    assert (opened["season_change_w_per_k_low"] <= WINDOW_W_K
            <= opened["season_change_w_per_k_high"])
    assert abs(opened["season_change_w_per_k"] - WINDOW_W_K) <= 15.0
    assert opened["season_change_nights_after"] >= 1
    assert bool(kept["season_changed"]) is False
    from impctl.report.fleet import write_fleet_report

    page = write_fleet_report(tmp_path / "FLEET.parquet", tmp_path / "report").read_text()
    assert "Households whose heat loss changed (1)" in page
    assert f"<td>house-0</td><td>{opened['season_changed_since']}</td>" in page
    assert kept[["season_changed_since", "season_change_w_per_k",
                 "season_change_nights_after"]].isna().all()
