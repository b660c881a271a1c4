"""``impctl curve`` end to end (run in this process), on rows the realistic plant recorded."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from cli_fixtures import run_impctl

from impctl.curve.data.synth import owner_rows
from impctl.model import default_house
from impctl.plant import HeatPump, PlantParams


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return run_impctl(*args)  # in this process: the tests check the output, not the process


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


FIT = {"schema": "impctl-fit/1",
       "lumped": {"hlc": {"value": 200.0, "low": 175.0, "high": 230.0},
                  "c_m": {"value": 2.0e7}, "tau": {"value": 28.0}},
       "parameters": {"u_walls": 0.5}}


def test_the_daemon_keeps_the_curve_after_a_fit_and_keeps_the_last_one(tmp_path, nights_csv,
                                                                       caplog):
    """The fit's subprocess chain runs the real ``impctl curve``; its result becomes
    ``<state_dir>/curve.json``, the daemon's plain-number reader takes it; nights without
    flow and return temperatures give no new curve, one log line, and the last one stays."""
    import asyncio
    import logging

    from impctl.config import load_config
    from impctl.daemon.curve.state import load_curve, suggested_flow_c
    from impctl.daemon.fitting import _curve

    state = tmp_path / "state"
    state.mkdir()
    config = tmp_path / "config.toml"
    config.write_text(f'state_dir = "{state}"\n[heatpump]\nhost = "127.0.0.1"\n'
                      "[curve]\nmargin_k = 1.5\n")
    cfg = load_config(config)
    fit_json = tmp_path / "fit.json"
    fit_json.write_text(json.dumps(FIT))
    base = [sys.executable, "-c", "from impctl.cli import main; main()"]
    asyncio.run(_curve(cfg, base, nights_csv, fit_json, tmp_path))
    kept = load_curve(state)
    assert kept is not None and kept["margin_k"] == 1.5
    assert kept["heat_need"]["hlc_w_per_k"]["source"].startswith("fit")
    flow = suggested_flow_c(kept, 0.0)
    assert flow == pytest.approx(kept["recommended"]["flow_at_0_c"], abs=0.05)
    lines = nights_csv.read_text().splitlines()
    head = lines[0].split(",")
    keep = [i for i, c in enumerate(head) if c not in ("t_flow_c", "t_return_c")]
    bare = tmp_path / "bare.csv"
    bare.write_text("\n".join(",".join(r.split(",")[i] for i in keep) for r in lines) + "\n")
    with caplog.at_level(logging.INFO, logger="impctl.daemon"):
        asyncio.run(_curve(cfg, base, bare, fit_json, tmp_path))
    assert "no heating curve from these nights" in caplog.text
    assert "t_flow_c, t_return_c" in caplog.text
    assert load_curve(state) == kept


def test_the_curve_section_is_checked_with_every_problem_at_once(tmp_path):
    from impctl.config import load_config
    from impctl.errors import InputError

    config = tmp_path / "config.toml"
    config.write_text('[heatpump]\nhost = "127.0.0.1"\n'
                      '[curve]\napply = "yes"\nraise_k = 9.0\nshort_h = 0.0\nmargin = 1\n')
    with pytest.raises(InputError) as err:
        load_config(config)
    lines = str(err.value).splitlines()
    assert any("curve.apply" in ln and "true or false" in ln for ln in lines)
    assert any("curve.raise_k" in ln and "[0.5, 3]" in ln for ln in lines)
    assert any("curve.short_h" in ln for ln in lines)
    assert any("curve.margin" in ln and "unknown key" in ln for ln in lines)


def test_the_owners_word_is_readable_by_the_daemons_user(tmp_path):
    """``impctl curve --apply`` runs as root, the daemon as its own user: the word it leaves
    (and the kept curve) must be readable by others, not mkstemp's 0600."""
    import stat

    from impctl.daemon.curve.intent import intent, set_intent
    from impctl.daemon.curve.state import keep_curve

    path = set_intent(tmp_path, True, "test")
    assert stat.S_IMODE(path.stat().st_mode) == 0o644 and intent(tmp_path) is True
    src = tmp_path / "fresh.json"
    src.write_text("{}")
    keep_curve(tmp_path, src)
    assert stat.S_IMODE((tmp_path / "curve.json").stat().st_mode) == 0o644
