"""The refusal lines say what is true in the file's own words: a duplicated timestamp quoted
as the file writes it (not after conversion to the local zone), sizes and durations rounded
so that they never contradict the limit they are compared with ("25 MB is more than the
25 MB", "3.0 h, under the 3 h minimum"), a file of one-second rows told how to make it one a
minute (the reference's snippet run on such a file), and no double negation ("no valid night
with no usable samples").

Real files, the real ``impctl`` command line (in-process) and a real SQLite store.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_reliability_input import cli, refused

from impctl.errors import InputError
from impctl.fit.nights.data import prepare_nights
from impctl.imp import read_nights
from impctl.store import Sample, Store

DOCS = Path(__file__).resolve().parents[1] / "docs" / "reference" / "nights.md"
HEADER = "timestamp,t_air,t_out,q_hc\n"


def _read_refused(path: Path) -> str:
    try:
        read_nights(path)
    except InputError as exc:
        return str(exc)
    raise AssertionError(f"{path} was read")


def test_a_duplicated_timestamp_is_quoted_as_the_file_writes_it(tmp_path):
    path = tmp_path / "dup.csv"
    path.write_text(HEADER + "2026-01-12T21:00:00Z,21,0,0\n2026-01-12T21:05:00Z,21,0,0\n"
                    "2026-01-12T21:05:00Z,21,0,0\n2026-01-12T21:10:00Z,21,0,0\n")
    assert _read_refused(path) == (
        f"{path}: row 4: timestamps must strictly increase: 1 duplicated timestamp (the "
        "first, 2026-01-12T21:05:00Z, repeats the row before): remove the repeated rows")
    path.write_text(HEADER + "2026-01-12 22:10,21,0,0\n2026-01-12 22:05,21,0,0\n")
    assert _read_refused(path) == (
        f"{path}: row 3: timestamps must strictly increase: the rows are not in time order "
        "(1 step back in time; the first, 2026-01-12 22:05, comes after 2026-01-12 22:10): "
        "sort the rows by timestamp")


def test_a_parquet_frame_quotes_its_timestamps_too(tmp_path):
    """A frame read from Parquet (datetimes or strings): the line quotes the cell it speaks
    of, as the frame holds it."""
    from impctl.imp.files.nights_csv import read_nights_frame

    stamps = pd.to_datetime(["2026-01-12T21:00:00Z", "2026-01-12T21:05:00Z",
                             "2026-01-12T21:05:00Z", "2026-01-12T21:10:00Z"], utc=True)
    frame = pd.DataFrame({"timestamp": stamps, "t_air": 21.0, "t_out": 0.0, "q_hc": 0.0})
    with pytest.raises(InputError) as err:
        read_nights_frame(frame, tmp_path / "h.parquet", "UTC")
    assert "(the first, 2026-01-12 21:05:00+00:00, repeats the row before)" in str(err.value)
    assert "row 4" in str(err.value)
    frame["timestamp"] = ["2026-01-12T22:10Z", "2026-01-12T22:05Z", "2026-01-12T22:15Z",
                          "2026-01-12T22:20Z"]
    with pytest.raises(InputError) as err:
        read_nights_frame(frame, tmp_path / "h.parquet", "UTC")
    assert "the first, 2026-01-12T22:05Z, comes after 2026-01-12T22:10Z" in str(err.value)


def _sized(path: Path, size_bytes: int, step_s: float = 300.0) -> Path:
    """A NIGHTS file of ``size_bytes`` (a sparse tail after a real head of rows
    ``step_s`` apart: the guard looks only at the size and the first rows)."""
    start = datetime(2026, 1, 12, 21, 0, tzinfo=UTC)
    head = HEADER + "".join(f"{(start + timedelta(seconds=i * step_s)).isoformat()},21.0,"
                            "0.0,0.0\n" for i in range(200))
    path.write_text(head)
    with path.open("r+b") as fh:
        fh.truncate(size_bytes)
    return path


def test_sizes_are_rounded_so_that_they_exceed_the_limit(tmp_path):
    (line,) = refused(cli("fit", "--nights", str(p := _sized(tmp_path / "a.csv",
                                                              25_400_000))), p)
    assert "25.4 MB is more than the 25 MB read here" in line, line
    (line,) = refused(cli("fit", "--nights", str(p := _sized(tmp_path / "b.csv",
                                                              25_000_001))), p)
    assert "25,000,001 bytes are more than the 25,000,000 bytes read here" in line, line
    (line,) = refused(cli("fit", "--nights", str(p := _sized(tmp_path / "c.csv",
                                                              31_000_000))), p)
    assert "31 MB is more than the 25 MB read here" in line and "last 60 days" in line, line


def test_a_file_of_one_second_rows_is_told_to_average_them(tmp_path):
    path = _sized(tmp_path / "1s.csv", 26_000_000, step_s=1.0)
    for command in ("fit", "classify"):
        (line,) = refused(cli(command, "--nights", str(path)), path)
        assert ("26 MB is more than the 25 MB read here (about 600,000 rows): its rows are 1 s "
                "apart, finer than the fit uses (5-minute blocks) — average them to one a "
                "minute first, which makes the file about 60 times smaller (pandas: "
                "df.resample('60s', on='timestamp').mean(); docs: NIGHTS files, 'Sampling')"
                ) in line, line


def test_the_references_resampling_snippet_makes_a_one_second_file_readable(tmp_path,
                                                                            monkeypatch):
    stamps = pd.date_range("2026-01-12 21:00", "2026-01-13 05:00", freq="1s",
                           tz="Europe/Ljubljana")
    heating = (stamps.hour >= 21) & (stamps.hour < 22)  # preheat, then off
    rng = np.random.default_rng(3)
    frame = pd.DataFrame({
        "timestamp": stamps.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "t_air": 23.0 - np.arange(len(stamps)) / 3600 * 0.4 + rng.normal(0, 0.05, len(stamps)),
        "t_out": 0.0, "q_hc": np.where(heating, 4000.0, 0.0)})
    frame.to_csv(tmp_path / "NIGHTS.csv", index=False)
    snippet = re.search(r"<!-- resample -->\n```python\n(.*?)```", DOCS.read_text(), re.S)[1]
    monkeypatch.chdir(tmp_path)
    exec(compile(snippet, str(DOCS), "exec"), {})  # noqa: S102 - the documented snippet
    minute = pd.read_csv(tmp_path / "NIGHTS-1min.csv")
    assert len(minute) == len(frame) // 60 + 1
    (night,) = read_nights(tmp_path / "NIGHTS-1min.csv")
    assert night.kind == "constrained" and night.duration_h == 7.0


def test_a_night_just_short_of_the_minimum_is_not_rounded_up_to_it(tmp_path):
    path = tmp_path / "short.csv"
    start = pd.Timestamp("2026-01-12 22:00", tz="Europe/Ljubljana")
    # 0 … 2 h 59 min: 2.98 h, which "%.1f" shows as 3.0
    stamps = [start + pd.Timedelta(seconds=s) for s in np.arange(0, 3 * 3600, 60)]
    pd.DataFrame({"timestamp": [t.isoformat() for t in stamps], "t_air": 22.0, "t_out": 0.0,
                  "q_hc": 2000.0, "night": "n1", "kind": "normal"}).to_csv(path, index=False)
    kept, _, skipped = prepare_nights(read_nights(path))
    assert kept == [] and skipped == [
        ("n1", "normal night covers 2.9 h, under the 3 h minimum")], skipped


def test_nothing_to_export_says_it_plainly(tmp_path):
    db = tmp_path / "impctl.db"
    start = datetime(2026, 1, 12, 21, 0, tzinfo=UTC)
    with Store(db) as store:
        nid = store.create_night("normal", 22.0, start, start + timedelta(hours=7))
        for i in range(5):
            store.add_sample(Sample(nid, start + timedelta(minutes=5 * i), t_air_c=22.0,
                                    t_out_c=0.0, q_hc_w=2000.0))
        store.set_night_state(nid, "done")
        store.assess_night(nid, False, ["too short"])
    out = tmp_path / "n.csv"
    code, _, err = cli("export", "--db", str(db), "--out", str(out))
    assert code == 2 and not out.exists()
    assert err.strip() == (f"impctl: {db}: nothing to export: no valid night in the store "
                           "has a usable sample (see impctl nights)"), err
