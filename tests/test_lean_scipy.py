"""SciPy's NumPy clone imported without NumPy's lazy submodules (mdsr_opt.core.lean_scipy)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(code: str) -> dict:
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


_REPORT = """
import json, sys, numpy
import scipy._lib.array_api_compat.numpy as clone
from mdsr_opt.core import lean_scipy
print(json.dumps({
    "loaded": sorted(m for m in sys.modules if m.startswith("numpy.") and m.count(".") == 1),
    "all": sorted(numpy.__all__), "dir": sorted(dir(numpy)),
    "clone": sorted(n for n in dir(clone) if not n.startswith("_")),
    "finders": sum(type(f).__name__ == "_Finder" for f in sys.meta_path),
    "sparse_works": float(__import__("scipy.sparse").sparse.identity(3).sum()),
}))
"""


def test_scipy_clone_leaves_numpys_lazy_submodules_unloaded_and_numpy_as_it_was():
    plain = _run("import scipy.sparse" + _REPORT)
    lean = _run("import mdsr_opt, scipy.sparse" + _REPORT)
    hidden = {"numpy." + n for n in ("f2py", "testing", "ma", "polynomial", "ctypeslib", "rec", "char")}
    assert hidden <= set(plain["loaded"])  # what the clone costs without the finder
    assert not hidden & set(lean["loaded"])
    # numpy itself is as it was: the same public names and listing (as sets: numpy builds __all__ from a
    # set), restored after the clone's import
    assert lean["all"] == plain["all"] and lean["dir"] == plain["dir"]
    # the clone lacks only the hidden submodules: the array API's namespaces and functions are there
    from mdsr_opt.core.lean_scipy import LAZY_SUBMODULES

    missing = set(plain["clone"]) - set(lean["clone"])
    assert {n.split(".")[1] for n in hidden} <= missing <= LAZY_SUBMODULES
    assert {"linalg", "fft", "asarray", "sum", "float64"} <= set(lean["clone"])
    assert lean["finders"] == 0 and lean["sparse_works"] == 3.0  # the finder left once it had served


def test_a_process_with_scipy_imported_first_or_a_submodule_loaded_keeps_it():
    first = _run("import scipy.sparse; from mdsr_opt.core import lean_scipy; ok = lean_scipy.install()" + _REPORT
                 + "\nprint(json.dumps(ok))")
    assert first is False  # the clone exists already: no finder
    # a lazy submodule loaded before the clone is imported stays in the clone (it costs nothing)
    loaded = _run("import numpy.ma, mdsr_opt, scipy.sparse" + _REPORT)
    assert "ma" in loaded["clone"] and "f2py" not in loaded["clone"]


_EDITABLE_LIKE = '''
import importlib.machinery as m, importlib.util, os, sys
ROOT = os.path.dirname(os.path.dirname(importlib.util.find_spec("scipy").origin))
LOADERS = [(m.ExtensionFileLoader, s) for s in m.EXTENSION_SUFFIXES] + [(m.SourceFileLoader, ".py")]

class Finder:  # serves scipy as an editable install's finder does: packages' paths lead nowhere
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] != "scipy":
            return None
        base = os.path.join(ROOT, *name.split("."))
        for loader, suf in LOADERS:
            init = os.path.join(base, "__init__" + suf)
            if os.path.isfile(init):
                spec = importlib.util.spec_from_file_location(name, init, loader=loader(name, init),
                                                              submodule_search_locations=["/nowhere"])
                return spec
            if os.path.isfile(base + suf):
                return importlib.util.spec_from_file_location(name, base + suf, loader=loader(name, base + suf))
        return None

sys.meta_path.insert(0, Finder())
'''


def test_scipy_served_by_another_finder_on_the_meta_path_is_found_through_it():
    """The finder asks the finders after it (an editable SciPy's, say), and leaves sys.meta_path alone while
    the import system walks it: taking itself off there made the import skip the next finder."""
    out = _run(_EDITABLE_LIKE + "import mdsr_opt, scipy.sparse" + _REPORT)
    assert out["sparse_works"] == 3.0 and out["finders"] == 0
    assert "numpy.f2py" not in out["loaded"]
