"""``impctl ARGS`` run inside the test process: the same ``main`` the console script runs, its
stdout, stderr and exit status returned as a :class:`subprocess.CompletedProcess`.

For tests that check what the command prints, writes and returns. A fresh interpreter costs
1–3 s of imports (torch, scipy, pandas) per call, so tests that check nothing about the
process itself run the command here; tests where the process matters (signals, the daemon,
a crash, which modules an invocation imports, warnings printed by the interpreter) keep a
real subprocess.
"""

from __future__ import annotations

import contextlib
import logging
import subprocess
import sys
import traceback
from collections.abc import Mapping
from pathlib import Path

from click.testing import CliRunner


def run_impctl(*args: str, env: Mapping[str, str | None] | None = None,
               cwd: Path | str | None = None, input: str | None = None
               ) -> subprocess.CompletedProcess:
    """``impctl ARGS`` in this process: ``env`` overrides ``os.environ`` for the call (None
    removes a variable), ``cwd`` is the working directory for the call; an exception that
    escapes ``main`` is printed on stderr with exit status 1, as the interpreter would."""

    argv = [str(a) for a in args]
    # a command that sets up logging (basicConfig(force=True)) must not leave its handler,
    # writing to this call's stderr, on the test process's root logger
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    try:
        return _run(argv, env, cwd, input)
    finally:
        root.handlers[:] = handlers
        root.setLevel(level)


def _run(argv: list[str], env: Mapping[str, str | None] | None, cwd: Path | str | None,
         input: str | None) -> subprocess.CompletedProcess:
    from impctl.cli import main

    with CliRunner().isolation(input=input, env=env) as (out, err, _):
        with contextlib.chdir(cwd) if cwd is not None else contextlib.nullcontext():
            try:
                main(argv)
                code = 0
            except SystemExit as exc:
                code = _exit_status(exc.code)
            except Exception:  # noqa: BLE001 — reported as the interpreter reports it
                traceback.print_exc()
                code = 1
        # text still in the wrappers' buffers belongs to the output
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        stdout = out.getvalue().decode("utf-8", "replace")
        stderr = err.getvalue().decode("utf-8", "replace")
    return subprocess.CompletedProcess(["impctl", *argv], code, stdout, stderr)


def _exit_status(code: object) -> int:
    # sys.exit(None) is 0, sys.exit(int) is the int, sys.exit("text") prints text and is 1
    if code is None:
        return 0
    if isinstance(code, int):
        return code
    print(code, file=sys.stderr)
    return 1
