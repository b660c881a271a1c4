"""A shortened ``impctl demo`` end to end, and ``impctl report`` on its store."""

from __future__ import annotations

import html
import json
import subprocess
import sys

import pytest
from cli_fixtures import run_impctl


def run_cli(*args: str, timeout: float = 1200) -> subprocess.CompletedProcess:
    """The demo in its own process (it starts and stops the simulator and the daemon);
    refused options and ``impctl report`` run in this process (run_impctl)."""
    # a guard against a hang, not an expectation: a busy two-core machine runs the demo
    # many times slower than a quiet one
    return subprocess.run([sys.executable, "-c", "from impctl.cli import main; main()", *args],
                          capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    # The ideal plant: the accuracy asserted below is the fit's on its own model (the
    # realistic default is test_demo_realistic_plant_is_the_default).
    proc = run_cli("demo", "--nights", "1+2", "--households", "40", "--speed", "20000",
                   "--out", str(out), "--model-dir", str(out / "models"), "--plant", "iso",
                   "--owner-days", "1+1")
    return out, proc


def test_short_demo_runs_end_to_end(demo):
    out, proc = demo
    assert proc.returncode == 0, proc.stderr[-3000:]
    text = proc.stdout
    # Progress was visible, the heat pump was restored, the table was printed.
    assert "nights" in text and "classifiers:" in text
    # The classifiers were trained for the plant the demo simulates, and say so.
    assert "virtual households of the iso plant" in text
    models = json.loads((out / "models" / "models.json").read_text())
    assert models["dataset"]["plant"] == "iso"
    assert "simulator loop-1 setpoint back at 21.0 °C, mode 1" in text
    for word in ("Parameters (the paper's Table IV)", "hlc", "c_m", "tau", "ε =", "Wall time"):
        assert word in text
    summary = json.loads((out / "summary.json").read_text())
    lumped = {q["name"]: q for q in summary["lumped"]}
    # The lumped quantities are what the nights determine; even a 1+2-night campaign with
    # 40-household classifiers recovers the demo house's HLC to a few per cent (τ and C_m
    # need more constrained nights: the README's accuracy table is for 2+6).
    assert abs(lumped["hlc"]["error_pct"]) < 5.0
    assert abs(lumped["tau"]["error_pct"]) < 25.0
    assert summary["heat_demand"]["out_of_sample"] is True
    # The fixed 1 + 2 campaign: three valid nights (and any invalid ones before them).
    assert summary["nights_valid"] == 3 and summary["nights_run"] >= 3
    assert summary["campaign"]["mode"] == "fixed" and "Campaign: fixed 1 + 2" in text
    # The owner's own days around and between the nights: recorded read-only, exported as
    # kind owner (a day before the campaign, a day after, the days between its nights), and
    # left out of this fit with the reason.
    owner = summary["owner"]
    assert owner["records"] >= 4 and owner["rows"] >= 3 * 96, owner
    assert "Owner days: " in text and "in nights.csv as kind owner" in text
    import pandas as pd

    exported = pd.read_csv(out / "nights.csv", keep_default_na=False)
    kinds = exported.drop_duplicates("night")["kind"].tolist()
    assert kinds[0] == "owner" and kinds[-1] == "owner" and kinds.count("owner") == owner[
        "records"] and set(kinds) == {"owner", "constrained", "normal"}, kinds
    params = {p["name"]: p for p in summary["parameters"]}
    # Product-only parameters are never claimed as measured.
    for name in ("walls_area", "windows_area", "u_windows"):
        assert params[name]["determined"] is False


def test_demo_realistic_plant_is_the_default(demo, tmp_path):
    """Without --plant the demo runs the realistic plant and says so (table and JSON). The
    classifiers of the ideal run above are not used for it: the mismatch is named and
    classifiers of the realistic plant's population are trained (20 households: short; that
    they are trained is checked here, not how well they classify)."""
    import shutil

    out_iso, proc_iso = demo
    assert proc_iso.returncode == 0
    shutil.copytree(out_iso / "models", tmp_path / "models")
    out = tmp_path / "demo"
    proc = run_cli("demo", "--nights", "1+1", "--households", "20", "--out", str(out),
                   "--model-dir", str(tmp_path / "models"), "--owner-days", "0+0")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "plant: realistic (radiators, weather curve" in proc.stdout
    assert "Plant: realistic (radiators, weather curve" in proc.stdout
    assert "clock ×10000" in proc.stdout and "cached models reused" not in proc.stdout
    assert (f"classifiers: not reusing the models in {tmp_path / 'models'}: they were trained "
            "for the iso plant's population, the demo simulates the realistic plant"
            in proc.stdout)
    assert "virtual households of the realistic plant" in proc.stdout
    models = json.loads((tmp_path / "models" / "models.json").read_text())
    assert models["dataset"]["plant"] == "realistic"
    assert "simulator loop-1 setpoint back at 21.0 °C, mode 1" in proc.stdout
    summary = json.loads((out / "summary.json").read_text())
    plant = summary["plant"]
    assert plant["kind"] == "realistic"
    # The demo house's [plant.*] tables reached the simulator.
    assert plant["realism"]["heat_pump"]["min_modulation"] == 0.4
    assert plant["realism"]["sensors"]["t_air_lag_s"] == 600.0
    lumped = {q["name"]: q for q in summary["lumped"]}
    assert lumped["hlc"]["error_pct"] is not None


def test_demo_adaptive_campaign(demo, tmp_path):
    """``--adaptive``: the daemon fits after each night and stops by itself; summary.json
    tells how (classifiers of the ideal run above reused)."""
    import shutil

    out_iso, proc_iso = demo
    assert proc_iso.returncode == 0
    shutil.copytree(out_iso / "models", tmp_path / "models")
    out = tmp_path / "demo"
    proc = run_cli("demo", "--adaptive", "--max-nights", "3", "--target", "0.3,0.5",
                   "--plant", "iso", "--speed", "10000", "--out", str(out),
                   "--model-dir", str(tmp_path / "models"), "--owner-days", "0+0")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "cached models reused" in proc.stdout  # the ideal plant's, for the ideal plant
    summary = json.loads((out / "summary.json").read_text())
    camp = summary["campaign"]
    assert camp["mode"] == "adaptive" and summary["nights_run"] == len(camp["nights"]) <= 3
    assert camp["nights"][0][0] == "constrained" and summary["nights_valid"] >= 2
    actions = [d["action"] for d in camp["decisions"]]
    assert actions[-1] == "stop" and actions.count("stop") == 1
    assert camp["intervals"][-1]["valid_nights"] == summary["nights_valid"]
    assert camp["line"].startswith("Campaign: adaptive") and camp["line"] in proc.stdout
    assert "simulator loop-1 setpoint back at 21.0 °C, mode 1" in proc.stdout
    # The report shows the campaign: the interval after each fit, every decision and why.
    page = (out / "report.html").read_text()
    assert "Campaign: how the intervals shrank" in page
    assert html.escape(camp["decisions"][-1]["reason"]) in page
    # The result is the daemon's last fit, on every valid night.
    fit = json.loads((out / "fit.json").read_text())
    assert fit["lumped"]["hlc"]["value"] == pytest.approx(camp["intervals"][-1]["hlc_w_per_k"])


def test_demo_adaptive_options_are_checked(tmp_path):
    for args, place in ((("--adaptive", "--nights", "1+1"), "--nights"),
                        (("--adaptive", "--target", "5,8"), "--target")):
        proc = run_impctl("demo", *args, "--out", str(tmp_path / "d"))
        assert proc.returncode == 2 and place in proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "d").exists()


