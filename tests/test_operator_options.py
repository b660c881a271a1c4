"""Issue 12, the options and files side: absurd values (physical bounds everywhere), options
that used to end in a traceback (time zones, NaN, negative lengths, impctl-sim), a report from
a wrong fit JSON, a demo with a bad house — each: exit 2, one line naming the option or file,
no traceback, nothing written.

Runs the real ``impctl`` and ``impctl-sim`` command lines in-process (the helpers of
``test_reliability_input``).
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from operator_fixtures import nights, nights_csv
from test_reliability_input import GOOD_HOUSE, _drivers_text, cli, files_in, refused, toml_text

from impctl.errors import InputError
from impctl.model.house_limits import HOUSE_LIMITS

FAST = settings(max_examples=60, deadline=None, derandomize=True)
__all__ = ["nights", "nights_csv"]  # module-scoped fixtures from operator_fixtures

# -- 9. physical bounds ----------------------------------------------------------------------------
def _one_line_about(result, what: str) -> str:
    code, out, err = result
    assert code == 2 and out == "" and "Traceback" not in err, (code, out, err)
    (line,) = err.splitlines()
    assert line.startswith(f"impctl: {what}: "), line
    return line


def test_absurd_options_are_refused(tmp_path, nights_csv):
    out = tmp_path / "out.csv"
    _one_line_about(cli("fit", "--nights", str(nights_csv), "--ach-vent", "1e6", "--json",
                        str(tmp_path / "f.json")), "--ach-vent")
    _one_line_about(cli("simulate", "--setpoint", "99", "--out", str(out)), "--setpoint")
    _one_line_about(cli("simulate", "--t-m-init", "nan", "--out", str(out)), "--t-m-init")
    assert files_in(tmp_path) == set()


@pytest.mark.parametrize("phi", ["1e9", "-5000"])
def test_drivers_heating_power_outside_a_dwelling_is_refused(tmp_path, phi):
    header, *rows = _drivers_text().splitlines()
    rows = [r + ("," + phi if i == 5 else ",") for i, r in enumerate(rows)]
    drivers = tmp_path / "drivers.csv"
    drivers.write_text("\n".join([header + ",phi_hc", *rows]) + "\n")
    line = _one_line_about(cli("simulate", "--drivers", str(drivers), "--out",
                               str(tmp_path / "out.csv")), str(drivers))
    assert "row 7" in line and "phi_hc" in line
    assert files_in(tmp_path) == {"drivers.csv"}


def test_house_floor_area_1e9_and_every_other_problem_at_once(tmp_path):
    house = tmp_path / "house.toml"
    house.write_text(toml_text({**GOOD_HOUSE, "floor_area": 1e9, "u_walls": 50.0,
                                "colour": "blue"}, drop={("c_f",)}))
    code, out, err = cli("simulate", "--house", str(house), "--out", str(tmp_path / "o.csv"))
    assert code == 2 and "Traceback" not in err
    lines = err.splitlines()
    assert all(x.startswith(f"impctl: {house}: key '") for x in lines)
    assert {x.split("key '")[1].split("'")[0] for x in lines} == {"floor_area", "u_walls",
                                                                  "colour", "c_f"}
    assert files_in(tmp_path) == {"house.toml"}


def test_every_iso_domain_problem_of_a_house_is_listed_at_once(tmp_path):
    house = tmp_path / "house.toml"
    house.write_text(toml_text({**GOOD_HOUSE, "floor_area": 12.0, "walls_area": 5000.0,
                                "windows_area": 400.0, "c_f": 3.7, "u_walls": 4.0,
                                "u_windows": 6.0, "ach_infl": 0.0}))
    code, _, err = cli("simulate", "--house", str(house), "--out", str(tmp_path / "o.csv"))
    assert code == 2 and "Traceback" not in err
    assert [x.split("key '")[1].split("'")[0] for x in err.splitlines()] == [
        "ach_infl", "u_walls", "windows_area"]
    assert files_in(tmp_path) == {"house.toml"}


@FAST
@given(st.sampled_from(sorted(HOUSE_LIMITS)), st.booleans(), st.floats(1.0001, 1e6))
def test_every_house_parameter_has_documented_bounds(key, above, factor):
    lo, hi = HOUSE_LIMITS[key]
    value = hi * factor if above else (lo / factor if lo > 0 else -factor)
    with pytest.raises(InputError) as info:
        from impctl.model import house_from_mapping

        house_from_mapping({**GOOD_HOUSE, key: value}, "h.toml")
    assert f"key '{key}'" in str(info.value) and "plausible range" in str(info.value)


def test_bounds_hold_what_the_population_and_the_fit_search(tmp_path):
    from impctl.fit.ode.parameters import PHYSICAL_BOUNDS

    for key, (lo, hi) in PHYSICAL_BOUNDS.items():
        assert HOUSE_LIMITS[key][0] <= lo and hi <= HOUSE_LIMITS[key][1], key


# -- 10. tracebacks --------------------------------------------------------------------------------
def test_unknown_time_zone_is_one_line(nights_csv):
    for argv in (("fit", "--nights", str(nights_csv)), ("classify", "--nights", str(nights_csv)),
                 ("simulate",)):
        line = _one_line_about(cli(*argv, "--tz", "Mars/X"), "--tz")
        assert "Mars/X" in line


def test_nan_and_negative_options_are_one_line(nights_csv):
    _one_line_about(cli("fit", "--nights", str(nights_csv), "--ach-infl", "nan"), "--ach-infl")
    _one_line_about(cli("simulate", "--days", "-1"), "--days")
    _one_line_about(cli("simulate", "--days", "0.2", "--step", "86400"), "--days")


def _sim(*argv: str) -> tuple[int, str]:
    from impctl_sim.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            main(list(argv))
        except SystemExit as exc:
            return exc.code, err.getvalue()
    raise AssertionError(f"impctl-sim {argv} started serving")


@pytest.mark.parametrize("argv", [
    ("--port", "99999"), ("--port", "-1"), ("--baudrate", "0"), ("--speed", "0"),
    ("--speed", "nan"), ("--speed", "1e300"), ("--setpoint", "99"), ("--setpoint", "nan"),
    ("--noise", "-1"), ("--noise", "nan"), ("--dhw-period-h", "-1"), ("--heat-meter-id", "0"),
    ("--heat-meter-id", "300"), ("--wall-epoch", "nan"), ("--weather-seed", "-1"),
    ("--seed", "-1"), ("--clock", "garbage"), ("--faults", "garbage"),
])
def test_impctl_sim_bad_options_are_one_line_exit_2(argv):
    code, err = _sim(*argv)
    assert code == 2 and "Traceback" not in err, err
    (line,) = err.splitlines()
    assert line.startswith("impctl-sim: ")


# -- 10/11. report --fit ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def store_and_fit(tmp_path_factory, nights):
    from datetime import UTC, datetime

    from impctl.fit.estimator import NightFit
    from impctl.fit.result.report import fit_to_dict
    from impctl.store import Store

    work = tmp_path_factory.mktemp("report")
    with Store(work / "impctl.db") as store:
        store.create_night("constrained", 21.0, datetime(2026, 1, 12, 21, tzinfo=UTC),
                           datetime(2026, 1, 13, 4, tzinfo=UTC))
    fit = NightFit(n_starts=1, per_night=False).fit(nights, None)
    good = work / "fit.json"
    good.write_text(json.dumps(fit_to_dict(fit)))
    return work / "impctl.db", good


def _report_refused(work: Path, db: Path, fit_json: Path) -> None:
    out = work / "rep"
    before = files_in(work)
    refused(cli("report", "--db", str(db), "--fit", str(fit_json), "--out", str(out)), fit_json)
    assert files_in(work) == before  # no PNGs, no report directory, no temporary directory


def test_report_refuses_wrong_schema_list_and_binary_json_leaving_nothing(tmp_path,
                                                                          store_and_fit):
    db, _ = store_and_fit
    cases = {"wrong.json": b'{"lumped": {"hlc": 5}, "parameters": {}}', "list.json": b"[1, 2]",
             "binary.json": bytes(range(256)) * 4, "other.json": b'{"schema": "x/1"}',
             "broken.json": b'{"lumped": '}
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        _report_refused(tmp_path, db, tmp_path / name)


def _paths(obj, prefix=()):
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj[:2]):
            yield from _paths(v, (*prefix, i))


_JSON = st.recursive(st.none() | st.booleans() | st.integers(-5, 5) | st.text(max_size=3)
                     | st.sampled_from([1e308, -0.0, 0.5]),
                     lambda c: st.lists(c, max_size=2) | st.dictionaries(st.text(max_size=3), c,
                                                                         max_size=2),
                     max_leaves=4)


@settings(max_examples=6, deadline=None, derandomize=True)
@given(st.data())
def test_fuzzed_fit_json_is_refused_cleanly_or_reported_completely(store_and_fit, data):
    """Any value anywhere in a real fit JSON: exit 2 with nothing written, or a complete
    report (page and four figures)."""
    import tempfile

    db, good = store_and_fit
    fit = json.loads(good.read_text())
    paths = [p for p in _paths(fit) if p]
    path = data.draw(st.sampled_from(paths))
    node = fit
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = data.draw(_JSON)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        bad = work / "fit.json"
        bad.write_text(json.dumps(fit))
        code, out, err = cli("report", "--db", str(db), "--fit", str(bad), "--out",
                             str(work / "rep"))
        if code == 2:
            refused((code, out, err), bad)
            assert files_in(work) == {"fit.json"}
        else:
            assert code == 0, err
            assert {p.name for p in (work / "rep").iterdir()} == {
                "report.html", "fig_nights.png", "fig_heat_demand.png", "fig_classes.png",
                "fig_parameters.png"}


def test_report_help_documents_config_and_out():
    code, out, _ = cli("report", "--help")
    assert code == 0
    text = " ".join(out.split())
    assert "--config" in text and "state_dir" in text
    assert "--out" in text and "report.html" in text


# -- 11. demo with a bad house --------------------------------------------------------------------
def test_demo_with_a_bad_house_leaves_no_demo_log(tmp_path):
    house = tmp_path / "bad.toml"
    house.write_text(toml_text({**GOOD_HOUSE, "floor_area": 1e9}))
    refused(cli("demo", "--house", str(house), "--out", str(tmp_path / "demo")), house)
    assert files_in(tmp_path) == {"bad.toml"}


