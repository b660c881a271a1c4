"""The one error type users see for bad input: file, place and problem on one line."""

from __future__ import annotations

from pathlib import Path


class InputError(ValueError):
    """Bad input (house file, CSV, config, register value) with where it was found.

    The command-line interface prints ``str(error)`` as one line on stderr and exits with
    status 2.

    Parameters
    ----------
    problem : str
        What is wrong, in words a user can act on.
    source : str or Path, optional
        The file (or device) the input came from.
    place : str, optional
        Where in the source: ``"row 12"``, ``"key 'c_f'"``, ``"register 2103"``.
    """

    def __init__(self, problem: str, source: str | Path | None = None, place: str | None = None):
        self.problem = problem
        self.source = None if source is None else str(source)
        self.place = place
        super().__init__(self._line())

    def _line(self) -> str:
        where = ": ".join(p for p in (self.source, self.place) if p)
        return f"{where}: {self.problem}" if where else self.problem

    def at(self, source: str | Path | None = None, place: str | None = None) -> InputError:
        """Return a copy with the source and/or place filled in where they were missing."""
        return InputError(
            self.problem,
            self.source if self.source is not None else source,
            self.place if self.place is not None else place,
        )


def sqlite_problem(exc: BaseException) -> str:
    """What a failed SQLite write means for the person reading the log, in a few words:
    "disk full", "read-only file system", or SQLite's own text."""
    import sqlite3

    code = getattr(exc, "sqlite_errorcode", None)
    if code == sqlite3.SQLITE_FULL:
        return "disk full"
    if code is not None and code & 0xFF == sqlite3.SQLITE_READONLY:
        return "read-only"
    return str(exc) or type(exc).__name__