def test_demo_report_is_self_contained(demo):
    out, proc = demo
    assert proc.returncode == 0
    page = (out / "report.html").read_text()
    assert page.count("data:image/png;base64,") == 4
    for section in ("What the nights determine", "Identifiability", "data quality",
                    "Demo: truth vs estimate", "Flexibility (at 21 °C"):
        assert section in page
    for fig in ("fig_nights.png", "fig_heat_demand.png", "fig_classes.png",
                "fig_parameters.png"):
        assert (out / fig).stat().st_size > 5000


def test_report_command_from_store(demo, tmp_path):
    out, proc = demo
    assert proc.returncode == 0
    again = run_impctl("report", "--db", str(out / "state" / "impctl.db"), "--out",
                       str(tmp_path / "rep"))
    assert again.returncode == 0, again.stderr
    assert (tmp_path / "rep" / "report.html").exists()


def test_report_without_store_is_one_line_exit_2(tmp_path):
    proc = run_impctl("report", "--db", str(tmp_path / "none.db"), "--out", str(tmp_path / "r"))
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "no impctl store" in proc.stderr
    assert not (tmp_path / "none.db").exists() and not (tmp_path / "r").exists()


def test_demo_rejects_bad_nights_option(tmp_path):
    proc = run_impctl("demo", "--nights", "three", "--out", str(tmp_path / "d"))
    assert proc.returncode == 2 and "--nights" in proc.stderr


@pytest.mark.parametrize("value, words", [("2", "expected BEFORE+AFTER"),
                                          ("7+30", "after in 0–21"), ("-1+2", "days before")])
def test_demo_rejects_bad_owner_days(tmp_path, value, words):
    proc = run_impctl("demo", "--owner-days", value, "--out", str(tmp_path / "d"))
    assert proc.returncode == 2 and "--owner-days" in proc.stderr and words in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and not (tmp_path / "d").exists()
    assert not (tmp_path / "d").exists()
