"""Lazy package exports: a package names its public objects and the module of the package that owns each;
the module is imported on first use, so importing a package stays cheap and creates no import circles."""

from __future__ import annotations

import importlib
from typing import Callable, Mapping

__all__ = ["lazy_exports"]


def lazy_exports(package: str, exports: Mapping[str, str], namespace: dict) -> tuple[Callable, Callable]:
    """``(__getattr__, __dir__)`` for package ``package`` whose public name ``n`` lives in module
    ``package + "." + exports[n]``; a looked-up value is cached in ``namespace`` (the package's globals).

    Example
    -------
    >>> g, d = lazy_exports("mdsr_opt.body", {"Mesh": "mesh"}, {})
    >>> g("Mesh").__name__, d()
    ('Mesh', ['Mesh'])
    """
    names = sorted(exports)

    def __getattr__(name: str):
        mod = exports.get(name)
        if mod is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{mod}", package), name)
        namespace[name] = value
        return value

    def __dir__():
        return list(names)

    return __getattr__, __dir__
