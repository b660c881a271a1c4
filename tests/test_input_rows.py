"""Bad input to the analysis commands, as a careless operator gives it: the ``[plant.*]``
tables of a house file for ``impctl simulate``, NaN and infinities for ``impctl flex`` and
``impctl demo``, and NIGHTS files from a spreadsheet in a European locale, with repeated or
unsorted rows. Each is one line naming the file (or option) and the likely cause, exit 2.

The CLI runs as a real subprocess.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from cli_fixtures import run_impctl

from impctl.errors import InputError
from impctl.imp import read_nights

HOUSE = """\
floor_area = 120.0
wall_height = 2.5
walls_area = 150.0
windows_area = 24.0
c_f = 2.6
u_walls = 0.4
u_windows = 1.2
ach_vent = 0.0
ach_infl = 0.3
"""


def _one_line(result, prefix: str) -> str:
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(prefix), result.stderr
    return lines[0][len(prefix):]


# -- impctl simulate --house with [plant.*] tables ------------------------------------------------
@pytest.mark.parametrize("table, expected", [
    ("[plant.emitter]\ndesign_water_c = nan\n",
     "key 'plant.emitter.design_water_c': must be a finite number"),
    ("[plant.emitter]\ncolour = 3\n",
     "key 'plant.emitter.colour': unknown key (expected: kind, exponent, design_water_c"),
    ("[plant.heat_pump]\nmin_modulation = 7.0\n",
     "key 'plant.heat_pump.min_modulation': must lie in"),
    ("[plant.garden]\nroses = 3\n", "key 'plant.garden': unknown section"),
])
def test_simulate_checks_the_plant_tables(tmp_path, table, expected):
    house = tmp_path / "house.toml"
    house.write_text(HOUSE + table)
    result = run_impctl("simulate", "--house", str(house), "--days", "1")
    assert _one_line(result, f"impctl: {house}: ").startswith(expected)


def test_simulate_says_good_plant_tables_are_not_used(tmp_path):
    house = tmp_path / "house.toml"
    house.write_text(HOUSE + "[plant.emitter]\ndesign_water_c = 40.0\n")
    result = run_impctl("simulate", "--house", str(house), "--days", "1")
    assert result.returncode == 0, result.stderr
    assert result.stderr.strip() == (
        f"note: {house}: [plant.emitter] checked but not used: impctl simulate runs the ideal "
        "5R1C model (impctl demo --house runs the realistic plant)")
    assert "heat delivered" in result.stdout


# -- NaN and infinities on the command line ---------------------------------------------------
@pytest.mark.parametrize("args, expected", [
    (("flex", "fit.json", "--t-out", "-inf"), "--t-out: must be a finite number, got -inf"),
    (("flex", "fit.json", "--t-set", "nan"), "--t-set: must be a finite number, got nan"),
    (("flex", "fit.json", "--drop", "inf"), "--drop: must be a finite number, got inf"),
    (("flex", "fit.json", "--t-out", "1e9"),
     "--t-out: 1000000000 °C is outside the plausible range [-50, 40] °C"),
    (("flex", "fit.json", "--drop", "0"), "--drop: 0 K is outside the plausible range (0, 10] K"),
    (("demo", "--speed", "nan"), "--speed: must lie in (0, 30000]"),
])
def test_non_finite_options_are_one_line(args, expected):
    result = run_impctl(*args)
    assert _one_line(result, "impctl: ").startswith(expected)


# -- NIGHTS files from spreadsheets --------------------------------------------------------------
ROWS = [("2026-01-12T22:00:00+01:00", "21.3", "4.5", "1500"),
        ("2026-01-12T22:05:00+01:00", "21.2", "4.5", "1400"),
        ("2026-01-12T22:10:00+01:00", "21.1", "4.4", "1300"),
        ("2026-01-12T22:15:00+01:00", "21.0", "4.4", "1200")]
HEADER = ("timestamp", "t_air", "t_out", "q_hc")


def _csv(path: Path, rows, sep: str = ",", decimal: str = ".") -> Path:
    lines = [sep.join(HEADER)] + [sep.join(c.replace(".", decimal) if i else c
                                           for i, c in enumerate(r)) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def _problem(path: Path) -> str:
    with pytest.raises(InputError) as err:
        read_nights(path)
    assert err.value.source == str(path)
    return f"{err.value.place}: {err.value.problem}"


def test_a_clean_file_reads(tmp_path):
    (night,) = read_nights(_csv(tmp_path / "ok.csv", ROWS))
    assert len(night.time_s) == 4


def test_semicolon_separator_is_named(tmp_path):
    path = _csv(tmp_path / "semi.csv", ROWS, sep=";")
    assert _problem(path) == (
        "row 1: separator ';' detected (header 'timestamp;t_air;t_out;q_hc'): NIGHTS.csv needs "
        "',' between fields (export the sheet as CSV with ',' as the field separator)")


def test_semicolons_and_decimal_commas_are_named(tmp_path):
    path = _csv(tmp_path / "eu.csv", ROWS, sep=";", decimal=",")
    assert _problem(path) == (
        "row 1: separator ';' and decimal commas detected (header 'timestamp;t_air;t_out;"
        "q_hc'; e.g. '21,3' in row 2): NIGHTS.csv needs ',' between fields and '.' as the "
        "decimal mark (export the sheet as CSV with those settings)")


def test_tab_separator_is_named(tmp_path):
    path = _csv(tmp_path / "tab.csv", ROWS, sep="\t")
    assert _problem(path).startswith("row 1: separator tab detected")


def test_decimal_commas_with_comma_separators_are_named(tmp_path):
    path = _csv(tmp_path / "dc.csv", ROWS, decimal=",")
    assert _problem(path) == ("row 2: 6 cells where the header has 4: decimal commas "
                              "detected, e.g. '21,3'; write numbers with '.' as the decimal mark")
    quoted = tmp_path / "quoted.csv"
    quoted.write_text("timestamp,t_air,t_out,q_hc\n2026-01-12T22:00:00+01:00,21.3,4.5,1500\n"
                      '2026-01-12T22:05:00+01:00,"21,2",4.5,1400\n')
    assert _problem(quoted) == ("row 3: decimal comma detected ('21,2'): write numbers with "
                                "'.' as the decimal mark")


def test_duplicated_rows_are_counted(tmp_path):
    path = _csv(tmp_path / "dup.csv", [ROWS[0], ROWS[1], ROWS[1], ROWS[2], ROWS[2], ROWS[3]])
    assert _problem(path) == (
        "row 4: timestamps must strictly increase: 2 duplicated timestamps (the first, "
        "2026-01-12T22:05:00+01:00, repeats the row before): remove the repeated rows")


def test_unsorted_rows_say_sort(tmp_path):
    path = _csv(tmp_path / "unsorted.csv", [ROWS[0], ROWS[2], ROWS[1], ROWS[3]])
    assert _problem(path) == (
        "row 4: timestamps must strictly increase: the rows are not in time order (1 step back "
        "in time; the first, 2026-01-12T22:05:00+01:00, comes after 2026-01-12T22:10:00+01:00):"
        " sort the rows by timestamp")


def test_the_cli_prints_the_cause_in_one_line(tmp_path):
    path = _csv(tmp_path / "eu.csv", ROWS, sep=";", decimal=",")
    result = run_impctl("fit", "--nights", str(path))
    assert _one_line(result, f"impctl: {path}: row 1: ").startswith(
        "separator ';' and decimal commas detected")


@pytest.mark.parametrize("odd", [None, "1_000", "0x10", "five"])
def test_numbers_read_as_to_numeric_reads_them_in_every_spelling(odd):
    """The fast read of number cells gives what ``pd.to_numeric`` gives, bit for bit — empty
    cells and text NaN, signs, exponents, leading zeros and the last digit's rounding — and a
    cell it cannot read sends the column through ``to_numeric`` itself."""
    import numpy as np
    import pandas as pd

    from impctl.imp.tables import text_floats

    cells = ["21.5", "+5", "5.", ".5", "1e3", "-2.5E-1", "00012", "-0", "", "nan", "inf",
             "0.1", "0.30000000000000004", "1.000000000000000000001", "123456789.123456789",
             "-40.0625", "1e400"]
    if odd is not None:
        cells.append(odd)
    text = pd.Series(cells, dtype=str)
    got = text_floats(text)
    want = pd.to_numeric(text.where(text != "", None), errors="coerce").to_numpy(
        dtype=float, na_value=np.nan)
    assert got.dtype == np.float64 and got.tobytes() == want.tobytes()
    assert got[cells.index("0.1")] == 0.1 and np.isnan(got[cells.index("")])


def test_a_row_cut_short_is_named_and_an_empty_last_cell_is_not_one(tmp_path):
    """A row with fewer cells than the header (a logger that lost power mid-line) is refused
    with its own row number, also after a blank line; a row whose last cell is empty has all
    its cells and is refused for the empty number instead."""
    lines = [",".join(HEADER)] + [",".join(r) for r in ROWS]
    cut = tmp_path / "cut.csv"
    cut.write_text("\n".join(lines[:3] + ["", "2026-01-12T22:10:00+01:00,21.1,4.4"]
                             + lines[4:]) + "\n")
    assert _problem(cut) == "row 5: 3 cells where the header has 4"
    # the same with Windows line ends, and with a quoted cell (read by the csv module)
    cut.write_bytes(cut.read_bytes().replace(b"\n", b"\r\n"))
    assert _problem(cut) == "row 5: 3 cells where the header has 4"
    cut.write_text(cut.read_text().replace("\r\n", "\n").replace(",21.3,", ',"21.3",'))
    assert _problem(cut) == "row 5: 3 cells where the header has 4"
    empty = tmp_path / "empty.csv"
    empty.write_text("\n".join(lines[:3] + ["2026-01-12T22:10:00+01:00,21.1,4.4,"]
                               + lines[4:]) + "\n")
    assert _problem(empty) == "row 4: column 'q_hc': empty cell"
