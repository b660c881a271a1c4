"""Issue 12, items 4 and 12: the configuration an operator writes.

Every ``[heatpump]`` problem at once (also in ``[heatpump.*]`` subsections), a missing
``[heatpump]`` or ``host = ""`` refused instead of a silent 127.0.0.1:502, ``heat_meter``
without ``address`` as one clear line, a UTF-8 BOM accepted, bounds on ``link_lost_limit_s``,
``min_coverage``, ``max_comfort_band_k`` and on the room-setpoint limits, and
``impctl check-config``. The CLI runs as a real subprocess (exit status, stderr lines, no
traceback); the bounds are also tried with hypothesis on the parser itself.
"""

from __future__ import annotations

import pytest
from cli_fixtures import run_impctl
from daemon_fixtures import ROOT, run_cli
from hypothesis import given, settings
from hypothesis import strategies as st

from impctl.config import config_from_mapping
from impctl.errors import InputError

EXAMPLE = ROOT / "deploy" / "config.example.toml"


def _lines(result, path) -> list[str]:
    lines = result.stderr.splitlines()
    prefix = f"impctl: {path}: "
    assert lines and all(x.startswith(prefix) for x in lines), result.stderr
    return [x[len(prefix):] for x in lines]


def test_every_heatpump_problem_at_once(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(f"""
state_dir = "{tmp_path / 'state'}"
[heatpump]
host = ""
port = 0
timeout_s = -1
colour = "red"
[heatpump.heat_meter]
device_id = 30
[heatpump.room_sensor]
address = 70000
device_id = 31
[heatpump.writes]
loop1_setpoint_c = [16, 45]
daily_budget = -1
""")
    for cmd in ("daemon", "check-config"):
        # the daemon in its own process; check-config's lines are checked in this one
        result = (run_cli(cmd, "--config", str(bad), timeout_s=30) if cmd == "daemon"
                  else run_impctl(cmd, "--config", str(bad)))
        assert result.returncode == 2 and result.stdout == "" and "Traceback" not in result.stderr
        assert sorted(_lines(result, bad)) == sorted([
            "[heatpump.writes] key 'loop1_setpoint_c': room-setpoint limits must satisfy "
            "10 <= min <= max <= 30 °C, got [16, 45]",
            "[heatpump.writes] key 'daily_budget': must be >= 0",
            "[heatpump.room_sensor] key 'address': must be 0–65535 (the zero-based PDU "
            "address)",
            "[heatpump.heat_meter] key 'address': missing (required)",
            "[heatpump] key 'colour': unknown key",
            "[heatpump] key 'host': must not be empty (the gateway's IP address or name)",
            "[heatpump] key 'port': must be 1–65535",
            "[heatpump] key 'timeout_s': must lie in (0, 60] s",
        ]), cmd
    assert not (tmp_path / "state").exists()


def test_missing_heatpump_section_and_missing_host_are_errors(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'state_dir = "{tmp_path / "s"}"\n')
    result = run_cli("daemon", "--config", str(cfg), timeout_s=30)
    assert result.returncode == 2
    assert _lines(result, cfg) == ["[heatpump]: missing section: set transport and host (tcp) "
                                   "or serial_port (rtu) of the heat pump"]
    cfg.write_text(f'state_dir = "{tmp_path / "s"}"\n[heatpump]\nport = 502\n')
    result = run_impctl("check-config", "--config", str(cfg))
    assert result.returncode == 2
    assert _lines(result, cfg) == ["[heatpump] key 'host': missing (required)"]
    assert not (tmp_path / "s").exists()


def test_bounds_and_bom(tmp_path):
    cfg = tmp_path / "c.toml"
    body = (f'state_dir = "{tmp_path / "s"}"\n[heatpump]\nhost = "192.168.1.50"\n'
            "[night]\nlink_lost_limit_s = 1e9\nmin_coverage = 0.01\nmax_comfort_band_k = 50\n")
    cfg.write_bytes(b"\xef\xbb\xbf" + body.encode())  # what Windows editors write
    result = run_impctl("check-config", "--config", str(cfg))
    assert result.returncode == 2
    assert _lines(result, cfg) == [
        "key 'night.max_comfort_band_k': must lie in (0, 3] K: further below the owner's "
        "setpoint a home is no longer comfortable",
        "key 'night.link_lost_limit_s': must be at most 3600 s: a night with the heating off "
        "is never left unwatched longer",
        "key 'night.min_coverage': must lie in [0.5, 1]: a night with less than half its "
        "samples is not data"]
    # The same file with a BOM and good values is accepted.
    good = body.split("[night]")[0]
    cfg.write_bytes(b"\xef\xbb\xbf" + good.encode())
    result = run_impctl("check-config", "--config", str(cfg))
    assert result.returncode == 0, result.stderr


def test_check_config_says_what_runs_tonight():
    result = run_impctl("check-config", "--config", str(EXAMPLE))
    # The example's state_dir (/var/lib/impctl) may not be creatable by the test user; every
    # other key is fine.
    if result.returncode == 2:
        assert _lines(result, EXAMPLE) and all("state_dir" in x for x in _lines(result, EXAMPLE))
        return
    out = result.stdout
    assert "no problem found" in out and "tcp 192.168.1.50:502 unit 20" in out
    assert "next:      constrained night from the campaign, window" in out
    assert "preheat: loop-1 setpoint 23.5 °C" in out and "T_min 18.5 °C" in out


def test_check_config_with_a_writable_state_dir(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text(EXAMPLE.read_text().replace('"/var/lib/impctl"',
                                               f'"{tmp_path / "state"}"'))
    result = run_impctl("check-config", "--config", str(cfg))
    assert result.returncode == 0, result.stderr
    assert "daemon:    NOT RUNNING (never started on this store)" in result.stdout
    assert "next:      constrained night from the campaign" in result.stdout
    assert "22:00 switch-off: loop-1 mode 0" in result.stdout
    assert not (tmp_path / "state").exists()  # checked, not created


BASE = {"state_dir": "/tmp/x", "heatpump": {"host": "192.168.1.50"}}


@settings(max_examples=200, deadline=None)
@given(lo=st.floats(-50, 80), hi=st.floats(-50, 80))
def test_room_setpoint_limits_outside_10_30_refused(lo, hi):
    mapping = {**BASE, "heatpump": {"host": "192.168.1.50",
                                    "writes": {"loop1_setpoint_c": [lo, hi]}},
               "campaign": {"constrained_setpoint_c": 20.0, "normal_setpoints_c": [20.0]},
               "night": {"comfort_band_k": 1.0}}
    ok = 10.0 <= lo <= hi <= 30.0
    try:
        cfg = config_from_mapping(mapping)
    except InputError as exc:
        if ok:  # a good pair may still not fit the campaign's setpoints, never the bounds
            assert "10 <= min <= max <= 30" not in str(exc)
        else:
            assert "key 'loop1_setpoint_c': room-setpoint limits" in str(exc)
        return
    assert ok and cfg.heatpump.writes.loop1_setpoint_c == (lo, hi)


@settings(max_examples=100, deadline=None)
@given(limit=st.floats(1, 1e10), cov=st.floats(0, 2), band=st.floats(0.01, 100))
def test_night_bounds_property(limit, cov, band):
    mapping = {**BASE, "night": {"link_lost_limit_s": limit, "min_coverage": cov,
                                 "max_comfort_band_k": band, "comfort_band_k": min(band, 1.5),
                                 "sample_interval_s": 1.0 if limit < 5 else 5.0}}
    try:
        config_from_mapping(mapping)
        accepted = True
    except InputError as exc:
        text = str(exc)
        accepted = False
    if accepted:
        assert limit <= 3600 and 0.5 <= cov <= 1 and band <= 3
    else:
        assert limit > 3600 or limit < 5 or not 0.5 <= cov <= 1 or band > 3, text


@pytest.mark.parametrize("pair", [[16, 45], [5, 23], [16, 31], [9.9, 20]])
def test_issue_limits_refused_by_the_daemon(tmp_path, pair):
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'state_dir = "{tmp_path / "s"}"\n[heatpump]\nhost = "192.168.1.50"\n'
                   f"[heatpump.writes]\nloop1_setpoint_c = {pair}\n")
    result = run_cli("daemon", "--config", str(cfg), timeout_s=30)
    assert result.returncode == 2
    assert any("loop1_setpoint_c" in x and "10 <= min <= max <= 30" in x
               for x in _lines(result, cfg))
