"""MkDocs hook: reference pages generated from the code at build time.

* ``<!-- generated: configuration -->`` becomes the gateway configuration's keys, defaults,
  units and accepted values. Keys and defaults come from the dataclasses that
  :func:`impctl.config.config_from_mapping` builds; the accepted values are what that
  validator answers when each key is set to an out-of-range value (so the page can never
  promise a bound the code does not check); the meaning of each key is its comment in
  ``deploy/config.example.toml``.
* ``<!-- generated: fleet-columns -->`` becomes the FLEET dataset's columns and types from
  :data:`impctl.fleet.results.table.SCHEMA`.
* The CLI page is rendered by mkdocs-click; the click group gets its subcommands here first.
"""

from __future__ import annotations

import re
import typing
from dataclasses import MISSING, fields, is_dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "deploy" / "config.example.toml"

#: A valid starting point for the probes: the smallest configuration the validator accepts.
_BASES = (
    {"heatpump": {"host": "192.0.2.1"}, "mqtt": {"host": "192.0.2.2"}},
    {"heatpump": {"transport": "rtu", "serial_port": "/dev/ttyUSB0"},
     "mqtt": {"host": "192.0.2.2"}},
)
_UNITS = (("_c", "°C"), ("_k", "K"), ("_s", "s"), ("_h", "h"), ("_w", "W"), ("_min", "min"),
          ("_mb", "MB"))
_PROBLEM = re.compile(r"^(?:\[(?P<table>[^\]]+)\] )?key '(?P<key>[^']+)': (?P<msg>.*)$")
# References to lab notes in the example's comments are not for the reader of this page.
_NOTE_REF = re.compile(r"\s*\((?:[^()]*(?:RESULTS\.md|README|[Ii]ssue \d+)[^()]*)\)|"
                       r";?\s*(?:bench/RESULTS\.md|README)[^;.)]*")


def on_config(config, **kwargs):
    """Attach the subcommands to the click group before mkdocs-click reads it."""
    from impctl import cli

    cli._register()
    return config


def on_page_markdown(markdown: str, page, config, files, **kwargs) -> str:
    """Fill the generated sections of a page."""
    if "<!-- generated: configuration -->" in markdown:
        markdown = markdown.replace("<!-- generated: configuration -->", configuration_md())
    if "<!-- generated: fleet-columns -->" in markdown:
        markdown = markdown.replace("<!-- generated: fleet-columns -->", fleet_columns_md())
    return markdown


_BRACKET_NOTE = re.compile(
    r'<autoref (?=[^>]*identifier="(?P<id>[^"]*\s[^"]*)")[^>]*>(?P<title>.*?)</autoref>', re.S)


_SPHINX_ROLE = re.compile(r":(?:func|class|mod|data|meth|attr|exc|obj):(<code>)~?")


def on_page_content(html: str, page, config, files, **kwargs) -> str:
    """Docstrings mark sources in brackets ("[-] [own choice]", "[RH §2]"): Markdown reads
    "[a] [b]" as a reference link, and autorefs would look for a page section "own choice".
    An identifier with a space is never a Python object: put the brackets back as text."""
    def text(m: re.Match) -> str:
        title, ident = m["title"], m["id"]
        return f"[{ident}]" if title == ident else f"[{title}] [{ident}]"

    # click ≥ 8.2 marks "no default" with a sentinel that mkdocs-click prints by its repr.
    html = html.replace("<code>Sentinel.UNSET</code>", "–")
    # Sphinx roles in docstrings (":func:`~a.b`") read as code here.
    html = _SPHINX_ROLE.sub(r"\1", html)
    return _BRACKET_NOTE.sub(text, html)


# -- the configuration ------------------------------------------------------------------------

def _dataclasses_in(hint) -> list[type]:
    args = typing.get_args(hint) or (hint,)
    return [a for a in args if isinstance(a, type) and is_dataclass(a)]


