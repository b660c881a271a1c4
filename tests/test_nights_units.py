"""NIGHTS files that read as a house but are not one, or are no NIGHTS table at all: °F
temperatures, Home Assistant's long history export, and a q_hc that is the heat pump's
electrical power. Each is refused in one line naming the likely cause (exit 2, nothing
written); the Home Assistant export turns into a NIGHTS file with the snippet the reference
shows.

Real files: the simulated nights of ``operator_fixtures`` written as NIGHTS.csv, the real
``impctl`` command line (in-process, as ``test_operator_data``).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pandas as pd
from operator_fixtures import fit_refused, nights, nights_csv
from test_reliability_input import cli, refused

from impctl.imp import read_nights

DOCS = Path(__file__).resolve().parents[1] / "docs" / "reference" / "nights.md"
__all__ = ["nights", "nights_csv"]  # module-scoped fixtures


def _fahrenheit(src: Path, dst: Path, columns=("t_air", "t_out", "setpoint")) -> Path:
    frame = pd.read_csv(src)
    for col in columns:
        frame[col] = frame[col] * 1.8 + 32.0
    frame.to_csv(dst, index=False, float_format="%.3f")
    return dst


def test_a_file_in_fahrenheit_says_so(tmp_path, nights_csv):
    """The issue: '86 outside −40…60 °C' for a file in °F; the line names the unit (also for
    a file whose rooms stay inside −40…60, e.g. at 55 °F)."""
    path = _fahrenheit(nights_csv, tmp_path / "f.csv")
    median = pd.read_csv(path)["t_air"].median()
    (line,) = fit_refused(tmp_path, path)
    assert line == (f"impctl: {path}: column 't_air': the room temperatures look like °F "
                    f"(median {median:.1f}: {(median - 32) / 1.8:.1f} °C if it is °F; no "
                    f"heated room is at {median:.0f} °C): NIGHTS files hold °C — convert "
                    "t_air, t_out and setpoint with (°F − 32) / 1.8")
    (line,) = refused(cli("classify", "--nights", str(path)), path)
    assert "look like °F" in line
    cool = pd.read_csv(path)
    cool["t_air"] = cool["t_air"] - cool["t_air"].max() + 59.0  # every room under 60 (°F)
    cool.to_csv(path, index=False)
    (line,) = fit_refused(tmp_path, path)
    assert "column 't_air': the room temperatures look like °F" in line


def test_a_setpoint_column_in_fahrenheit_says_so(tmp_path, nights_csv):
    path = _fahrenheit(nights_csv, tmp_path / "sp.csv", columns=("setpoint",))
    (line,) = fit_refused(tmp_path, path)
    assert re.search(r"column 'setpoint': [\d.]+ is outside 5…35 °C — looks like °F "
                     r"\([\d.]+ °C\): convert with \(°F − 32\) / 1\.8$", line), line


def test_q_hc_that_is_electrical_power_is_refused_where_p_el_is_given(tmp_path, nights_csv):
    """The issue: a COP-3 heat pump's electricity as q_hc gave HLC 48 instead of 131 W/K,
    silently. With the heat pump's electrical power beside it, q_hc ≈ p_el_w tells."""
    frame = pd.read_csv(nights_csv)
    frame["p_el_w"] = frame["q_hc"] / 3.0   # a heat pump at COP 3
    honest = tmp_path / "honest.csv"
    frame.to_csv(honest, index=False)
    assert len(read_nights(honest)) == 5    # heat beside its electricity: read as usual
    frame["q_hc"] = frame["p_el_w"]         # the electricity given as the heat
    wrong = tmp_path / "electric.csv"
    frame.to_csv(wrong, index=False)
    (line,) = fit_refused(tmp_path, wrong)
    running = int(((frame["p_el_w"] >= 200) & (frame["q_hc"] > 100)).sum())
    assert line == (f"impctl: {wrong}: column 'q_hc': q_hc looks like electrical power, not "
                    f"heat: on the {running} rows where p_el_w shows the heat pump running, "
                    "q_hc is 1.00 × p_el_w in the median (a heat pump delivers 2–5 times the "
                    "electricity it uses) — give the thermal heat output in W (a heat meter; "
                    "Kronoterm register 2329)")


ENTITIES = {"t_air": "sensor.living_room_temperature", "t_out": "sensor.outdoor_temperature",
            "q_hc": "sensor.heat_pump_heat_power"}


def _home_assistant_history(src: Path, dst: Path) -> Path:
    """The nights as Home Assistant's history export writes them: one row per entity and
    state change, times in UTC, an 'unavailable' now and then."""
    frame = pd.read_csv(src)
    stamps = pd.to_datetime(frame["timestamp"], format="ISO8601", utc=True)
    rows = []
    for col, entity in ENTITIES.items():
        for i, (t, v) in enumerate(zip(stamps, frame[col], strict=True)):
            # each sensor reports a few seconds apart from the others, as real ones do
            t = t + pd.Timedelta(seconds=7 * list(ENTITIES).index(col))
            rows.append((entity, "unavailable" if i % 97 == 50 else f"{v:.2f}",
                         t.isoformat().replace("+00:00", "Z")))
    rows.sort(key=lambda r: r[2])
    pd.DataFrame(rows, columns=["entity_id", "state", "last_changed"]).to_csv(dst, index=False)
    return dst


def test_a_home_assistant_history_export_is_recognised_and_pivots(tmp_path, nights_csv,
                                                                   monkeypatch):
    history = _home_assistant_history(nights_csv, tmp_path / "history.csv")
    (line,) = fit_refused(tmp_path, history)
    assert line == (
        f"impctl: {history}: row 1: a Home Assistant history export (one row per entity and "
        "change: entity_id,state,last_changed; entities sensor.living_room_temperature, "
        "sensor.outdoor_temperature, sensor.heat_pump_heat_power): NIGHTS needs one row per "
        "time with the columns timestamp,t_air,t_out,q_hc — pivot it first, naming which "
        "entity is which column (docs: NIGHTS files, 'From Home Assistant's history')")
    # The reference's snippet, as a reader would paste it, makes a NIGHTS file of it.
    snippet = re.search(r"<!-- pivot -->\n```python\n(.*?)```", DOCS.read_text(), re.S)[1]
    monkeypatch.chdir(tmp_path)
    exec(compile(snippet, str(DOCS), "exec"), {})  # noqa: S102 - the documented snippet
    assert os.path.exists("NIGHTS.csv")
    pivoted = read_nights(tmp_path / "NIGHTS.csv")
    original = read_nights(nights_csv)
    assert [n.kind for n in pivoted] == [n.kind for n in original]
    assert [n.start for n in pivoted] == [n.start for n in original]
