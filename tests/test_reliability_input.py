"""Bad input: exit status 2, one line per problem naming the file, never a traceback, nothing
written — property-based (hypothesis) over the daemon config TOML, the house TOML, DRIVERS.csv
and NIGHTS.csv; and register words that are sentinels or out of range never reach the store
as temperatures.

Two kinds of checks:

* **malformed by construction** — every single mutation of a valid file from a catalogue
  (wrong type, NaN/±inf, out of range, unknown or missing key, table replaced by a scalar,
  broken syntax, bad cells, bad timestamps, ragged rows, sentinels such as −600, binary
  garbage) is run through the real ``impctl`` command line in-process
  (:func:`impctl.cli.main`): exit 2, every stderr line ``impctl: FILE: …`` (the config lists
  one line per problem, everything else exactly one line), no traceback, and no output file,
  temporary file or state directory left behind. Hypothesis then combines several mutations
  at once;
* **fuzzed** — hypothesis-generated files (random keys and values, random CSV cells) go to
  the readers: they either refuse with an InputError or accept something the daemon or the
  model can use without failing (finite numbers, a clock, a schedule, a finite simulation).

Existing tests already pin the exact wording of individual problems
(``test_daemon_config``, ``test_simulate_cli``, ``test_imp_nights_csv``) and decode every raw
word of every temperature register (``test_heatpump_registers``); these tests add the search.
"""

from __future__ import annotations

import asyncio
import contextlib
import io
import math
import tempfile
import threading
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from impctl.cli import main as impctl_main
from impctl.errors import InputError

SETTINGS = settings(max_examples=150, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])


