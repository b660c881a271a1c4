"""The emitter the season model allows for, read from the heating water the gateway records.

Steady nights of a house with a known emitter law (synthetic: the water's excess over the room
at each night's load), and the run's short realistic winter (``winter_season``: underfloor
houses) through the fit; ``impctl fit``'s emitter line and JSON: test_season.py.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest
from cli_fixtures import run_impctl

from impctl.errors import InputError
from impctl.imp.files.nights_csv import read_nights, write_nights
from impctl.imp.night import NightSamples
from impctl.population.season_run.nights import household_nights
from impctl.season import record_from_nights
from impctl.season.emitter import (
    DECAY_BAND_K,
    LAG_BOUND_S,
    RADIATOR_EXCESS_K,
    SCREED_DECAY_H,
    TAU_E_MAX_UNDERFLOOR_S,
    TAU_E_MAX_UNKNOWN_S,
    emitter_kind,
    lag_bound_s,
    water_decay_h,
    water_excess_k,
)
from impctl.season.fit import fit_nights
from impctl.season.result import format_season

TZ = "Europe/Ljubljana"
HLC_W_PER_K, GAINS_W = 150.0, 250.0


def _nights(design_water_c: float, exponent: float, t_out_c: list[float]) -> list[NightSamples]:
    """Owner records (noon to noon) of a house held at 20 °C whose emitter is sized to give
    the design load at ``design_water_c`` mean water, 10 °C below the design outdoor −10 °C."""
    k = HLC_W_PER_K * 30.0 / (design_water_c - 20.0) ** exponent
    out = []
    for i, te in enumerate(t_out_c):
        start = pd.Timestamp("2026-12-01 12:00", tz=TZ) + pd.Timedelta(days=i)
        t = np.arange(0.0, 24 * 3600, 300.0)
        q = np.full(len(t), HLC_W_PER_K * (20.0 - te) - GAINS_W)
        water = 20.0 + (q / k) ** (1.0 / exponent)
        out.append(NightSamples(f"{start.date()} owner", "owner", start, t, 20.0 + 0 * t,
                                te + 0 * t, q, t_flow_c=water + 2.5, t_return_c=water - 2.5))
    return out


def without_fade(nights: list[NightSamples]) -> list[NightSamples]:
    """The nights with no water on the constrained ones: the fade after a switch-off is not
    read, and the emitter's lag is bounded by the emitter the excess reads (its class)."""
    return [dataclasses.replace(n, t_flow_c=None, t_return_c=None) if n.kind == "constrained"
            else n for n in nights]


@pytest.mark.parametrize(("design_water_c", "exponent", "kind"),
                         [(33.0, 1.1, "underfloor"), (38.0, 1.1, "underfloor"),
                          (45.0, 1.3, "radiators"), (40.0, 1.3, "radiators")])
def test_the_water_tells_radiators_from_a_screed_in_cold_and_mild_weather(
        design_water_c, exponent, kind):
    cold = record_from_nights(_nights(design_water_c, exponent, [-8, -6, -5, -4]))
    mild = record_from_nights(_nights(design_water_c, exponent, [4, 5, 6, 7]))
    ex_cold, ex_mild = water_excess_k(cold, HLC_W_PER_K), water_excess_k(mild, HLC_W_PER_K)
    # one load: a mild night's low water and a cold night's high water give one number
    assert ex_mild == pytest.approx(ex_cold, rel=0.15)
    assert emitter_kind(ex_cold) == emitter_kind(ex_mild) == kind


def _constrained(decay_h: float, off_h: float = 7.0, day: int = 0) -> NightSamples:
    """A constrained night: heat off from 22:00 for ``off_h`` hours (then on again), the room
    cooling, the water's excess over it fading with the e-folding time ``decay_h``."""
    start = pd.Timestamp("2026-12-10 22:00", tz=TZ) + pd.Timedelta(days=day)
    t = np.arange(0.0, 7 * 3600, 300.0)
    air = 21.0 - 2.0 * (1 - np.exp(-t / (30 * 3600.0)))
    on = t >= off_h * 3600.0
    water = air + 12.0 * np.exp(-t / (decay_h * 3600.0)) + np.where(on, 15.0, 0.0)
    q = np.where(on, 3000.0, 0.0)
    return NightSamples(f"{start.date()} constrained", "constrained", start, t, air, 0.0 * t,
                        q, t_flow_c=water + 1.0, t_return_c=water - 1.0)