def _tables(cls: type, table: str, out: dict[str, list], parents: dict[str, tuple]) -> None:
    """Walk the configuration's dataclasses: table name → [(key, field, hint, class)];
    ``parents``: sub-table → (the class and field that hold it)."""
    hints = typing.get_type_hints(cls)
    rows = out.setdefault(table, [])
    for f in fields(cls):
        if f.name == "source" or f.metadata.get("configured") is False:
            continue  # not a configuration key (set at run time)
        inner = _dataclasses_in(hints[f.name])
        if inner and f.name == "link":
            if table == "heatpump":      # the heat pump's own link: its keys sit in [heatpump]
                _tables(inner[0], table, out, parents)
            else:
                rows.append((f.name, f, "table", cls))
            continue
        if inner:
            sub = f"{table}.{f.name}" if table else f.name
            parents[sub] = (cls, f.name)
            _tables(inner[0], sub, out, parents)
            if len(typing.get_args(hints[f.name])) > 1 and not _optional_only(hints[f.name]):
                rows.append((f.name, f, hints[f.name], cls))  # a name or a table (room_sensor)
            continue
        rows.append((f.name, f, hints[f.name], cls))


def _attribute_docs(cls: type) -> dict[str, str]:
    """The numpy-style ``Attributes`` section of a dataclass's docstring: name → text."""
    doc = (cls.__doc__ or "").split("\n")
    out: dict[str, str] = {}
    names: list[str] = []
    inside = False
    for line in doc:
        text = line.strip()
        if text == "Attributes":
            inside = True
            continue
        if not inside or set(text) <= {"-"}:
            continue
        m = re.match(r"^([a-z_][\w, ]*?)\s*:\s*(.*)$", text)
        if m and not line.startswith(" " * 8):
            names = [n.strip() for n in m[1].split(",")]
            for n in names:
                out[n] = m[2].strip()
        elif text and names:
            for n in names:
                out[n] = f"{out[n]} {text}"
        elif not text:
            names = []
    return {k: _NOTE_REF.sub("", v).strip() for k, v in out.items()}


def _optional_only(hint) -> bool:
    args = typing.get_args(hint)
    return len(args) == 2 and type(None) in args


def _default(f) -> object:
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:
        return f.default_factory()
    return MISSING


def _fmt(value: object) -> str:
    if value is MISSING:
        return "required"
    if value is None:
        return "not set"
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, str):
        return f'`"{value}"`'
    if isinstance(value, tuple):
        return "`[" + ", ".join(_fmt(v).strip("`") for v in value) + "]`"
    if isinstance(value, float):
        return f"`{value:g}`" if value != int(value) or abs(value) >= 1e6 else f"`{value:.1f}`"
    return f"`{value}`"


def _unit(key: str) -> str:
    for suffix, unit in _UNITS:
        if key.endswith(suffix):
            return unit
    return ""


def _set(mapping: dict, path: list[str], value: object) -> dict:
    import copy

    out = copy.deepcopy(mapping)
    node = out
    for part in path[:-1]:
        node = node.setdefault(part, {})
    node[path[-1]] = value
    return out


def _probes(default: object, hint: object = None) -> list[object]:
    if default is MISSING and hint in (int, float, str):
        default = hint()
    if isinstance(default, bool):
        return []
    if isinstance(default, int):
        return [-10**9, 10**9]
    if isinstance(default, float):
        return [-1e9, 1e9]
    if isinstance(default, tuple) and len(default) == 2:
        return [[1e9, -1e9], [-1e9, 1e9]]
    if isinstance(default, tuple):
        return [[-1e9], [1e9]]
    if isinstance(default, str):
        return ["\u00bfnot a valid value?"]
    return []


