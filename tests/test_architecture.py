"""The package's house rules, checked on its source: folders by stage, no import circles, small modules."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import networkx as nx
import pytest

PKG = Path(__file__).resolve().parents[1] / "mdsr_opt"
MAX_LINES = 620  # "about 600 lines at most" per module

#: the stages of the data flow, lowest first; a module may import from its own stage and lower ones only
STAGES = ("core", "body", "mechanics", "plot", "synthesis", "photos", "scenes", "studies", "author", "cli")


@functools.lru_cache(maxsize=None)
def _parse(source: str) -> ast.Module:
    """The syntax tree of ``source``, parsed once for this module's tests (each walks the package's files; none
    changes a tree): eight of them parsed all 161 files again."""
    return ast.parse(source)


@pytest.fixture(scope="module", autouse=True)
def _forget_the_trees():
    yield
    _parse.cache_clear()  # about 85 MB of trees, not kept for the rest of the session
    _graph.cache_clear()


def _modules() -> dict[str, Path]:
    out = {}
    for p in PKG.rglob("*.py"):
        parts = p.relative_to(PKG).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(("mdsr_opt",) + parts)] = p
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]):
    """(imported module, imported names, line) for every import in the file, nested ones included."""
    is_pkg = path.name == "__init__.py"
    for node in ast.walk(_parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_pkg else name.split(".")[:-1]
                base = base[:len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if not target.startswith("mdsr_opt"):
                continue
            for a in node.names:
                sub = f"{target}.{a.name}"
                if sub in modules:  # `from . import plot`: the module itself
                    yield sub, [], node.lineno
                else:
                    yield target, [a.name], node.lineno
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("mdsr_opt"):
                    yield a.name, [], node.lineno


@functools.lru_cache(maxsize=None)
def _graph():
    """The package's import graph (read, never changed, by three tests) and its modules."""
    modules = _modules()
    g = nx.DiGraph()
    for name, path in modules.items():
        g.add_node(name)
        for target, _names, _line in _imports(name, path, modules):
            if target != name and target in modules:
                g.add_edge(name, target)
    return g, modules


def test_every_module_is_small():
    big = {n: len(p.read_text().splitlines()) for n, p in _modules().items()}
    assert {n: k for n, k in big.items() if k > MAX_LINES} == {}


def test_no_import_circles():
    g, _ = _graph()
    # a package's lazy __init__ imports nothing at the top; edges into a package are edges to its __init__
    cycles = list(nx.simple_cycles(g))
    assert cycles == []


def test_stages_import_only_downwards():
    g, _ = _graph()
    rank = {s: i for i, s in enumerate(STAGES)}
    bad = []
    for a, b in g.edges:
        sa, sb = a.split(".")[1:2], b.split(".")[1:2]
        if not sa or not sb or sa[0] not in rank or sb[0] not in rank:
            continue
        if rank[sb[0]] > rank[sa[0]]:
            bad.append(f"{a} -> {b}")
    assert bad == []


def test_figures_import_no_study_or_scene_code():
    g, _ = _graph()
    bad = [f"{a} -> {b}" for a, b in g.edges if a.startswith("mdsr_opt.plot")
           and (b.startswith("mdsr_opt.studies") or b.startswith("mdsr_opt.scenes"))]
    assert bad == []


def test_no_module_uses_another_modules_private_names():
    modules = _modules()
    bad = []
    for name, path in modules.items():
        for target, names, line in _imports(name, path, modules):
            if target == name:
                continue
            bad += [f"{name}:{line} imports {target}.{n}" for n in names
                    if n.startswith("_") and not n.startswith("__")]
    assert bad == []


def test_top_level_holds_only_folders_and_the_entry_points():
    files = sorted(p.name for p in PKG.glob("*.py"))
    assert files == ["__init__.py", "__main__.py"]
    assert sorted(p.name for p in PKG.iterdir() if p.is_dir() and p.name != "__pycache__") == sorted(STAGES)


@pytest.mark.parametrize("name", ["design", "align", "plot", "scenes", "studies"])
def test_package_level_names_do_not_clash_with_modules(name):
    import importlib

    import mdsr_opt

    value = getattr(mdsr_opt, name, None)
    if name in mdsr_opt.__all__:  # a public function of the package: never shadowed by a module
        for mod in list(_modules()):
            importlib.import_module(mod) if not mod.endswith("__main__") else None
        assert callable(value) and not isinstance(value, type(mdsr_opt))
    else:
        assert not hasattr(mdsr_opt, "__all__") or name not in mdsr_opt.__all__


