"""Look at the report in a real browser: a headless Chromium screenshot of report.html.

Run:  .venv/bin/python bench/report_screenshot.py [REPORT_DIR] [--out shot.png]

REPORT_DIR defaults to ./impctl-demo (what ``impctl demo`` writes). Needs Debian's chromium
(``apt-get install chromium``); it is not part of the test suite for that reason. Prints the
command used and the size of the screenshot; open the PNG to look at the page.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report_dir", nargs="?", default="impctl-demo", type=Path)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    page = (args.report_dir / "report.html").resolve()
    if not page.exists():
        print(f"no report at {page}: run `impctl demo` first", file=sys.stderr)
        return 2
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        print("chromium not installed: apt-get install chromium", file=sys.stderr)
        return 2
    out = (args.out or args.report_dir / "report_screenshot.png").resolve()
    with tempfile.TemporaryDirectory() as profile:
        cmd = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
               "--no-first-run", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", f"--user-data-dir={profile}",
               "--window-size=1200,4000", f"--screenshot={out}", page.as_uri()]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    print(f"# command: {' '.join(cmd[:1] + cmd[1:-3])} --screenshot={out} {page.as_uri()}")
    if proc.returncode != 0 or not out.exists():
        print(proc.stderr[-2000:], file=sys.stderr)
        return 1
    print(f"screenshot: {out} ({out.stat().st_size / 1024:.0f} KiB) of {page} "
          f"({page.stat().st_size / 1024:.0f} KiB, figures embedded)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
