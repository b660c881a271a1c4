"""The pieces of the HTML reports: a PNG inlined as an image, a table (escaped)."""

from __future__ import annotations

import base64
import html
from pathlib import Path


def img(path: Path) -> str:
    """The PNG at ``path`` as an inline ``<img>`` (the page stays one self-contained file)."""
    data = base64.b64encode(path.read_bytes()).decode()
    return f'<img src="data:image/png;base64,{data}" alt="{html.escape(path.stem)}">'


def table(headers: list[str], rows: list[list]) -> str:
    """An HTML table, every cell escaped."""
    head = "".join(f"<th>{html.escape(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>"
                   for r in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
