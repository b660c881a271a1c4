"""The systemd unit and its companions: ``systemd-analyze verify`` (no warning at all, also
with the UART drop-in), the offline security score, the directories it may write and the
addresses it may reach, and the real ``systemd-sysusers`` / ``systemd-tmpfiles`` making the
heat-pump lock directory."""

from __future__ import annotations

import ipaddress
import os
import re
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from lock_fixtures import deployed_lock_dir, run_lock_dir, scratch_root

DEPLOY = Path(__file__).resolve().parents[1] / "deploy"
UNIT = DEPLOY / "impctl.service"
UART_DROP_IN = DEPLOY / "impctl.service.d" / "uart.conf"


def _stage(folder: Path, *drop_ins: Path) -> Path:
    """The unit with its /opt/impctl paths pointed at this checkout's venv, so that
    ``verify`` can check the executables exist; drop-ins go to ``impctl.service.d/`` next to
    it, where ``verify`` reads them."""
    assert shutil.which("systemd-analyze"), "systemd-analyze is needed (Debian package systemd)"
    impctl = Path(sys.executable).with_name("impctl")
    assert impctl.exists()
    text = UNIT.read_text().replace("/opt/impctl/.venv/bin/impctl", str(impctl))
    staged = folder / "impctl.service"
    staged.write_text(text)
    for drop_in in drop_ins:
        (folder / "impctl.service.d").mkdir(exist_ok=True)
        shutil.copy(drop_in, folder / "impctl.service.d" / drop_in.name)
    return staged


def _verify(unit: Path) -> subprocess.CompletedProcess:
    return subprocess.run(["systemd-analyze", "verify", "--man=no", str(unit)],
                          capture_output=True, text=True)


def _settings(key: str) -> list[str]:
    """Every value of ``key=`` in the unit, split at blanks, in order."""
    return [v for line in UNIT.read_text().splitlines() if line.startswith(f"{key}=")
            for v in line.split("=", 1)[1].split()]


@pytest.fixture
def staged_unit(tmp_path: Path) -> Path:
    return _stage(tmp_path)


def test_unit_verifies_without_any_warning(staged_unit):
    proc = _verify(staged_unit)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.strip() == "" and proc.stdout.strip() == ""


def test_the_uart_drop_in_verifies_and_allows_the_uarts(tmp_path):
    proc = _verify(_stage(tmp_path, UART_DROP_IN))
    assert proc.returncode == 0 and proc.stderr.strip() == "" == proc.stdout.strip(), \
        proc.stderr
    # verify does read it: a wrong key in the drop-in is named.
    with (tmp_path / "impctl.service.d" / "uart.conf").open("a") as f:
        f.write("DeviceAlow=char-ttyAMA rw\n")
    assert "uart.conf:" in _verify(tmp_path / "impctl.service").stderr
    allowed = [line.split("=", 1)[1] for line in UART_DROP_IN.read_text().splitlines()
               if line.startswith("DeviceAllow=")]
    assert allowed == ["char-ttyAMA rw", "char-ttyS rw", "char-ttySC rw"]


def test_unit_writes_only_the_heat_pump_lock_directory_tmpfiles_makes():
    assert _settings("ReadWritePaths") == ["-/run/lock/impctl"]
    [tmpfiles] = [line.split() for line in (DEPLOY / "impctl.tmpfiles").read_text()
                  .splitlines() if line and not line.startswith("#")]
    assert tmpfiles == ["d", "/run/lock/impctl", "3770", "root", "impctl", "-"]
    [sysusers] = [line for line in (DEPLOY / "impctl.sysusers").read_text().splitlines()
                  if line and not line.startswith("#")]
    assert sysusers.split()[:2] == ["u", "impctl"]
    assert _settings("User") == ["impctl"] and _settings("Group") == ["impctl"]
    assert "DynamicUser" not in UNIT.read_text()


def _networks(values: list[str]) -> list[ipaddress.IPv4Network | ipaddress.IPv6Network]:
    """IPAddressAllow= values as networks, its keywords as systemd.resource-control(5) says."""
    keywords = {"localhost": ["127.0.0.0/8", "::1/128"],
                "link-local": ["169.254.0.0/16", "fe80::/64"],
                "multicast": ["224.0.0.0/4", "ff00::/8"], "any": ["0.0.0.0/0", "::/0"]}
    return [ipaddress.ip_network(n) for v in values for n in keywords.get(v, [v])]


def test_unit_reaches_loopback_and_the_lan_over_ipv4_and_ipv6_only():
    assert _settings("IPAddressDeny") == ["any"]
    allowed = _networks(_settings("IPAddressAllow"))
    for address in ("127.0.0.1", "::1", "192.168.1.50", "10.1.2.3", "172.16.0.9",
                    "169.254.10.20", "fd12:3456:789a::50", "fe80::1e2f:65ff:fe00:50"):
        ip = ipaddress.ip_address(address)
        assert any(ip in n for n in allowed if n.version == ip.version), address
    for address in ("8.8.8.8", "100.64.0.1", "2a00:1450:4001::50", "2001:db8::1"):
        ip = ipaddress.ip_address(address)
        assert not any(ip in n for n in allowed if n.version == ip.version), address


def test_sysusers_and_tmpfiles_make_the_lock_directory_root_and_impctl_share():
    with scratch_root() as base:
        # Without the tmpfiles line a root impctl made it 0755 root:root (and only root could
        # use it); the line puts it right, as it makes it at every boot.
        made_by_root = run_lock_dir(base) / "impctl"
        made_by_root.mkdir(mode=0o755)
        deployed = deployed_lock_dir(base)
        st = os.stat(deployed.path)
        assert deployed.path == made_by_root
        assert (st.st_uid, st.st_gid, stat.S_IMODE(st.st_mode)) == (0, deployed.gid, 0o3770)
        assert deployed.uid not in (0, 65534) and deployed.gid != 0


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
    for line in ("Type=notify", "WatchdogSec=", "Restart=on-failure", "User=impctl",
                 "StateDirectory=impctl", "ProtectSystem=strict", "NoNewPrivileges=yes",
                 "SupplementaryGroups=dialout", "DeviceAllow=char-ttyUSB rw",
                 "ExecStopPost=/opt/impctl/.venv/bin/impctl restore"):
        assert line in text, line
    assert "PrivateDevices" not in text  # it would hide /dev/ttyUSB*
