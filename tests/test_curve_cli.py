"""``impctl curve`` end to end, as a real subprocess, on rows the realistic plant recorded."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from impctl.curve.synth import owner_rows
from impctl.model import default_house
from impctl.plant import HeatPump, PlantParams


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "from impctl.cli import main; main()", *args],
                          capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def nights_csv(tmp_path_factory) -> Path:
    rows, _ = owner_rows(default_house(), PlantParams(heat_pump=HeatPump(curve_gain=1.3)), 12,
                         seed=5)
    path = tmp_path_factory.mktemp("curve") / "nights.csv"
    rows.to_csv(path, index=False)
    return path


def test_curve_says_what_to_set_and_writes_json_and_plot(tmp_path, nights_csv):
    out, png = tmp_path / "curve.json", tmp_path / "curve.png"
    res = run_cli("curve", "--nights", str(nights_csv), "--json", str(out), "--plot", str(png))
    assert res.returncode == 0, res.stderr
    first = res.stdout.splitlines()[0]
    assert "hotter than this house needs at 0 °C" in first and "kWh" in first
    assert "HLC" not in res.stdout  # words an owner reads
    data = json.loads(out.read_text())
    assert data["schema"] == "impctl-curve/1"
    assert data["lowers"] is True
    assert data["recommended"]["flow_at_0_c"] < data["running"]["flow_at_0_c"]
    assert data["savings"]["saving_kwh"]["value"] > 0
    assert data["setpoint_c"] == {"value": 21.0, "source": "the owner's nights"}
    assert data["savings"]["climate"]["source"] == "assumed"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_nights_without_water_temperatures_are_refused_in_one_line(tmp_path, nights_csv):
    lines = nights_csv.read_text().splitlines()
    head = lines[0].split(",")
    keep = [i for i, c in enumerate(head) if c not in ("t_flow_c", "t_return_c")]
    bare = tmp_path / "bare.csv"
    bare.write_text("\n".join(",".join(r.split(",")[i] for i in keep) for r in lines) + "\n")
    out = tmp_path / "curve.json"
    res = run_cli("curve", "--nights", str(bare), "--json", str(out))
    assert res.returncode == 2
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and str(bare) in err[0] and "t_flow_c, t_return_c" in err[0]
    assert not out.exists()


def test_bad_options_and_outputs_are_refused(tmp_path, nights_csv):
    res = run_cli("curve", "--nights", str(nights_csv), "--margin-k", "9")
    assert res.returncode == 2 and "--margin-k" in res.stderr
    res = run_cli("curve", "--nights", str(nights_csv), "--json", str(nights_csv))
    assert res.returncode == 2 and "would overwrite the NIGHTS file" in res.stderr
    missing = tmp_path / "none.csv"
    res = run_cli("curve", "--nights", str(missing))
    assert res.returncode == 2 and "file not found" in res.stderr
    fit = tmp_path / "fit.json"
    fit.write_text("[1, 2]")
    res = run_cli("curve", "--nights", str(nights_csv), "--fit", str(fit))
    assert res.returncode == 2 and "expected a JSON object" in res.stderr