def test_stage_packages_re_export_nothing():
    """One public name per object: a stage's ``__init__`` is its docstring only (``author``'s holds the
    server's own code), so a function is reached at the top level (what a user calls) or in its module."""
    bad = []
    for stage in STAGES:
        body = ast.parse((PKG / stage / "__init__.py").read_text()).body
        if stage == "author":
            bad += [f"author: {ast.unparse(n)}" for n in body if isinstance(n, ast.ImportFrom) and n.level == 1]
        elif not (len(body) == 1 and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)):
            bad.append(f"{stage}: {len(body)} statements")
    assert bad == []


def test_a_modules_public_names_are_its_own():
    """A module's ``__all__`` lists only what it defines: an object imported from another module stays
    public there alone (one public path per object besides the package's top level)."""
    bad = []
    for name, path in _modules().items():
        if name == "mdsr_opt":  # the package's own names: its stub (see the tests below)
            continue
        body = _parse(path.read_text()).body
        defined: set[str] = set()
        listed: list[str] = []
        for node in body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                defined.add(node.name)
            elif isinstance(node, (ast.Assign, ast.AnnAssign)):
                for t in node.targets if isinstance(node, ast.Assign) else [node.target]:
                    if isinstance(t, ast.Name):
                        defined.add(t.id)
                        if t.id == "__all__":
                            listed = list(ast.literal_eval(node.value))
        bad += [f"{name}.{n}" for n in listed if n not in defined]
    assert bad == []


def _stub_names() -> dict[str, str]:
    """public name -> module, as ``mdsr_opt/__init__.pyi`` lists them (what type checkers see)."""
    out: dict[str, str] = {}
    for node in ast.parse((PKG / "__init__.pyi").read_text()).body:
        if isinstance(node, ast.ImportFrom):
            assert node.level == 1 and node.module, ast.unparse(node)
            for a in node.names:
                assert a.asname in (None, a.name), f"{a.name} renamed to {a.asname}"  # no second name
                assert a.name not in out, f"{a.name} listed twice"
                out[a.name] = f"mdsr_opt.{node.module}"
    return out


def test_the_stub_and_the_runtime_exports_agree():
    """Type checkers read ``__init__.pyi``; ``import mdsr_opt`` exports the same names, each the object of
    its defining module, and no object under two names."""
    import importlib

    import mdsr_opt

    stub = _stub_names()
    assert len(stub) >= 60
    assert sorted(mdsr_opt.__all__) == sorted([*stub, "__version__"])
    assert dir(mdsr_opt) == sorted(mdsr_opt.__all__)
    objects = {}
    for name, module in stub.items():
        value = getattr(mdsr_opt, name)
        assert value is getattr(importlib.import_module(module), name)
        assert getattr(value, "__module__", module) == module, f"{name} is defined in {value.__module__}"
        assert id(value) not in objects, f"{name} and {objects.get(id(value))} are one object"
        objects[id(value)] = name
    with pytest.raises(AttributeError):
        getattr(mdsr_opt, "design")  # the pipeline has one name: design_pipeline


def test_importing_the_package_imports_no_numerics():
    """``import mdsr_opt`` reads the stub and imports nothing heavy (numpy, CasADi, matplotlib...)."""
    import subprocess
    import sys

    heavy = ("numpy", "scipy", "casadi", "matplotlib", "networkx", "cv2", "meshio", "shapely")
    code = ("import sys, mdsr_opt; print(' '.join(sorted(m for m in sys.modules if m.split('.')[0] in "
            f"{heavy!r} or m.startswith('mdsr_opt.'))))")
    out = subprocess.run([sys.executable, "-c", code], cwd=PKG.parent, capture_output=True, text=True, check=True)
    assert out.stdout.split() == []


@pytest.mark.parametrize("package", ["mdsr_opt"] + [f"mdsr_opt.{s}" for s in STAGES])
def test_every_public_name_resolves(package):
    """Each name a package lists in ``__all__`` (or its lazy export table) imports and is the object of
    that name in its owning module (a wrong module path in an export table is only found when used)."""
    import importlib

    pkg = importlib.import_module(package)
    names = [n for n in getattr(pkg, "__all__", []) if not n.startswith("__")]
    broken = []
    for name in names:
        try:
            value = getattr(pkg, name)
        except (AttributeError, ImportError) as exc:
            broken.append(f"{name}: {exc}")
            continue
        assert value is not None, name
    assert not broken, f"{package}: " + "; ".join(broken)