@pytest.mark.parametrize(("decay_h", "kind"), [(0.8, "radiators"), (2.0, "radiators"),
                                               (5.0, "underfloor"), (8.0, "underfloor")])
def test_where_the_excess_cannot_tell_the_waters_decay_after_a_switch_off_does(decay_h, kind):
    nights = _nights(45.0, 1.3, [-5, 0, 3, 5]) + [_constrained(decay_h, day=d) for d in (0, 1)]
    rec = record_from_nights(nights)
    measured = water_decay_h(rec)
    assert measured == pytest.approx(decay_h, rel=0.05)
    assert emitter_kind(12.0, measured) == kind      # inside the band: the decay decides
    # outside it the excess alone, whatever the decay
    assert emitter_kind(DECAY_BAND_K[0] - 1.0, 0.8) == "underfloor"
    assert emitter_kind(DECAY_BAND_K[1] + 1.0, 8.0) == "radiators"
    assert emitter_kind(12.0) == emitter_kind(12.0, float("nan")) == "underfloor"


def test_the_decay_is_not_read_from_a_short_stretch_or_without_the_water():
    # the heat back within half an hour: too short a stretch to read the water fade
    short = record_from_nights(_nights(45.0, 1.3, [-5, 0, 3]) + [_constrained(2.0, off_h=0.5)])
    assert np.isnan(water_decay_h(short))
    dry = [dataclasses.replace(n, t_flow_c=None, t_return_c=None)
           for n in _nights(45.0, 1.3, [-5, 0, 3]) + [_constrained(2.0)]]
    assert np.isnan(water_decay_h(record_from_nights(dry)))
    # no constrained night: nothing to read it from
    assert np.isnan(water_decay_h(record_from_nights(_nights(45.0, 1.3, [-5, 0, 3]))))
    assert SCREED_DECAY_H > 2.0


def test_without_the_water_or_enough_nights_the_emitter_is_unknown():
    nights = _nights(45.0, 1.3, [-5, 0, 3, 5])
    dry = [dataclasses.replace(n, t_flow_c=None, t_return_c=None) for n in nights]
    assert np.isnan(water_excess_k(record_from_nights(dry), HLC_W_PER_K))
    assert np.isnan(water_excess_k(record_from_nights(nights[:2]), HLC_W_PER_K))
    assert np.isnan(water_excess_k(record_from_nights(nights), float("nan")))
    assert emitter_kind(float("nan")) is None
    assert water_excess_k(record_from_nights(nights), HLC_W_PER_K) > RADIATOR_EXCESS_K


def test_a_screed_house_gets_its_fades_bound_on_the_lag_in_one_search(winter_season, searches):
    """Where a constrained night shows the water's fade, the lag's bound is a share of it —
    one search, said in the JSON and the text — and a warm refit keeps that bound."""
    assert (winter_season.params.emitter.kind == 1).all()     # the run's houses: underfloor
    nights = household_nights(winter_season, 0)
    fit, _ = fit_nights(nights)
    assert fit.water_decay_h >= SCREED_DECAY_H and fit.emitter == "underfloor"
    bound = lag_bound_s(fit.water_decay_h)
    assert searches == [bound] and fit.theta[2] <= bound + 1e-6
    emitter = fit.as_dict()["emitter"]
    assert emitter["tau_e_max_h"] == round(bound / 3600, 2)
    assert emitter["water_decay_h"] == round(fit.water_decay_h, 1)
    assert f"its lag up to {round(bound / 3600, 2):g} h" in "\n".join(format_season(fit))
    # the share of a radiator's fast fade is held at half an hour, a slow screed's at 8 h
    assert lag_bound_s(0.2) == LAG_BOUND_S[0] and lag_bound_s(40.0) == LAG_BOUND_S[1]
    searches.clear()
    refit, _ = fit_nights(nights, start=fit.theta)
    assert searches == [bound] and refit.warm_start
    assert refit.values["hlc_w_per_k"] == pytest.approx(fit.values["hlc_w_per_k"], rel=1e-3)


