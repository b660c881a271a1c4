"""Idle memory of the impctl daemon (issue 6 target: RSS ≤ 60 MB, no torch/sklearn/pandas).

Run:  .venv/bin/python bench/daemon_rss.py [--settle 5] [--speed 1]

Starts ``impctl-sim`` and then ``impctl daemon --config X`` exactly as systemd does
(``python -c "from impctl.cli import main; main()" daemon --config X``), both as subprocesses
on loopback, with a campaign configured and no night due (so the daemon is idle: connected,
scheduler running, polling the trigger queue). When the daemon has started its scheduler it
waits ``--settle`` seconds and reads, from outside the process:

* ``VmRSS`` / ``VmHWM`` (peak) / ``RssAnon`` from ``/proc/PID/status``;
* which heavy packages it loaded, from the shared objects in ``/proc/PID/maps`` (torch,
  scikit-learn, pandas and numpy all load compiled extensions, so a package imported at all
  shows up there; the process is not modified to find out).

For comparison it repeats the measurement with a variant that registers only the
device-side subcommands (``impctl.cli.device``), i.e. what the daemon would weigh if the
CLI did not import every subcommand module at start, and with ``[mqtt]`` on (issue 17: a
real mosquitto on loopback, the bridge connected with commands on; needs ``mosquitto``).
"""

from __future__ import annotations

import argparse
import platform
import re
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from daemon_fixtures import (  # noqa: E402
    IMPCTL_SIM,
    PYTHON,
    daemon_mapping,
    stop_process,
    wait_until,
    write_config,
)
from mqtt_fixtures import broker  # noqa: E402

from impctl.clock import VirtualClock  # noqa: E402

TARGET_MB = 60.0
MQTT_VARIANT = "impctl daemon with [mqtt] on"
FORBIDDEN = ("torch", "sklearn", "pandas")
WATCHED = (*FORBIDDEN, "numpy", "scipy", "matplotlib", "pyarrow")
VARIANTS = {
    "impctl daemon (as deployed)": "from impctl.cli import main; main()",
    "device commands only (comparison)":
        "import sys; from impctl.cli import cli; import impctl.cli.device.commands; "
        "cli.main(args=sys.argv[1:])",
}


def status_kb(pid: int) -> dict[str, int]:
    """The memory lines of /proc/PID/status [kB]."""
    out = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM", "RssAnon", "RssFile", "VmSize"):
            out[key] = int(value.split()[0])
    return out


def loaded_packages(pid: int) -> dict[str, int]:
    """Watched package → number of its shared objects mapped into the process."""
    files = set()
    for line in Path(f"/proc/{pid}/maps").read_text().splitlines():
        parts = line.split(maxsplit=5)
        if len(parts) == 6 and re.search(r"\.so(\.|$)", parts[5]):
            files.add(parts[5])
    found = {}
    for pkg in WATCHED:
        pat = re.compile(rf"/site-packages/{pkg}(/|\.libs/|-)")
        n = sum(1 for f in files if pat.search(f))
        if n:
            found[pkg] = n
    return found


def measure(code: str, port: int, clock: VirtualClock, work: Path, settle_s: float,
            mqtt: dict | None = None) -> dict:
    state = work / "state"
    mapping = daemon_mapping(
        state, port, clock,
        campaign={"enabled": True, "fit_when_complete": True})
    if mqtt is not None:
        mapping["mqtt"] = mqtt
    mapping["log_level"] = "info"
    config = write_config(work / "config.toml", mapping)
    cmd = [PYTHON, "-c", code, "daemon", "--config", str(config)]
    log = work / "daemon.log"
    with log.open("w") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, cwd=ROOT)
    try:
        wait_until(lambda: "next night job at" in log.read_text(), 60, "the daemon to settle",
                   proc=proc)
        if mqtt is not None:
            wait_until(lambda: "MQTT connected" in log.read_text(), 30, "the broker",
                       proc=proc)
        time.sleep(settle_s)
        mem = status_kb(proc.pid)
        pkgs = loaded_packages(proc.pid)
        running = proc.poll() is None
    finally:
        rc = stop_process(proc)
    return dict(cmd=cmd, mem=mem, pkgs=pkgs, running=running, rc=rc, log=log)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--settle", type=float, default=5.0,
                        help="seconds to wait after the scheduler started")
    parser.add_argument("--speed", type=float, default=1.0,
                        help="clock factor (1 = real time; no night is due for hours)")
    args = parser.parse_args()

    # 09:00 local in January: the next night's preheat (20:00) is 11 simulated hours away.
    epoch = datetime(2026, 1, 12, 8, 0, tzinfo=UTC)
    with tempfile.TemporaryDirectory(prefix="impctl-rss-") as tmp:
        work = Path(tmp)
        clock_file = work / "sim.clock"
        sim = subprocess.Popen(
            [*IMPCTL_SIM, "--port", "0", "--speed", repr(args.speed), "--epoch",
             epoch.isoformat(), "--clock-file", str(clock_file)],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT)
        try:
            line = sim.stdout.readline()
            port = int(line.split("serving tcp ")[1].split()[0].rsplit(":", 1)[1])
            clock = VirtualClock.from_spec(clock_file.read_text().strip())
            results = {}
            for name, code in VARIANTS.items():
                sub = work / re.sub(r"\W+", "_", name)
                sub.mkdir()
                results[name] = measure(code, port, clock, sub, args.settle)
            # The deployed daemon again, with [mqtt] on: a real mosquitto on loopback, the
            # bridge connected, discovery published, commands subscribed (issue 17).
            sub = work / "mqtt"
            sub.mkdir()
            with broker(sub / "broker") as b:
                results[MQTT_VARIANT] = measure(
                    VARIANTS["impctl daemon (as deployed)"], port, clock, sub, args.settle,
                    mqtt={"host": "127.0.0.1", "port": b.port, "client_id": "bench",
                          "commands": True})
        finally:
            stop_process(sim)

    print(f"impctl daemon idle memory — {platform.python_implementation()} "
          f"{platform.python_version()}, {platform.machine()}, settle {args.settle:g} s, "
          f"target VmRSS <= {TARGET_MB:g} MB")
    print()
    print(f"{'variant':<36} {'VmRSS MB':>9} {'VmHWM MB':>9} {'RssAnon MB':>11}  "
          f"{'target':<7} loaded heavy packages (.so files mapped)")
    for name, r in results.items():
        mem = r["mem"]
        ok = "ok" if mem["VmRSS"] / 1024 <= TARGET_MB else "OVER"
        pkgs = ", ".join(f"{k} ({v})" for k, v in r["pkgs"].items()) or "none"
        print(f"{name:<36} {mem['VmRSS'] / 1024:>9.1f} {mem['VmHWM'] / 1024:>9.1f} "
              f"{mem['RssAnon'] / 1024:>11.1f}  {ok:<7} {pkgs}")
    print()
    for name, r in results.items():
        bad = [p for p in FORBIDDEN if p in r["pkgs"]]
        verdict = ("imports none of torch/sklearn/pandas" if not bad
                   else "MUST NOT import: " + ", ".join(bad))
        print(f"{name}: {verdict}; exit status on SIGTERM {r['rc']}")
    print()
    print("command measured:")
    deployed = results["impctl daemon (as deployed)"]["cmd"]
    print("  " + " ".join(f"'{c}'" if " " in c or ";" in c else c for c in deployed))
    print("  (memory from /proc/PID/status of that process, packages from /proc/PID/maps)")


if __name__ == "__main__":
    main()
