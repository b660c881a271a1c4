"""Lazy names for the pipeline packages, so that importing one stays light (no torch, no
scikit-learn, no pandas until a name that needs them is used)."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable
from typing import Any


def attach(package: str, submod_attrs: dict[str, list[str]]
           ) -> tuple[Callable[[str], Any], Callable[[], list[str]], list[str]]:
    """Module-level ``__getattr__``, ``__dir__`` and the lazy names of ``package``.

    ``submod_attrs`` maps a submodule to the names it provides. A resolved name is stored in
    the package's namespace, so a function named like a submodule stays
    the function after the submodule is imported.
    """
    where = {name: mod for mod, names in submod_attrs.items() for name in names}

    def __getattr__(name: str) -> Any:
        module = where.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(where))

    return __getattr__, __dir__, list(where)