def _accepted(table: str, key: str, default: object, hint: object = None) -> str:
    """What the validator answers to out-of-range values of this key, one line each."""
    from impctl.config import ConfigError, config_from_mapping
    from impctl.errors import InputError

    full = f"{table}.{key}" if table else key
    path = full.split(".")
    messages: list[str] = []
    for base in _BASES:
        if table.startswith("heatpump.heat_meter") or table.startswith("heatpump.room_sensor"):
            base = _set(base, path[:2], {"device_id": 30, "address": 0})
        for value in _probes(default, hint):
            try:
                config_from_mapping(_set(base, path, value))
            except ConfigError as exc:
                for problem in exc.problems:
                    m = _PROBLEM.match(problem.problem)
                    if not m:
                        continue
                    where = f"{m['table']}.{m['key']}" if m["table"] else m["key"]
                    msg = re.sub(r",? got .*$", "", m["msg"])  # the probe, not the rule
                    msg = msg.replace("\u00bfnot a valid value?", "…")
                    msg = re.sub(r"-?(?:1e\+09|1000000000)(?:\.0)?", "…", msg)
                    if where == full and msg not in messages:
                        messages.append(msg)
            except (InputError, Exception):  # noqa: BLE001 - a page must still build
                continue
    return "<br>".join(_escape(m) for m in messages) or "any"


def _escape(text: str) -> str:
    return text.replace("|", "\\|").replace("<", "&lt;")


def _example_comments() -> tuple[dict[str, str], set[str]]:
    """``table.key`` → its comment in deploy/config.example.toml (commented-out keys too), and
    the tables whose header is not commented out there."""
    out: dict[str, str] = {}
    live = {""}
    table, last = "", None
    for raw in EXAMPLE.read_text(encoding="utf-8").splitlines():
        line = raw.strip()
        m = re.match(r"^#?\s*\[([\w.]+)\]\s*(?:#\s*(.*))?$", line)
        if m:
            table, last = m[1], None
            if not line.startswith("#"):
                live.add(table)
            if m[2]:
                out[table] = m[2].strip()
            continue
        m = re.match(r"^#?\s*([A-Za-z_]\w*)\s*=\s*(?:\{[^}]*\}|[^#])*?(?:#\s*(.*))?$", line)
        if m and not raw.startswith(" "):
            last = f"{table}.{m[1]}" if table else m[1]
            out[last] = (m[2] or "").strip()
            continue
        m = re.match(r"^#\s*(.*)$", line)
        if m and raw.startswith(" ") and last:
            out[last] = f"{out[last]} {m[1].strip()}".strip()
        elif not line:
            last = None
    return {k: _NOTE_REF.sub("", v).strip().rstrip(";,") for k, v in out.items()}, live


def configuration_md() -> str:
    """The configuration reference: one table per TOML table."""
    from impctl.config import Config

    tables: dict[str, list] = {}
    parents: dict[str, tuple] = {}
    _tables(Config, "", tables, parents)
    comments, live = _example_comments()
    parts = []
    for table, rows in tables.items():
        if not rows:
            continue
        title = f"`[{table}]`" if table else "Top level"
        parts.append(f"### {title}\n")
        about = comments.get(table, "")
        if table in parents and (table not in live or not about):
            holder, name = parents[table]
            about = _attribute_docs(holder).get(name, about)
        if about:
            parts.append(_escape(about) + "\n")
        parts.append("| key | default | unit | accepted (the validator's own words) | meaning |")
        parts.append("|---|---|---|---|---|")
        for key, f, hint, cls in rows:
            full = f"{table}.{key}" if table else key
            default = _default(f)
            if hint == "table":
                shown, accepted = "not set", "a table with the keys of `[heatpump]`"
            else:
                shown = "not set" if is_dataclass(default) else _fmt(default)
                accepted = _accepted(table, key, default, hint)
            documented = _attribute_docs(cls).get(key, "")
            example = comments.get(full, "")
            meaning = (example or documented) if table in live else (documented or example)
            parts.append(f"| `{key}` | {shown} | {_unit(key)} | {accepted} | {_escape(meaning)} |")
        parts.append("")
    return "\n".join(parts)


# -- the FLEET columns ------------------------------------------------------------------------

def fleet_columns_md() -> str:
    """The FLEET dataset's columns with their Arrow types, in file order."""
    from impctl.fleet.results.table import SCHEMA

    lines = ["| column | type |", "|---|---|"]
    lines += [f"| `{f.name}` | {f.type} |" for f in SCHEMA]
    return "\n".join(lines)