# -- the command line, in-process ----------------------------------------------------------------
def cli(*argv: str) -> tuple[int, str, str]:
    """Run ``impctl ARGV`` in this process: (exit status, stdout, stderr). Any exception other
    than SystemExit propagates — that is a traceback a user would have seen."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            impctl_main(list(argv))
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
    return code, out.getvalue(), err.getvalue()


def refused(result: tuple[int, str, str], path: Path, *, one_line: bool = True) -> list[str]:
    """Assert exit 2 with ``impctl: PATH: …`` lines only; return them."""
    code, out, err = result
    lines = err.splitlines()
    assert code == 2, (code, out, err)
    assert lines and all(line.startswith(f"impctl: {path}: ") for line in lines), err
    assert "Traceback" not in err and out == "", (out, err)
    if one_line:
        assert len(lines) == 1, err
    return lines


def _short(what: str, exc: Exception) -> str:
    return f"{what}: {type(exc).__name__}: {(str(exc) or '-').splitlines()[0][:90]}"


def assert_all_refused(tmp_path: Path, cases, check) -> None:
    """Run ``check(workdir, case)`` for every ``(what, case)`` in its own directory; collect
    every failure (a traceback is a failure too) and report them all at once."""
    failures = []
    for i, (what, case) in enumerate(cases):
        work = tmp_path / str(i)
        work.mkdir()
        try:
            check(work, case)
        except Exception as exc:  # noqa: BLE001 - list every failing case, not just the first
            failures.append(_short(what, exc))
    assert not failures, f"{len(failures)} of {len(cases)}:\n" + "\n".join(failures)


def files_in(directory: Path) -> set[str]:
    return {str(p.relative_to(directory)) for p in directory.rglob("*")}


# -- TOML text -----------------------------------------------------------------------------------
def toml_text(mapping: dict, raw: dict[tuple[str, ...], str] | None = None,
              drop: set[tuple[str, ...]] = frozenset(), prefix: tuple[str, ...] = ()) -> str:
    """``mapping`` as TOML; ``raw`` puts literal TOML text at a key path (added if missing),
    ``drop`` leaves keys out."""
    raw = raw or {}

    def value(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, (int, float)):
            return repr(v)
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        return "[" + ", ".join(value(x) for x in v) + "]"

    lines, tables = [], []
    keys = list(mapping) + [p[len(prefix)] for p in raw if len(p) == len(prefix) + 1
                            and p[:len(prefix)] == prefix and p[len(prefix)] not in mapping]
    for key in keys:
        path = (*prefix, key)
        if path in drop:
            continue
        if path in raw:
            lines.append(f"{key} = {raw[path]}")
        elif isinstance(mapping[key], dict):
            tables.append(key)
        else:
            lines.append(f"{key} = {value(mapping[key])}")
    text = "\n".join(lines) + "\n"
    for key in tables:
        path = (*prefix, key)
        text += f"\n[{'.'.join(path)}]\n" + toml_text(mapping[key], raw, drop, path)
    return text


# -- the daemon configuration ---------------------------------------------------------------------
def base_config(state_dir: Path) -> dict:
    """A valid configuration with every key the checks below touch."""
    return {
        "state_dir": str(state_dir), "timezone": "Europe/Ljubljana", "log_level": "info",
        "heatpump": {"host": "127.0.0.1", "port": 502, "timeout_s": 3.0, "attempts": 3,
                     "connect_backoff_s": [0.5, 30.0], "drain_s": 0.2, "device_id": 20,
                     "transport": "tcp", "generation": "auto",
                     "writes": {"loop1_setpoint_c": [16.0, 23.0], "daily_budget": 12,
                                "verify_attempts": 3, "verify_delay_s": 0.5,
                                "restore_reserve": 2}},
        "night": {"window": "22:00-05:00", "comfort_band_k": 1.5, "sample_interval_s": 60.0,
                  "abort_margin_k": 0.5, "link_lost_limit_s": 900.0, "t_out_min_c": -25.0,
                  "t_out_max_c": 8.0, "constrained_action": "loop_off",
                  "setpoint_floor_c": 18.0, "preheat_h": 2.0, "emission_lag_h": 1.0,
                  "min_coverage": 0.8},
        "campaign": {"mode": "fixed", "target_rel_halfwidth": {"hlc": 0.05, "tau": 0.08},
                     "constrained_nights": 2, "constrained_setpoint_c": 21.0,
                     "normal_setpoints_c": [21.0, 22.0], "misfire_grace_s": 3600.0,
                     "enabled": True},
        "clock": {"epoch": "2026-01-12T20:00:00+00:00", "speed": 600.0,
                  "wall_epoch_s": 1.8e9},
    }


_NONFINITE = ["nan", "inf", "-inf"]
#: Key path → TOML literals each of which makes the configuration malformed.
BAD_CONFIG_VALUES: dict[tuple[str, ...], list[str]] = {
    ("state_dir",): ["5", "[1]"],
    ("timezone",): ['"Mars/Olympus_Mons"', '""', "1"],
    ("log_level",): ['"verbose"', "3"],
    ("night", "window"): ['"22:00"', '"25:00-05:00"', '"22:00-22:00"', '"ab:cd-ef:gh"', '""',
                          "2200"],
    ("night", "comfort_band_k"): ["0", "-1.0", "3.5", '"1.5"', *_NONFINITE],
    ("night", "sample_interval_s"): ["4", "901", "true", *_NONFINITE],
    ("night", "abort_margin_k"): ["-0.1", "2.5", *_NONFINITE],
    ("night", "link_lost_limit_s"): ["1", "[900]", *_NONFINITE],
    ("night", "t_out_min_c"): ["20.0", *_NONFINITE],
    ("night", "t_out_max_c"): ["-30.0", *_NONFINITE],
    ("night", "constrained_action"): ['"off"', "0"],
    ("night", "setpoint_floor_c"): ["10.0", "30.0", *_NONFINITE],
    ("night", "preheat_h"): ["-1.0", "48.0", *_NONFINITE],
    ("night", "emission_lag_h"): ["-1.0", *_NONFINITE],
    ("night", "min_coverage"): ["0", "1.5", *_NONFINITE],
    ("campaign", "constrained_nights"): ["-1", "1.5", '"two"'],
    ("campaign", "constrained_setpoint_c"): ["30.0", "10.0", *_NONFINITE],
    ("campaign", "normal_setpoints_c"): ["[30.0]", "[nan]", '["21"]', "21.0"],
    ("campaign", "misfire_grace_s"): ["-1.0", "0", "0.5", *_NONFINITE],
    ("campaign", "enabled"): ['"yes"', "1"],
    ("campaign", "mode"): ['"smart"', "1"],
    ("campaign", "max_nights"): ["1", "2.5"],
    ("campaign", "min_each_kind"): ["0", "5"],
    ("campaign", "stall_nights"): ["0"],
    ("campaign", "target_rel_halfwidth"): ["0.05"],
    ("campaign", "target_rel_halfwidth", "hlc"): ["0", "1.5", '"5 %"', "nan"],
    ("campaign", "target_rel_halfwidth", "colour"): ['"blue"'],
    ("clock", "speed"): ["0", "-1.0", *_NONFINITE],
    ("clock", "epoch"): ['"yesterday"', '"2026-01-12T20:00:00"', "2026-01-12T20:00:00Z"],
    ("clock", "wall_epoch_s"): ["-1.0", "1", *_NONFINITE],
    ("heatpump", "host"): ["5", "[1]"],
    ("heatpump", "port"): ["0", "70000", '"502"', "502.5"],
    ("heatpump", "timeout_s"): ["0", "-1.0", '"3"', *_NONFINITE],
    ("heatpump", "attempts"): ["0", "2.5", "true"],
    ("heatpump", "connect_backoff_s"): ["[0, 1]", "[2.0, 1.0]", "[1.0]", "1.0", "[nan, 1.0]"],
    ("heatpump", "transport"): ['"udp"', "1"],
    ("heatpump", "device_id"): ["0", "300", "20.5"],
    ("heatpump", "drain_s"): ["-1.0", *_NONFINITE],
    ("heatpump", "generation"): ['"newest"', "2"],
    ("heatpump", "writes", "loop1_setpoint_c"): ["[30.0, 20.0]", "[0.0, 10.0]", "[16.0]",
                                                 "[16.0, nan]", "20.0"],
    ("heatpump", "writes", "daily_budget"): ["-1", "3", "12.5", '"12"'],
    ("heatpump", "writes", "verify_attempts"): ["0", "2.5"],
    ("heatpump", "writes", "verify_delay_s"): ["-1.0", *_NONFINITE],
    ("heatpump", "writes", "restore_reserve"): ["-1", "1.5"],
    # Unknown keys, and tables that are not tables.
    ("colour",): ['"blue"'],
    ("night", "colour"): ['"blue"'],
    ("heatpump", "colour"): ['"blue"'],
    ("heatpump", "writes", "colour"): ['"blue"'],
    ("night",): ["5", '"x"'],
    ("campaign",): ["true"],
    ("clock",): ["[]"],
    ("heatpump",): ["5"],
    ("heatpump", "writes"): ["5", "[1]"],
}
_BROKEN_TOML = ["[night\nwindow = 1\n", "window =\n", 'log_level = "info\n',
                'log_level = "info"\nlog_level = "debug"\n', "[night]\n[night]\n",
                "\xff\xfe binary \x00\n"]


def config_mutations() -> list[tuple[str, Callable[[dict], str]]]:
    """(description, base mapping → malformed TOML text)."""
    out: list[tuple[str, Callable[[dict], str]]] = []
    for path, literals in BAD_CONFIG_VALUES.items():
        for lit in literals:
            out.append((f"{'.'.join(path)} = {lit}",
                        lambda base, p=path, v=lit: toml_text(base, {p: v})))
    for text in _BROKEN_TOML:
        out.append((f"broken TOML {text[:20]!r}", lambda base, t=text: toml_text(base) + t))
    return out


CONFIG_MUTATIONS = config_mutations()


def _write(path: Path, text: str) -> Path:
    # "\xff" marks deliberate binary garbage; a fuzzed cell may add characters beyond latin-1
    # to it (seen under load), which stay garbage as "?".
    path.write_bytes(text.encode("utf-8", errors="surrogateescape")
                     if "\xff" not in text else text.encode("latin-1", errors="replace"))
    return path


def _config_refused(tmp: Path, text: str) -> None:
    """The daemon refuses this config: exit 2, one line per problem, nothing created."""
    from impctl.config import load_config

    path = _write(tmp / "config.toml", text)
    try:
        cfg = load_config(path)
    except InputError:
        pass
    else:
        raise AssertionError(f"malformed config accepted ({cfg.source})")
    refused(cli("daemon", "--config", str(path)), path, one_line=False)
    refused(cli("status", "--config", str(path)), path, one_line=False)
    assert files_in(tmp) == {"config.toml"}  # no state directory, no store


def test_every_single_config_mutation_is_refused(tmp_path):
    assert_all_refused(tmp_path, CONFIG_MUTATIONS,
                       lambda work, mutate: _config_refused(
                           work, mutate(base_config(work / "state"))))


@SETTINGS
@given(st.lists(st.integers(0, len(CONFIG_MUTATIONS) - 1), min_size=2, max_size=4,
                unique=True))
def test_several_config_mutations_at_once_are_refused(picks):
    with tempfile.TemporaryDirectory() as tmp:
        base = base_config(Path(tmp) / "state")
        raw, broken = {}, ""
        for i in picks:
            what, _ = CONFIG_MUTATIONS[i]
            key, sep, lit = what.partition(" = ")
            if what.startswith("broken TOML"):
                broken = CONFIG_MUTATIONS[i][1](base)[len(toml_text(base)):]
            elif sep and tuple(key.split(".")) in BAD_CONFIG_VALUES:
                raw[tuple(key.split("."))] = lit
        if not raw and not broken:
            raw[("night", "comfort_band_k")] = "nan"
        _config_refused(Path(tmp), toml_text(base, raw) + broken)


_ANY_TOML_VALUE = st.one_of(
    st.integers(-10**6, 10**6).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(
        lambda f: "nan" if math.isnan(f) else ("inf" if f == math.inf else
                                                 "-inf" if f == -math.inf else repr(f))),
    st.text(st.characters(codec="ascii", exclude_characters='"\\\n\r'), max_size=12).map(
        lambda s: f'"{s}"'),
    st.booleans().map(lambda b: "true" if b else "false"),
    st.lists(st.floats(-100, 100), max_size=3).map(lambda v: "[" + ", ".join(map(repr, v))
                                                    + "]"),
    st.sampled_from(["2026-01-12T20:00:00Z", "{a = 1}", '"22:00-05:00"', '"UTC"']),
)


@SETTINGS
@given(st.dictionaries(st.sampled_from(sorted(BAD_CONFIG_VALUES)), _ANY_TOML_VALUE,
                       min_size=1, max_size=5))
def test_fuzzed_configs_are_refused_cleanly_or_usable(values):
    """Any value at any key: an InputError (exit 2, nothing created) or a configuration the
    daemon can start from — finite numbers, a clock, a policy, a schedule, a budget."""
    from impctl.config import load_config
    from impctl.daemon.nights.schedule import act_trigger, campaign_plan, next_act_time
    from impctl.daemon.service import clock_from_config, policy_from_config
    from impctl.heatpump import WriteBudget
    from impctl.modbus import ModbusLink

    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        path = _write(work / "config.toml", toml_text(base_config(work / "state"), values))
        try:
            cfg = load_config(path)
        except InputError:
            refused(cli("daemon", "--config", str(path)), path, one_line=False)
            assert files_in(work) == {"config.toml"}
            return
        for section in (cfg.night, cfg.campaign, cfg.clock, cfg.heatpump.link,
                        cfg.heatpump.writes):
            for name, v in vars(section).items():
                for x in (v if isinstance(v, tuple) else (v,)):
                    if isinstance(x, float):
                        assert math.isfinite(x), (name, v)
        clock = clock_from_config(cfg)
        policy_from_config(cfg)
        campaign_plan(cfg)
        act_trigger(cfg)
        next_act_time(cfg, clock.now())
        WriteBudget(work / "writes.db", cfg.heatpump.writes.daily_budget).close()

        async def client_builds() -> None:
            link = ModbusLink(cfg.heatpump.link)
            link._make_client().close()

        asyncio.run(client_builds())


# -- the house file --------------------------------------------------------------------------------
GOOD_HOUSE = {"floor_area": 120.0, "wall_height": 2.5, "walls_area": 150.0,
              "windows_area": 24.0, "c_f": 2.6, "u_walls": 0.4, "u_windows": 1.2,
              "ach_vent": 0.0, "ach_infl": 0.3}
_POSITIVE = ("floor_area", "wall_height", "walls_area", "windows_area", "u_walls", "u_windows")
BAD_HOUSE_VALUES: dict[str, list[str]] = {
    **{k: ["0", "-1.0", '"1"', "true", "[1.0]", *_NONFINITE] for k in _POSITIVE},
    "c_f": ["0.4", "5.1", *_NONFINITE],
    "ach_infl": ["-0.1", *_NONFINITE],
    "heat_recovery": ["-0.1", "1.1", "nan"],
    "max_heating_power": ["0", "-1.0", "nan", "-inf"],
    "colour": ['"blue"'],
}


def _drivers_text(rows: int = 24) -> str:
    stamps = pd.date_range("2026-01-12T00:00", periods=rows, freq="h")
    return "timestamp,t_out,setpoint\n" + "".join(
        f"{t.isoformat()},{-2.0 + 0.1 * i:.1f},21.0\n" for i, t in enumerate(stamps))


def _simulate_refused(work: Path, bad: Path, house: Path, drivers: Path, *,
                      one_line: bool = True) -> None:
    out = work / "out.csv"
    before = files_in(work)
    refused(cli("simulate", "--house", str(house), "--drivers", str(drivers), "--out",
                str(out)), bad, one_line=one_line)
    assert files_in(work) == before  # no OUT.csv, no temporary file


def _house_refused(work: Path, text: str) -> None:
    from impctl.model import load_house

    house = _write(work / "house.toml", text)
    drivers = _write(work / "drivers.csv", _drivers_text())
    try:
        load_house(house)
    except InputError:
        pass
    else:
        raise AssertionError(f"malformed house accepted:\n{text}")
    _simulate_refused(work, house, house, drivers, one_line=False)  # one line per problem


def test_every_single_house_mutation_is_refused(tmp_path):
    cases = [(f"{k} = {v}", toml_text(GOOD_HOUSE, {(k,): v}))
             for k, values in BAD_HOUSE_VALUES.items() for v in values]
    cases += [(f"{k} missing", toml_text(GOOD_HOUSE, drop={(k,)})) for k in GOOD_HOUSE
              if k != "ach_vent"]
    cases += [("no air exchange", toml_text(GOOD_HOUSE, {("ach_infl",): "0.0"}))]
    cases += [(f"broken TOML {t[:12]!r}", toml_text(GOOD_HOUSE) + t) for t in _BROKEN_TOML]
    assert_all_refused(tmp_path, cases, _house_refused)


@SETTINGS
@given(st.dictionaries(st.sampled_from(sorted(BAD_HOUSE_VALUES)), _ANY_TOML_VALUE,
                       min_size=1, max_size=4))
def test_fuzzed_house_files_are_refused_cleanly_or_simulate_finitely(values):
    from impctl.model import load_house, simulate

    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        path = _write(work / "house.toml", toml_text(GOOD_HOUSE, {(k,): v
                                                                  for k, v in values.items()}))
        try:
            house = load_house(path)
        except InputError:
            _simulate_refused(work, path, path, _write(work / "drivers.csv", _drivers_text()),
                              one_line=False)
            return
        for value in (house.hlc_w_per_k, house.c_m_j_per_k, house.tau_h):
            assert np.isfinite(value) and value > 0, (values, value)
        out = simulate(house, np.full(48, -5.0), 3600.0, setpoint_c=21.0)
        assert all(np.all(np.isfinite(np.asarray(v))) for v in vars(out).values()
                   if isinstance(v, np.ndarray)), values


# -- DRIVERS.csv and NIGHTS.csv -------------------------------------------------------------------
#: Cell values that make a numeric cell malformed (−600 and 2150: a sensor sentinel and a
#: temperature in tenths of a degree, the commonest wrong exports).
BAD_NUMBERS = ["abc", "nan", "inf", "-inf", "1e400", "", "1e300", "-600", "2150", "21,5"]
BAD_STAMPS = ["yesterday", "", "2026-13-01T00:00", "2026-01-12T25:00", "1e9"]


def csv_mutations(text: str, numeric: dict[str, list[str]], equal_steps: bool
                  ) -> list[tuple[str, str]]:
    """(description, malformed CSV text) derived from a valid ``text``; ``numeric`` maps a
    column to the cell values that are malformed there."""
    header, *rows = text.splitlines()
    cols = header.split(",")
    out = []

    def with_row(i: int, row: str) -> str:
        return "\n".join([header, *rows[:i], row, *rows[i + 1:]]) + "\n"

    mid = len(rows) // 2
    for col, bad_values in numeric.items():
        j = cols.index(col)
        for bad in bad_values:
            cells = rows[mid].split(",")
            cells[j] = bad
            out.append((f"{col} = {bad!r}", with_row(mid, ",".join(cells))))
    for bad in BAD_STAMPS:
        cells = rows[mid].split(",")
        cells[0] = bad
        out.append((f"timestamp = {bad!r}", with_row(mid, ",".join(cells))))
    out.append(("duplicate timestamp", with_row(mid, rows[mid - 1])))
    out.append(("rows out of order", "\n".join([header, *rows[::-1]]) + "\n"))
    if equal_steps:
        out.append(("a row missing (unequal steps)", "\n".join([header, *rows[:mid],
                                                                 *rows[mid + 1:]]) + "\n"))
    out.append(("ragged row: extra cell", with_row(mid, rows[mid] + ",1,2")))
    out.append(("ragged row: missing cell", with_row(mid, rows[mid].rsplit(",", 1)[0])))
    for col in cols[:2]:
        j = cols.index(col)
        out.append((f"column {col} missing", "\n".join(
            ",".join(c for k, c in enumerate(line.split(",")) if k != j)
            for line in [header, *rows]) + "\n"))
    out.append(("header only", header + "\n"))
    out.append(("empty file", ""))
    out.append(("binary garbage", "\x00\xff\xfe\x01" * 20))
    return out


def _nights_text(rows: int = 24) -> str:
    stamps = pd.date_range("2026-01-12T22:00", periods=rows, freq="10min")
    return "timestamp,t_air,t_out,q_hc,night,kind\n" + "".join(
        f"{t.isoformat()},{22.5 - 0.05 * i:.2f},-1.0,0.0,n1,constrained\n"
        for i, t in enumerate(stamps))


_NOT_EMPTY = [b for b in BAD_NUMBERS if b != ""]  # an empty setpoint means "heating off"
# 2150 W is a plausible heat output and −600 W a defrost's draw on a signed heat reading;
# −30000 W is below any defrost
_POWER = [b for b in BAD_NUMBERS if b not in ("2150", "-600")] + ["-30000"]
DRIVERS_MUTATIONS = csv_mutations(_drivers_text(), {"t_out": BAD_NUMBERS,
                                                    "setpoint": _NOT_EMPTY}, equal_steps=True)
NIGHTS_MUTATIONS = csv_mutations(_nights_text(), {"t_air": BAD_NUMBERS, "t_out": BAD_NUMBERS,
                                                  "q_hc": _POWER}, equal_steps=False)


def _drivers_refused(work: Path, text: str) -> None:
    from impctl.drivers import read_drivers

    drivers = _write(work / "drivers.csv", text)
    house = _write(work / "house.toml", toml_text(GOOD_HOUSE))
    try:
        read_drivers(drivers, None, "Europe/Ljubljana")
    except InputError:
        pass
    else:
        raise AssertionError(f"malformed drivers accepted:\n{text}")
    _simulate_refused(work, drivers, house, drivers)


def _nights_refused(work: Path, text: str) -> None:
    from impctl.imp import read_nights

    nights = _write(work / "nights.csv", text)
    try:
        read_nights(nights, "Europe/Ljubljana")
    except InputError:
        pass
    else:
        raise AssertionError(f"malformed nights accepted:\n{text}")
    before = files_in(work)
    refused(cli("fit", "--nights", str(nights), "--json", str(work / "fit.json"), "--plot",
                str(work / "fit.png")), nights)
    refused(cli("classify", "--nights", str(nights)), nights)
    assert files_in(work) == before


@pytest.mark.parametrize("name", ["DRIVERS", "NIGHTS"])
def test_every_single_csv_mutation_is_refused(tmp_path, name):
    mutations, check = {"DRIVERS": (DRIVERS_MUTATIONS, _drivers_refused),
                        "NIGHTS": (NIGHTS_MUTATIONS, _nights_refused)}[name]
    assert_all_refused(tmp_path, mutations, check)


_CELL = st.one_of(st.sampled_from(BAD_NUMBERS + BAD_STAMPS),
                  st.floats(allow_nan=True, allow_infinity=True).map(repr),
                  st.integers(-10**9, 10**9).map(str),
                  st.text(st.characters(codec="utf-8", exclude_characters=",\n\r"),
                          max_size=8))


@SETTINGS
@given(st.sampled_from(["DRIVERS", "NIGHTS"]),
       st.lists(st.tuples(st.integers(0, 23), st.integers(0, 5), _CELL), min_size=1,
                max_size=4))
def test_fuzzed_csv_cells_are_refused_cleanly_or_read_as_plausible_numbers(name, edits):
    """Random cells anywhere: an InputError (exit 2, one line, nothing written) or a table
    whose numbers are all finite and physically plausible."""
    from impctl.drivers import read_drivers
    from impctl.imp import read_nights

    base = _drivers_text() if name == "DRIVERS" else _nights_text()
    header, *rows = base.splitlines()
    rows = [r.split(",") for r in rows]
    for i, j, cell in edits:
        rows[i][j % len(rows[i])] = cell
    text = "\n".join([header, *(",".join(r) for r in rows)]) + "\n"
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        path = _write(work / "in.csv", text)
        try:
            if name == "DRIVERS":
                table, dt_s = read_drivers(path, None, "Europe/Ljubljana")
                t_out = table["t_out"].to_numpy(dtype=float)
                setpoint = table["setpoint"].to_numpy(dtype=float)  # NaN: heating off
                assert dt_s > 0 and np.all((t_out >= -60) & (t_out <= 60)), t_out
                on = ~np.isnan(setpoint)
                assert np.all((setpoint[on] >= 5) & (setpoint[on] <= 35)), setpoint
            else:
                for night in read_nights(path, "Europe/Ljubljana"):
                    assert np.all((night.t_air_c >= -40) & (night.t_air_c <= 60))
                    assert np.all((night.t_out_c >= -60) & (night.t_out_c <= 60))
                    assert np.all((night.q_hc_w >= -25_000) & (night.q_hc_w <= 100_000))
        except InputError:
            if name == "DRIVERS":
                _simulate_refused(work, path, _write(work / "house.toml",
                                                     toml_text(GOOD_HOUSE)), path)
            else:
                refused(cli("classify", "--nights", str(path)), path)


# -- register words → store ----------------------------------------------------------------------
class _LiveSimulator:
    """A simulator, a connected client and a store on an event loop in a background thread,
    shared by the examples of one test."""

    def __init__(self, work: Path) -> None:
        from impctl_sim import KronotermSimulator, SimConfig
        from sim_fixtures import hp_config

        from impctl.clock import VirtualClock
        from impctl.heatpump import HeatPumpClient
        from impctl.store import Store

        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        clock = VirtualClock(datetime(2026, 1, 12, 20, tzinfo=UTC), 1000.0)
        self.sim = KronotermSimulator(SimConfig(clock=clock))
        self.call(self.sim.start())
        self.hp = HeatPumpClient(hp_config(self.sim.port, generation="extended"), clock=clock)
        self.call(self.hp.connect(max_wait_s=5.0))
        self.store = Store(work / "impctl.db")
        self.night = self.store.create_night("constrained", 21.0, clock.now(), clock.now())

    def call(self, coro):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(30)

    def close(self) -> None:
        self.hp.close()
        self.call(self.sim.stop())
        self.store.close()
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    sim = _LiveSimulator(tmp_path_factory.mktemp("live"))
    yield sim
    sim.close()


#: Sample field → the register the heat pump serves it from.
TEMPERATURES = {"t_air_c": 2160, "t_out_c": 2103, "t_return_c": 2101, "t_supply_c": 2104,
                "setpoint_c": 2187}


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.sampled_from(sorted(TEMPERATURES)),
       st.one_of(st.integers(0, 0xFFFF), st.sampled_from(
           [0xFDA8, 0xFE70, 0x0000, 0xFE0C, 0x8000, 0x7FFF, 0x05DD, 0xFDA7, 0x05DC])))
def test_sentinel_and_out_of_range_words_never_reach_the_store_as_temperatures(live, field,
                                                                                word):
    """Any 16-bit word in a temperature register, served over Modbus, polled by the client,
    stored as a sample: the stored value is missing (None) or a plausible temperature
    (−60…150 °C) that the word really encodes — never −60.0 from −600, −40.0 from −400, 0.0
    from an absent thermostat, or 3276.7 from a garbage word."""
    from impctl.controller import sample_from_snapshot
    from impctl.modbus import to_int16
    from impctl.store import Sample


    ma = TEMPERATURES[field]
    raw = to_int16(word)

    async def poll():
        live.sim.rw[ma] = raw
        while (await live.sim.read_words(ma)) != [word]:
            await asyncio.sleep(0.005)
        return await live.hp.snapshot()

    snap = live.call(poll())
    sample = sample_from_snapshot(live.night, snap)
    live.store.add_sample(sample)
    stored: Sample = live.store.samples(live.night)[-1]
    value = getattr(stored, field)
    sentinel = raw <= -500 or (field == "t_air_c" and raw in (-400, 0))
    if sentinel or not -600 <= raw <= 1500:
        assert value is None, (field, word, raw, value)
    if value is not None:
        assert -60.0 <= value <= 150.0 and value == pytest.approx(raw / 10), (field, raw, value)
    if ma == 2187:
        live.sim.rw[ma] = 210
    else:
        del live.sim.rw[ma]
