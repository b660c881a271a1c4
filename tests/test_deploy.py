"""The systemd unit: systemd-analyze verify (no warning at all) and the offline security score."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

UNIT = Path(__file__).resolve().parents[1] / "deploy" / "impctl.service"


@pytest.fixture
def staged_unit(tmp_path: Path) -> Path:
    """The unit with its /opt/impctl paths pointed at this checkout's venv, so that
    ``verify`` can check the executables exist."""
    assert shutil.which("systemd-analyze"), "systemd-analyze is needed (Debian package systemd)"
    impctl = Path(sys.executable).with_name("impctl")
    assert impctl.exists()
    text = UNIT.read_text().replace("/opt/impctl/.venv/bin/impctl", str(impctl))
    staged = tmp_path / "impctl.service"
    staged.write_text(text)
    return staged


def test_unit_verifies_without_any_warning(staged_unit):
    proc = subprocess.run(["systemd-analyze", "verify", "--man=no", str(staged_unit)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.strip() == "" and proc.stdout.strip() == ""


def test_unit_security_exposure_at_most_2_5(staged_unit):
    proc = subprocess.run(
        # --threshold is in tenths of the printed score: 25 = 2.5.
        ["systemd-analyze", "security", "--offline=true", "--threshold=25", str(staged_unit)],
        capture_output=True, text=True)
    match = re.search(r"Overall exposure level for \S+: ([0-9.]+)", proc.stdout)
    assert match, proc.stdout + proc.stderr
    assert float(match.group(1)) <= 2.5
    assert proc.returncode == 0


def test_unit_has_the_safety_lines():
    text = UNIT.read_text()
    for line in ("Type=notify", "WatchdogSec=", "Restart=on-failure", "DynamicUser=yes",
                 "StateDirectory=impctl", "ProtectSystem=strict", "NoNewPrivileges=yes",
                 "SupplementaryGroups=dialout", "DeviceAllow=char-ttyUSB rw",
                 "ExecStopPost=/opt/impctl/.venv/bin/impctl restore"):
        assert line in text, line
    assert "PrivateDevices" not in text  # it would hide /dev/ttyUSB*
