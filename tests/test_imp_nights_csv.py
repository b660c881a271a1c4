"""NIGHTS.csv: reading labelled and unlabelled nights, and refusing bad files clearly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from impctl.errors import InputError
from impctl.imp import night_features, read_nights, write_nights

TZ = "Europe/Ljubljana"


def _log(start: str, hours: float, step_min: int = 10) -> pd.DataFrame:
    """A continuous log: heating off 22:00–05:00 on the first night, on otherwise."""
    stamps = pd.date_range(start, periods=int(hours * 60 / step_min), freq=f"{step_min}min",
                           tz=TZ)
    n = len(stamps)
    local_hour = stamps.hour
    first_night = (stamps >= pd.Timestamp(start, tz=TZ).normalize() + pd.Timedelta(hours=22)) & (
        stamps <= pd.Timestamp(start, tz=TZ).normalize() + pd.Timedelta(hours=29))
    heating = np.where(first_night, 0, 1)
    return pd.DataFrame({
        "timestamp": [t.isoformat() for t in stamps],
        "t_air": np.where(heating == 1, 22.0, 23.0 - 0.01 * np.arange(n)),
        "t_out": 1.0 - 0.1 * (local_hour % 7),
        "q_hc": np.where(heating == 1, 3000.0, 0.0),
        "heating": heating,
    })


def test_unlabelled_log_is_cut_into_windows_and_kinds_inferred(tmp_path):
    path = tmp_path / "log.csv"
    _log("2026-01-12 20:00", 34).to_csv(path, index=False)     # until 06:00 on the 14th
    nights = read_nights(path, TZ)
    assert [n.night_id for n in nights] == ["2026-01-12", "2026-01-13"]
    assert [n.kind for n in nights] == ["constrained", "normal"]
    first = nights[0]
    assert first.start == pd.Timestamp("2026-01-12 22:00", tz=TZ)
    assert first.time_s[0] == 0.0 and first.time_s[-1] == 7 * 3600.0   # end inclusive
    assert len(first.time_s) == 43


def test_kind_inferred_from_heat_output_without_heating_column(tmp_path):
    path = tmp_path / "log.csv"
    _log("2026-01-12 20:00", 34).drop(columns="heating").to_csv(path, index=False)
    assert [n.kind for n in read_nights(path, TZ)] == ["constrained", "normal"]


def test_window_across_dst_change_is_six_hours(tmp_path):
    stamps = pd.date_range("2026-03-28 21:00", "2026-03-29 06:00", freq="30min", tz=TZ)
    df = pd.DataFrame({"timestamp": [t.isoformat() for t in stamps], "t_air": 22.0,
                       "t_out": 3.0, "q_hc": 2000.0})
    path = tmp_path / "dst.csv"
    df.to_csv(path, index=False)
    (night,) = read_nights(path, TZ)
    assert night.duration_h == 6.0 and night.kind == "normal"


def test_write_then_read_gives_the_same_nights_and_features(tmp_path):
    from impctl.population import ImpSimConfig, sample_households, simulate_imp

    cfg = ImpSimConfig(days=2)
    result = simulate_imp(sample_households(1, seed=5), config=cfg, seed=5)
    nights = result.nights_of(0)
    back = read_nights(write_nights(nights, tmp_path / "n.csv"), TZ)
    assert len(back) == len(nights) == 2 * len(cfg.plans())
    by_id = {n.night_id: n for n in back}
    for night in nights:
        got = by_id[night.night_id]
        assert got.kind == night.kind and got.start == night.start
        np.testing.assert_allclose(got.time_s, night.time_s)
        assert night_features(got) == pytest.approx(night_features(night), rel=1e-5,
                                                    nan_ok=True)


def test_a_parquet_frame_reads_its_text_cells_as_the_csv_does(tmp_path):
    """Night ids as numbers, padded kinds and labels, null labels (pandas' string type keeps
    them NaN): the Parquet frame gives the nights the CSV gives."""
    from impctl.imp.files.nights_csv import read_nights_frame

    stamps = pd.date_range("2026-01-12 22:00", periods=12, freq="10min", tz=TZ)
    frame = pd.DataFrame({
        "timestamp": stamps, "t_air": 22.0 - 0.05 * np.arange(12), "t_out": 1.0,
        "q_hc": 0.0, "heating": 0,
        "night": [7] * 6 + [8] * 6,
        "kind": ["owner "] * 6 + [" owner"] * 6,
        "label": pd.array([None] * 6 + [" dhw"] * 6, dtype="str"),
    })
    frame.to_parquet(tmp_path / "n.parquet")
    csv = tmp_path / "n.csv"
    frame.assign(timestamp=[t.isoformat() for t in stamps]).to_csv(csv, index=False)
    read = pd.read_parquet(tmp_path / "n.parquet")
    assert read["label"].isna().sum() == 6
    got, want = read_nights_frame(read, tmp_path / "n.parquet", TZ), read_nights(csv, TZ)
    assert [(n.night_id, n.kind, n.label) for n in got] == [
        (n.night_id, n.kind, n.label) for n in want] == [("7", "owner", ""),
                                                         ("8", "owner", "dhw")]


def test_a_parquet_frame_reads_its_optional_numbers_as_the_csv_does(tmp_path):
    """The optional numeric columns stored as numbers (defrost as integers, the household
    electricity and the rooms as floats, with a null, an infinity and a value out of range):
    the Parquet frame's nights carry what the CSV's carry, bit for bit."""
    from impctl.fleet.results.previous import nights_digest
    from impctl.imp.files.nights_csv import read_nights_frame

    stamps = pd.date_range("2026-01-12 22:00", periods=12, freq="10min", tz=TZ)
    frame = pd.DataFrame({
        "timestamp": stamps, "t_air": 22.0 - 0.05 * np.arange(12), "t_out": 1.0,
        "q_hc": [0.0] * 6 + [2000.0] * 6, "night": ["a"] * 6 + ["b"] * 6, "kind": "owner",
        "defrost": [0, 0, 1, 0, 0, 0] * 2,
        "p_house_w": [np.nan, np.inf, 4e4] + [310.0 + 0.1 * i for i in range(9)],
        "t_rooms_c": np.linspace(21.3, 20.1, 12),
    })
    frame.to_parquet(tmp_path / "n.parquet")
    csv = tmp_path / "n.csv"
    frame.assign(timestamp=[t.isoformat() for t in stamps]).to_csv(csv, index=False)
    read = pd.read_parquet(tmp_path / "n.parquet")
    assert read["defrost"].dtype == np.int64 and read["p_house_w"].dtype == np.float64
    got, want = read_nights_frame(read, tmp_path / "n.parquet", TZ), read_nights(csv, TZ)
    assert got[1].p_house_w == pytest.approx(310.55) and got[0].defrost_h > 0
    assert got[0].t_air_offset_k == pytest.approx(0.85, abs=0.01)
    assert [nights_digest([n]) for n in got] == [nights_digest([n]) for n in want]


GOOD = ("timestamp,t_air,t_out,q_hc\n2026-01-12T22:00,22.0,1.0,2000\n"
        "2026-01-12T22:10,22.0,1.0,2100\n")


@pytest.mark.parametrize("text, words", [
    ("", "file is empty"),
    ("timestamp,t_air,t_out\n2026-01-12T22:00,22,1\n", "missing column 'q_hc'"),
    (GOOD + "2026-01-12T22:20,22.0,abc,2000\n", "row 4: column 't_out': 'abc' is not"),
    (GOOD + "2026-01-12T22:20,,1.0,2000\n", "row 4: column 't_air': empty cell"),
    (GOOD + "2026-01-12T22:10,22.0,1.0,2000\n", "row 4: timestamps must strictly increase"),
    (GOOD + "2026-01-12T22:20,2150,1.0,2000\n", "row 4: column 't_air': 2150 is outside"),
    (GOOD + "2026-01-12T22:20,22,1.0,-30000\n", "row 4: column 'q_hc': -30000 is outside"),
    (GOOD + "yesterday,22,1.0,300\n", "row 4: cannot parse timestamp"),
    ("timestamp,t_air,t_out,q_hc,heating\n2026-01-12T22:00,22,1,0,2\n", "row 2: column 'heating'"),
    ("timestamp,t_air,t_out,q_hc,kind\n2026-01-12T22:00,22,1,0,cold\n", "row 2: column 'kind'"),
    ("timestamp,t_air,t_out,q_hc,night,kind\n2026-01-12T22:00,22,1,0,a,normal\n"
     "2026-01-12T22:10,22,1,0,a,constrained\n", "row 3: night 'a' changes kind"),
    ("timestamp,t_air,t_out,q_hc,night\n2026-01-12T22:00,22,1,0,a\n2026-01-12T22:10,22,1,0,b\n"
     "2026-01-12T22:20,22,1,0,a\n", "row 4: night 'a' is split"),
    ("timestamp,t_air,t_out,q_hc,night\n2026-01-12T22:00,22,1,0,a\n", "night 'a' has only one"),
    ("timestamp,t_air,t_out,q_hc\n2026-01-12T12:00,22,1,0\n2026-01-12T13:00,22,1,0\n",
     "no two samples inside one 22:00–05:00 window"),
])
def test_bad_files_give_one_line_naming_file_and_row(tmp_path, text, words):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(InputError) as err:
        read_nights(path, TZ)
    line = str(err.value)
    assert "\n" not in line and str(path) in line and words in line


def test_missing_file_is_named(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_nights(Path(tmp_path / "nope.csv"))


@pytest.mark.parametrize("signed", [False, True])
def test_defrost_column_gives_each_night_its_defrost_hours_and_those_not_read(tmp_path, signed):
    """10-min rows, three of them defrosting: read at 0 W the draw was not read (all three
    hours count as unread); with one row at −900 W the reading is signed (none unread: the
    other rows are means over defrost and heating). A night whose defrost cells are mostly
    unreadable has no defrost figures (NaN), never a number."""
    log = _log("2026-01-12T12:00", 48)
    night2 = pd.to_datetime(log["timestamp"]) >= pd.Timestamp("2026-01-13T12:00", tz=TZ)
    held2 = night2 & (pd.to_datetime(log["timestamp"]).dt.hour == 23)
    rows = np.flatnonzero(held2)[:3]
    log["defrost"] = "0"
    log.loc[rows, "defrost"] = "1"
    log.loc[rows, "q_hc"] = 0.0
    if signed:
        log.loc[rows[2], "q_hc"] = -900.0
    log.loc[~night2, "defrost"] = "x"   # the first day's cells unreadable: missing
    path = tmp_path / "nights.csv"
    log.to_csv(path, index=False)
    first, second = read_nights(path, tz=TZ)
    assert np.isnan(first.defrost_h) and np.isnan(first.defrost_unread_h)
    assert second.kind == "normal"
    assert second.defrost_h == pytest.approx(0.5)
    assert second.defrost_unread_h == (0.0 if signed else pytest.approx(0.5))