def test_under_the_fades_bound_the_search_starts_once_from_the_grids_best_point(
        winter_season, monkeypatch):
    """Where the fade bounds the lag, the search runs once, from the start grid's best point
    in the lag's slow basin (clipped to the bound), not from each basin's: here, as on the
    bench, the lower-cost of the two starts the two-basin search takes. (How far the results
    move: decision record 0031.)"""
    from impctl.season.projection import solve
    from impctl.season.projection.columns import Design

    rec = record_from_nights(household_nights(winter_season, 0))
    d, bounds = Design.of(rec), solve.bounds_for(lag_bound_s(water_decay_h(rec)))
    runs: list[np.ndarray] = []
    lm = solve._levenberg_marquardt

    def counted(u0, *args, **kw):
        runs.append(u0.copy())
        return lm(u0, *args, **kw)

    monkeypatch.setattr(solve, "_levenberg_marquardt", counted)
    theta, _, _ = solve.search(d, bounds=bounds, one_start=True)
    assert len(runs) == 1
    solve.search(d, bounds=bounds)
    assert len(runs) == 3            # the two basins' starts
    costs = [float(np.sum(solve._residual(u, d, bounds) ** 2)) for u in runs[1:]]
    assert costs[0] != costs[1]
    assert np.array_equal(runs[0], runs[1 + int(np.argmin(costs))])
    # the season fit takes this path where the fade is read
    runs.clear()
    fit, _ = fit_nights(household_nights(winter_season, 0))
    assert len(runs) == 1 and fit.theta == pytest.approx(theta, rel=1e-9)


def test_a_screed_house_gets_the_screeds_lag_and_says_it_was_measured(winter_season):
    assert (winter_season.params.emitter.kind == 1).all()     # the run's houses: underfloor
    nights = without_fade(household_nights(winter_season, 0))
    fit, _ = fit_nights(nights)
    emitter = fit.as_dict()["emitter"]
    assert fit.emitter == "underfloor" and emitter["source"].startswith("measured")
    assert emitter["tau_e_max_h"] == TAU_E_MAX_UNDERFLOOR_S / 3600
    assert fit.water_excess_k < RADIATOR_EXCESS_K
    dry, _ = fit_nights([dataclasses.replace(n, t_flow_c=None, t_return_c=None)
                         for n in nights])
    assert dry.emitter is None and dry.theta[2] <= TAU_E_MAX_UNKNOWN_S + 1e-6
    assert dry.as_dict()["emitter"]["source"].startswith("assumed")


@pytest.fixture
def searches(monkeypatch) -> list[float]:
    """The upper bound on the emitter's lag [s] of each search the season fit runs, in turn."""
    import impctl.season.fit as season_fit

    calls: list[float] = []
    search = season_fit.search

    def counted(*args, **kw):
        calls.append(kw["bounds"][2][1])
        return search(*args, **kw)

    monkeypatch.setattr(season_fit, "search", counted)
    return calls


def test_a_refit_of_a_screed_house_searches_once_under_the_screeds_bound(winter_season,
                                                                         searches):
    nights = without_fade(household_nights(winter_season, 0))
    full, _ = fit_nights(nights)
    calls = searches
    calls.clear()
    assert full.theta[2] > 1.5 * 3600      # the screed's lag, past the radiators' bound
    refit, _ = fit_nights(nights, start=full.theta)
    assert calls == [TAU_E_MAX_UNDERFLOOR_S] and refit.emitter == "underfloor"
    assert refit.values["hlc_w_per_k"] == pytest.approx(full.values["hlc_w_per_k"], rel=1e-3)
    calls.clear()
    fit_nights(nights)                     # a full search: radiators first, then the screed
    assert calls == [1.5 * 3600, TAU_E_MAX_UNDERFLOOR_S]


def test_a_screed_start_whose_water_reads_radiators_is_read_as_the_full_search_reads_it(
        winter_season, searches, monkeypatch):
    """From a screed fit's θ the water, scaled by the warm search's HLC, may read radiators
    where the full search's reading, at its radiators-bound HLC, reads a screed (a house near
    the threshold). A warm search under the radiators' bound reads it that way: where it reads
    a screed the warm fit stands, no full search; where it reads radiators the full search
    decides."""
    import impctl.season.fit as season_fit

    nights = without_fade(household_nights(winter_season, 0))
    full, _ = fit_nights(nights)
    real = season_fit.water_excess_k
    readings: list[float] = []

    def first_reads_radiators(rec, hlc_w_per_k):
        readings.append(hlc_w_per_k)
        return DECAY_BAND_K[1] + 1.0 if len(readings) == 1 else real(rec, hlc_w_per_k)

    monkeypatch.setattr(season_fit, "water_excess_k", first_reads_radiators)
    searches.clear()
    refit, _ = fit_nights(nights, start=full.theta)
    assert searches == [TAU_E_MAX_UNDERFLOOR_S, 1.5 * 3600]      # no full search
    assert refit.emitter == "underfloor" and refit.warm_start
    assert refit.water_excess_k == real(record_from_nights(nights), readings[1])
    assert refit.values["hlc_w_per_k"] == pytest.approx(full.values["hlc_w_per_k"], rel=1e-3)
    monkeypatch.setattr(season_fit, "water_excess_k",
                        lambda rec, hlc_w_per_k: DECAY_BAND_K[1] + 1.0)
    searches.clear()
    again, _ = fit_nights(nights, start=full.theta)
    assert searches == [TAU_E_MAX_UNDERFLOOR_S, 1.5 * 3600, 1.5 * 3600]   # then the full one
    assert again.emitter == "radiators" and not again.warm_start


