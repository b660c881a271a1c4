"""Numbers people write (MQTT payloads, command-line options, CSV cells, config strings):
ASCII only.

Python's ``float()`` and ``int()`` take any Unicode decimal digit and space — ``float('٢٢')``
and ``int('２２')`` are 22 — so a payload typed on a phone set to Arabic or with a Japanese
input method would be taken as a number nobody sees in the text. Every parse of a number from
people's text goes through :func:`parse_float` / :func:`parse_int` (or checks
:func:`non_ascii_problem` before a parser of its own), which refuse any character outside
ASCII with one line naming it. Pure standard library: imported by the daemon and the CLI.
"""

from __future__ import annotations

import unicodedata


def non_ascii_problem(text: str) -> str | None:
    """Why ``text`` is not a number written in ASCII — its first character outside ASCII,
    named (e.g. ``'２２' holds '２' (FULLWIDTH DIGIT TWO): write numbers with the ASCII
    digits 0-9``) — or None when it is all ASCII."""
    for ch in text:
        if not ch.isascii():
            name = unicodedata.name(ch, f"U+{ord(ch):04X}")
            shown = text if len(text) <= 40 else text[:37] + "..."
            return (f"{shown!r} holds {ch!r} ({name}): write numbers with the ASCII digits "
                    "0-9")
    return None


def parse_float(text: str) -> float:
    """``float(text)`` for ASCII text only.

    Raises
    ------
    ValueError
        A character outside ASCII (the message names it, :func:`non_ascii_problem`), a "_"
        (Python's digit grouping, no number people write), or what ``float`` refuses.
    """
    problem = non_ascii_problem(text) or underscore_problem(text)
    if problem is not None:
        raise ValueError(problem)
    return float(text)


def parse_int(text: str) -> int:
    """``int(text)`` (base 10) for ASCII text only; raises ValueError as :func:`parse_float`."""
    problem = non_ascii_problem(text) or underscore_problem(text)
    if problem is not None:
        raise ValueError(problem)
    return int(text)


def underscore_problem(text: str) -> str | None:
    """Why ``text`` is no number people write when it holds "_" (Python's digit grouping:
    ``float('2_2')`` is 22, a typo read as another number), else None."""
    return f"{text!r} holds '_': write numbers with the digits 0-9 alone" if "_" in text \
        else None
