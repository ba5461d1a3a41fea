"""Every ``mdsr_opt.`` dotted path named in the tree (docstrings, comments, messages, output strings, the
README, scene and data files) names something that exists: a module, or an attribute reached from one."""

from __future__ import annotations

import importlib
import inspect
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SUFFIXES = {".py", ".md", ".toml", ".json", ".js", ".html", ".txt", ".csv", ".cfg", ".css", ".yml", ".yaml"}
#: a dotted path starting at the package; a match followed by ``/`` is a file-format tag
#: (``"mdsr_opt.poses/1"``), a name kept stable for files written earlier, not a module path
DOTTED = re.compile(r"(?<![\w.])mdsr_opt(?:\.[A-Za-z_]\w*)+")


def _text_files() -> list[Path]:
    try:
        names = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                               check=True).stdout.splitlines()
        files = [ROOT / n for n in names]
    except (OSError, subprocess.CalledProcessError):  # not a git checkout (an unpacked sdist)
        files = [p for p in ROOT.rglob("*") if p.is_file() and ".git" not in p.parts]
    return [p for p in files if p.suffix in SUFFIXES and "__pycache__" not in p.parts and p.is_file()]


def _references() -> dict[str, list[str]]:
    """``{dotted path: ["file:line", ...]}`` over the tracked text files."""
    found: dict[str, list[str]] = {}
    for path in _text_files():
        text = path.read_text(encoding="utf-8", errors="replace")
        for lineno, line in enumerate(text.splitlines(), 1):
            for m in DOTTED.finditer(line):
                if line[m.end():m.end() + 1] == "/":
                    continue
                found.setdefault(m.group(0), []).append(f"{path.relative_to(ROOT)}:{lineno}")
    return found


def _instance_attribute(cls: type, name: str) -> bool:
    """``name`` is a dataclass field, an annotated attribute or set as ``self.name`` in a method of ``cls``
    (or of a base class): it exists on instances but not necessarily on the class."""
    for klass in cls.__mro__:
        if klass is object:
            continue
        if name in getattr(klass, "__dataclass_fields__", {}) or name in vars(klass).get("__annotations__", {}):
            return True
        try:
            source = inspect.getsource(klass)
        except (OSError, TypeError):
            continue
        if re.search(rf"\bself\.{re.escape(name)}\s*(:[^=\n]*)?=(?!=)", source):
            return True
    return False


def resolves(dotted: str) -> bool:
    """Import the longest module prefix of ``dotted``, then look up the rest as attributes.

    ``mdsr_opt.problems`` is the checkout's top-level ``problems/`` folder, which only an installed package
    (or an editable install) has inside ``mdsr_opt``: a test run from a checkout over a regular install
    imports the source tree's ``mdsr_opt``, so its paths are resolved in that folder instead."""
    parts = dotted.split(".")
    if parts[:2] == ["mdsr_opt", "problems"]:
        if len(parts) == 2:
            return (ROOT / "problems" / "__init__.py").is_file()
        return (ROOT / "problems" / f"{parts[2]}.py").is_file()  # a problem script (its names unchecked)
    for i in range(len(parts), 0, -1):
        name = ".".join(parts[:i])
        try:
            obj = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name is not None and name.startswith(exc.name):  # this prefix is no module: try a shorter one
                continue
            raise  # the module exists but needs something missing: a real error, not a stale reference
        for attr in parts[i:]:
            if hasattr(obj, attr):
                obj = getattr(obj, attr)
            elif isinstance(obj, type) and _instance_attribute(obj, attr) and attr == parts[-1]:
                return True
            else:
                return False
        return True
    return False


def test_the_resolver_tells_real_paths_from_stale_ones():
    assert resolves("mdsr_opt.mechanics.equilibrium.solve_internal")
    assert resolves("mdsr_opt.mechanics.model.EnergyModel.is_numeric")  # set in __init__
    assert resolves("mdsr_opt.Mesh")  # a lazy export of the package
    pkg = "mdsr_opt"  # spelled apart, so that the scan of this file does not find these stale paths
    assert not resolves(pkg + ".evaluate.render_photo")  # the old flat layout
    assert not resolves(pkg + ".mechanics.equilibrium.no_such_function")
    assert not resolves(pkg + ".mechanics.model.EnergyModel.no_such_attribute")
    assert resolves(pkg + ".problems") and resolves(pkg + ".problems.gecko")  # the checkout's problems/
    assert not resolves(pkg + ".problems.no_such_robot")
    refs = _references()
    assert len(refs) > 50 and "mdsr_opt.photos.camera.render_photo" in refs


def test_every_dotted_path_in_the_tree_resolves():
    stale = {name: where for name, where in sorted(_references().items()) if not resolves(name)}
    assert stale == {}, "stale module paths (name: file:line):\n" + "\n".join(
        f"{name}: {', '.join(where)}" for name, where in stale.items())


@pytest.mark.parametrize("line", ['"format": "mdsr_opt.poses/1"', "see mdsr_opt/scenes/rundir.py"])
def test_format_tags_and_file_paths_are_not_module_paths(line):
    assert [m.group(0) for m in DOTTED.finditer(line) if line[m.end():m.end() + 1] != "/"] == []