def test_a_declared_emitter_is_known_searched_once_and_a_disagreeing_water_is_said(
        winter_season, searches):
    """The installer's word comes before the water: one search under the declared emitter's
    bound, the JSON says "declared", and where the water reads another emitter both the JSON
    and the text say so."""
    import impctl.season.fit as season_fit

    nights = household_nights(winter_season, 0)              # a screed house
    dry = [dataclasses.replace(n, t_flow_c=None, t_return_c=None) for n in nights]
    calls = searches
    known, _ = fit_nights(dry, emitter="underfloor")
    assert calls == [TAU_E_MAX_UNDERFLOOR_S]
    assert known.emitter == "underfloor" and known.theta[2] > TAU_E_MAX_UNKNOWN_S
    block = known.as_dict()["emitter"]
    assert block["source"] == "declared" and "water_reads" not in block
    assert "declared" in "\n".join(format_season(known))
    calls.clear()
    wrong, _ = fit_nights(nights, emitter="radiators")
    assert calls == [1.5 * 3600] and wrong.theta[2] <= 1.5 * 3600 + 1e-6
    assert wrong.as_dict()["emitter"]["water_reads"] == "underfloor"
    assert "the heating water reads underfloor" in "\n".join(format_season(wrong))
    with pytest.raises(ValueError, match="emitter 'screed'"):
        season_fit.fit_season(record_from_nights(nights), emitter="screed")


def test_impctl_fits_season_job_passes_the_declared_emitter_to_its_child(winter_season):
    """``impctl fit --emitter``: the season model runs in a forked child beside the IMP fit;
    the declaration reaches it."""
    from impctl.cli.analysis.fit_cmd import _SeasonJob

    nights = household_nights(winter_season, 0)
    block, _ = _SeasonJob(nights, "radiators").result()
    assert block["emitter"]["source"] == "declared" and block["emitter"]["kind"] == "radiators"
    assert block["emitter"]["water_reads"] == "underfloor"


def test_a_warm_start_from_a_screed_on_a_radiator_house_runs_the_full_search():
    nights = _nights(45.0, 1.3, [-6, -3, -1, 0, 2, 3, 5, 6])
    cold, _ = fit_nights(nights)
    assert cold.emitter == "radiators" and not cold.warm_start
    same, _ = fit_nights(nights, start=cold.theta)   # the fit it starts from read radiators
    assert same.warm_start and same.emitter == "radiators"
    screed = (cold.theta[0], cold.theta[1], 4.0 * 3600, *cold.theta[3:])
    assert screed[2] > 1.5 * 3600 and screed[2] <= TAU_E_MAX_UNDERFLOOR_S
    moved, _ = fit_nights(nights, start=screed)
    # the water reads radiators where the start's fit read a screed: not a morning's step
    assert not moved.warm_start and moved.emitter == "radiators"
    assert moved.theta == cold.theta
    assert moved.values["hlc_w_per_k"] == cold.values["hlc_w_per_k"]


