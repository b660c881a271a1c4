"""What `pip install .` (a wheel, not the editable checkout) ships: every package and data file."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _config() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def test_every_package_under_src_is_listed():
    """The package list is explicit: a new package left out of it works in the editable
    checkout and is missing from a gateway's wheel (ImportError at the first night)."""
    listed = set(_config()["packages"])
    found = {".".join(p.parent.relative_to(ROOT / "src").parts)
             for p in (ROOT / "src").rglob("__init__.py")}
    assert found - listed == set(), f"not in pyproject.toml packages: {sorted(found - listed)}"
    assert {p for p in listed if p.startswith("impctl.")} <= found


def test_every_data_file_is_shipped():
    """Non-Python files next to the code are read at run time: each must match package-data."""
    import fnmatch

    data = _config().get("package-data", {})
    for path in (ROOT / "src" / "impctl").rglob("*"):
        if path.is_dir() or path.suffix in (".py", ".pyc", ".md") or "__pycache__" in path.parts:
            continue
        rel = path.relative_to(ROOT / "src")
        package = ".".join(rel.parent.parts)
        patterns = data.get(package, [])
        # A pattern of a parent package may name the file by a sub-path ("data/*.toml").
        parents = [(".".join(rel.parts[:i]), "/".join(rel.parts[i:])) for i in range(1, len(
            rel.parts))]
        ok = any(fnmatch.fnmatch(sub, pat) for pkg, sub in parents
                 for pat in data.get(pkg, [])) or any(fnmatch.fnmatch(path.name, p)
                                                       for p in patterns)
        assert ok, f"{rel} is not in [tool.setuptools.package-data]"