#: modules that exist only on POSIX systems: never imported when a module of the package is imported
POSIX_ONLY = {"resource", "fcntl", "termios", "pwd", "grp"}
#: process machinery the package does without (import hooks, heap freezing, /proc, bare forks)
MACHINERY = {("gc", "freeze"), ("gc", "disable"), ("sys", "meta_path"), ("os", "fork")}


def _import_time_nodes(tree: ast.AST):
    """The nodes a module runs when it is imported: everything outside function bodies (class bodies run,
    and so do decorators and default values)."""
    todo = list(ast.iter_child_nodes(tree))
    while todo:
        node = todo.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            todo += node.decorator_list + node.args.defaults + [d for d in node.args.kw_defaults if d]
            continue
        if isinstance(node, ast.Lambda):
            continue
        yield node
        todo += ast.iter_child_nodes(node)


def _posix_imports(source: str) -> list[str]:
    """``line module`` of every import of a POSIX-only module that runs at import time."""
    found = []
    for node in _import_time_nodes(_parse(source)):
        if isinstance(node, ast.Import):
            found += [f"{node.lineno} {a.name}" for a in node.names if a.name.split(".")[0] in POSIX_ONLY]
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module.split(".")[0] in POSIX_ONLY:
            found.append(f"{node.lineno} {node.module}")
    return found


def _machinery(source: str) -> list[str]:
    """``line what`` of every use of :data:`MACHINERY` or mention of /proc/self, anywhere in the source."""
    found = []
    for node in ast.walk(_parse(source)):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                and (node.value.id, node.attr) in MACHINERY:
            found.append(f"{node.lineno} {node.value.id}.{node.attr}")
        elif isinstance(node, ast.ImportFrom) and any((node.module, a.name) in MACHINERY for a in node.names):
            found.append(f"{node.lineno} from {node.module} import")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and "/proc/self" in node.value:
            found.append(f"{node.lineno} {node.value[:40]!r}")
    return found


def test_no_module_imports_a_posix_only_module_at_import_time():
    # the check itself: top level, in a try or a class body counts; inside a function it does not
    assert sorted(_posix_imports("import os\ntry:\n    import fcntl\nexcept ImportError:\n    pass\n"
                                 "class A:\n    from resource import getrusage\n"
                                 "def f():\n    import pwd\n")) == ["3 fcntl", "7 resource"]
    bad = {name: found for name, path in _modules().items() if (found := _posix_imports(path.read_text()))}
    assert bad == {}


def test_no_module_uses_process_machinery():
    """No gc.freeze or gc.disable, no import hook on sys.meta_path, nothing read from /proc/self, no os.fork,
    anywhere in the package (at import time or not)."""
    assert sorted(_machinery("import gc, os\ndef f():\n    gc.freeze()\n    open('/proc/self/maps')\n"
                             "    return os.fork()\nfrom sys import meta_path\n")) == [
        "3 gc.freeze", "4 '/proc/self/maps'", "5 os.fork", "6 from sys import"]
    bad = {name: found for name, path in _modules().items() if (found := _machinery(path.read_text()))}
    assert bad == {}


#: warnings that announce an old spelling kept for a while: nothing was released, so none is kept
DEPRECATIONS = {"DeprecationWarning", "PendingDeprecationWarning", "FutureWarning"}


def test_no_module_keeps_deprecated_spellings():
    """No module issues (or names) a deprecation warning, and the keyword-renaming shim is gone."""
    bad = []
    for name, path in _modules().items():
        for node in ast.walk(_parse(path.read_text())):
            ident = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else None
            if ident in DEPRECATIONS:
                bad.append(f"{name}:{node.lineno} {ident}")
    assert bad == []
    assert not (PKG / "core" / "deprecation.py").exists()
    assert not any("deprecat" in p.read_text().lower() for p in _modules().values())


def test_every_file_compiles_without_warnings():
    """No invalid escape sequence or other compile-time warning (a SyntaxError in a later Python)."""
    import warnings

    bad = []
    for path in sorted([*PKG.rglob("*.py"), *PKG.parent.joinpath("tests").rglob("*.py"),
                        *PKG.parent.joinpath("problems").rglob("*.py")]):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            compile(path.read_text(), str(path), "exec")
        bad += [f"{path.name}:{w.lineno} {w.message}" for w in caught]
    assert bad == []