def test_a_refit_of_a_house_whose_water_could_not_tell_searches_once_under_its_bound(
        searches):
    """The water on two nights only (fewer than the emitter test needs): recorded, but it
    cannot tell the emitter, so the lag's bound is the unknown emitter's. A morning's refit
    from such a fit searches once under that bound — not under the screed's and then in
    full (three searches where one does)."""
    nights = _nights(45.0, 1.3, [-6, -3, -1, 0, 2, 3, 5, 6])
    nights = [n if i < 2 else dataclasses.replace(n, t_flow_c=None, t_return_c=None)
              for i, n in enumerate(nights)]
    cold, _ = fit_nights(nights)
    assert cold.emitter is None and searches == [1.5 * 3600, TAU_E_MAX_UNKNOWN_S]
    searches.clear()
    start = (cold.theta[0], cold.theta[1], 2.5 * 3600, *cold.theta[3:])
    warm, _ = fit_nights(nights, start=start, start_bound_s=TAU_E_MAX_UNKNOWN_S)
    assert searches == [TAU_E_MAX_UNKNOWN_S]
    assert warm.warm_start and warm.emitter is None
    assert warm.values["hlc_w_per_k"] == pytest.approx(cold.values["hlc_w_per_k"], rel=0.01)
    # θ alone cannot tell such a fit from a screed's: the screed's bound, then the full search
    searches.clear()
    alone, _ = fit_nights(nights, start=start)
    assert searches == [TAU_E_MAX_UNDERFLOOR_S, 1.5 * 3600, TAU_E_MAX_UNKNOWN_S]
    assert not alone.warm_start


def test_a_warm_start_says_the_bound_its_fit_ended_under(tmp_path):
    """``impctl season --warm-start`` reads the earlier result's emitter bound with its θ
    (the daemon's morning refit runs it so); the fleet's ``--previous`` row its emitter."""
    from impctl.cli.analysis.season_cmd import _warm_start

    nights = _nights(45.0, 1.3, [-6, -3, -1, 0, 2, 3, 5, 6])
    nights = [n if i < 2 else dataclasses.replace(n, t_flow_c=None, t_return_c=None)
              for i, n in enumerate(nights)]
    fit, _ = fit_nights(nights)
    path = tmp_path / "season.json"
    path.write_text(json.dumps({"season": fit.as_dict()}))
    theta, bound = _warm_start(path)
    assert theta == pytest.approx(fit.theta) and bound == TAU_E_MAX_UNKNOWN_S


def test_a_file_declares_the_emitter_and_the_season_model_takes_it(tmp_path):
    nights = [dataclasses.replace(n, emitter="underfloor")
              for n in _nights(45.0, 1.3, [-6, -3, -1, 0, 2, 3])]
    path = write_nights(nights, tmp_path / "n.csv")
    back = read_nights(path, TZ)
    assert {n.emitter for n in back} == {"underfloor"}
    fit, _ = fit_nights(back)
    # known before measured: the installer's word, though the water reads radiators
    assert fit.emitter == "underfloor" and fit.emitter_declared
    assert fit.emitter_dict()["source"] == "declared"
    assert fit.emitter_dict()["water_reads"] == "radiators"
    undeclared, _ = fit_nights(read_nights(write_nights(_nights(45.0, 1.3, [-6, -3, -1, 0, 2, 3]),
                                                        tmp_path / "m.csv"), TZ))
    assert undeclared.emitter == "radiators" and not undeclared.emitter_declared


@pytest.mark.parametrize(("cells", "problem", "row"),
                         [(("screed",), "'screed' is not one of radiators, underfloor", 2),
                          (("radiators", "underfloor"), "'underfloor' after 'radiators'", 3)])
def test_a_bad_or_second_emitter_in_a_file_is_one_line(tmp_path, cells, problem, row):
    path = write_nights(_nights(45.0, 1.3, [-6, -3]), tmp_path / "n.csv")
    frame = pd.read_csv(path)
    frame["emitter"] = ""
    for i, c in enumerate(cells):
        frame.loc[i, "emitter"] = c
    frame.to_csv(path, index=False)
    with pytest.raises(InputError) as err:
        read_nights(path, TZ)
    assert problem in str(err.value) and f"row {row}" in str(err.value)
    assert "column 'emitter'" in str(err.value) and "\n" not in str(err.value)


def test_the_command_line_and_the_file_must_agree_on_the_emitter(tmp_path):
    nights = [dataclasses.replace(n, emitter="radiators")
              for n in _nights(45.0, 1.3, [-6, -3, -1, 0, 2, 3])]
    path = write_nights(nights, tmp_path / "n.csv")
    res = run_impctl("season", "--nights", str(path), "--emitter", "underfloor")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "--emitter underfloor, but the file's emitter column says radiators" in res.stderr
    agreed = run_impctl("season", "--nights", str(path), "--emitter", "radiators", "--json",
                        str(tmp_path / "s.json"))
    assert agreed.returncode == 0, agreed.stderr
    block = json.loads((tmp_path / "s.json").read_text())["season"]
    assert block["emitter"]["source"] == "declared" and block["emitter"]["kind"] == "radiators"
