"""SciPy imported without NumPy's lazily loaded submodules.

``scipy.sparse`` (1.14 and later) imports SciPy's copy of ``array_api_compat``, whose NumPy namespace is a
clone of ``numpy``: it imports every name of ``numpy.__all__`` and reads every name ``dir(numpy)`` lists.
Since NumPy 2 those names include submodules that NumPy loads only when first used (``numpy.f2py``,
``numpy.testing``, ``numpy.ma``, ``numpy.polynomial``, ...), so the clone imports them all: 0.17 of the 0.46
s that ``import mdsr_opt.cli.run`` took here, on every command's way to its first solve. None of them
belongs to the array API, and SciPy reaches them through ``numpy`` itself, never through the clone.

:func:`install` (called when ``mdsr_opt`` is imported) puts a finder on ``sys.meta_path`` that, when that
clone's module is imported, hides those submodules from ``numpy.__all__`` and ``dir(numpy)`` while the
module runs, and restores both at once. Nothing else changes: NumPy still loads each submodule on first
use, and a process that imported SciPy before ``mdsr_opt`` keeps what it has. (While the clone's module
runs, about 0.1 s, another thread that lists ``numpy``'s names would miss those submodules too.)
"""

from __future__ import annotations

import importlib.abc
import sys

__all__ = ["install", "LAZY_SUBMODULES", "CLONE"]

#: SciPy's module that clones ``numpy`` (``scipy/_lib/array_api_compat/numpy/__init__.py``)
CLONE = "scipy._lib.array_api_compat.numpy"

#: NumPy's submodules that are loaded on first use and are no part of the array API: left out of the clone
LAZY_SUBMODULES = frozenset({"f2py", "testing", "ctypeslib", "rec", "char", "ma", "polynomial", "matrixlib",
                             "core", "strings"})


class _Loader(importlib.abc.Loader):
    """The clone's own loader, with NumPy's lazy submodules hidden while its module runs."""

    def __init__(self, loader):
        self._loader = loader

    def create_module(self, spec):
        return self._loader.create_module(spec)

    def exec_module(self, module):
        import numpy

        names, listing = numpy.__dict__.get("__all__"), numpy.__dict__.get("__dir__")
        hidden = [n for n in LAZY_SUBMODULES if f"numpy.{n}" not in sys.modules]  # loaded ones cost nothing
        try:
            if isinstance(names, list):
                numpy.__all__ = [n for n in names if n not in hidden]
            if callable(listing):
                numpy.__dir__ = lambda: [n for n in listing() if n not in hidden]
            self._loader.exec_module(module)
        finally:
            if isinstance(names, list):
                numpy.__all__ = names
            if callable(listing):
                numpy.__dir__ = listing
            uninstall()  # here, not in find_spec: the import system is done walking sys.meta_path


class _Finder(importlib.abc.MetaPathFinder):
    """Finds :data:`CLONE` with the finders after it on ``sys.meta_path`` and wraps its loader (once)."""

    served = False

    def find_spec(self, name, path=None, target=None):
        if name != CLONE or self.served:
            return None
        self.served = True  # a failed or repeated import goes the usual way
        finders = list(sys.meta_path)
        spec = None
        for finder in finders[finders.index(self) + 1:] if self in finders else finders:
            find = getattr(finder, "find_spec", None)
            spec = find(name, path, target) if find is not None else None
            if spec is not None:
                break
        if spec is not None and spec.loader is not None and hasattr(spec.loader, "exec_module"):
            spec.loader = _Loader(spec.loader)
        return spec


def install() -> bool:
    """Put the finder on ``sys.meta_path`` unless SciPy's clone was imported already (or the finder is
    there); True when it is there afterwards."""
    if CLONE in sys.modules:
        return False
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.insert(0, _Finder())
    return True


def uninstall() -> None:
    """Take the finder off ``sys.meta_path`` (if it is there)."""
    sys.meta_path[:] = [f for f in sys.meta_path if not isinstance(f, _Finder)]
