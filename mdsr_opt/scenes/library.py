"""The problem-library registry: where the scripts live, listing them, building a scene by name or path."""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

from .scene import Scene, UnknownName, resolve_resolution
from .scenefile import load_scene, remeshable
from ..core.checks import did_you_mean

__all__ = ['load_problem_module', 'problems_dir', 'figure_scripts', 'list_problems', 'get_problem', 'remeshable_source']


def load_problem_module(path: str | os.PathLike):
    """Load a problem script as a module by file path (e.g. to reuse a body's outline in another scene)."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"no such problem script: {p}")
    return load_module(p)


# ---------------------------------------------------------------------------------------------- registry
def problems_dir() -> Path | None:
    """The folder of problem scripts.

    In order: the environment variable ``MDSR_PROBLEMS``; the package ``mdsr_opt.problems`` of an installed
    wheel (the build maps the checkout's top-level ``problems/`` folder into the package, found through
    :mod:`importlib`); the ``problems/`` folder of the source checkout the package was imported from (running
    from the repository). ``None`` when there is none.
    """
    env = os.environ.get("MDSR_PROBLEMS")
    if env:
        p = Path(env)
        if not p.is_dir():
            raise FileNotFoundError(f"MDSR_PROBLEMS={env!r} is not a folder")
        return p
    try:
        spec = importlib.util.find_spec("mdsr_opt.problems")
    except ImportError:  # pragma: no cover - a broken parent package
        spec = None
    if spec is not None and spec.submodule_search_locations:
        for loc in spec.submodule_search_locations:
            if Path(loc).is_dir():
                return Path(loc)
    here = Path(__file__).resolve().parents[2] / "problems"
    if here.is_dir():
        return here
    return None


def _library_files() -> dict[str, Path]:
    d = problems_dir()
    if d is None:
        return {}
    return {p.stem: p for p in sorted(d.glob("*.py")) if not p.stem.startswith("_")}


def _is_figure(path: Path) -> bool:
    """A figure script (e.g. ``figure6.py``): defines ``run_figure(out, ...)`` instead of a ``build``."""
    text = path.read_text()
    return "\ndef run_figure(" in text and "\ndef build(" not in text


def problem_files() -> dict[str, Path]:
    return {k: p for k, p in _library_files().items() if not _is_figure(p)}


def figure_scripts() -> dict[str, Path]:
    """The library's figure scripts (``mdsr run NAME`` calls their ``run_figure(out, resolution, log)``)."""
    return {k: p for k, p in _library_files().items() if _is_figure(p)}


def list_problems() -> list[str]:
    """Names of the scenes in the problem library (sorted)."""
    return sorted(problem_files())


def load_module(path: Path):
    key = f"mdsr_problem_{path.stem}_{abs(hash(str(path.resolve())))}"
    mod = sys.modules.get(key)
    if mod is not None:
        return mod
    spec = importlib.util.spec_from_file_location(key, path)
    if spec is None or spec.loader is None:
        raise ValueError(f"cannot load {path} as a Python module")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[key] = mod
    try:
        spec.loader.exec_module(mod)
    except BaseException:
        sys.modules.pop(key, None)
        raise
    return mod


def build_from(path: Path, resolution) -> Scene:
    mod = load_module(path)
    build = getattr(mod, "build", None)
    if not callable(build):
        raise ValueError(f"{path} defines no factory build(resolution=...) -> Scene")
    scene = build() if resolution is None else build(resolution=resolution)  # None: the script's own default
    if not isinstance(scene, Scene):
        raise TypeError(f"{path}: build() must return a Scene, got {type(scene).__name__}")
    if not scene.source:
        scene.source = str(path)
    return scene


def get_problem(name: str | os.PathLike, resolution: str | int | None = None) -> Scene:
    """Build a scene by library name, from a problem script path, or from a scene file.

    Parameters
    ----------
    name : str or path
        A name from :func:`list_problems`, a ``.py`` file with a ``build`` factory, or a ``.toml`` /
        ``.json`` scene file (:func:`load_scene`).
    resolution : {"coarse", "medium", "fine"} or int, optional
        Approximate node count (see the module docstring); default: the script's own ``build`` default
        (``"medium"`` for the library's scenes, ``"coarse"`` for ``gripper_hold``, whose solves are contact
        solves) and the file's own ``body.resolution`` (or ``max_area``) for scene files. A resolution given
        re-meshes a scene file's outline; a scene file whose body is a mesh file refuses one.

    Raises
    ------
    UnknownName (a KeyError and a ValueError)
        An unknown name (the message lists the library).
    FileNotFoundError
        A path that does not exist.
    """
    if resolution is not None:
        resolve_resolution(resolution)
    s = os.fspath(name)
    p = Path(s)
    if p.suffix.lower() in (".py", ".toml", ".json") or os.sep in s or "/" in s:
        if not p.exists():
            raise FileNotFoundError(f"no such scene file: {s}")
        if p.is_dir():
            raise ValueError(f"{s} is a folder, not a scene: give a problem name, a problem script (.py) or a "
                             "scene file (.toml/.json)")
        if p.suffix.lower() == ".py":
            return build_from(p, resolution)
        return load_scene(p, resolution=resolution)
    files = problem_files()
    if s not in files:
        where = problems_dir()
        lib = ", ".join(files) if files else f"none found (problems folder: {where})"
        hint = did_you_mean(s, files)
        raise UnknownName(f"unknown problem {s!r}{hint}; the library has: {lib}")
    return build_from(files[s], resolution)


def remeshable_source(name: str | os.PathLike) -> bool:
    """Whether :func:`get_problem` can build the scene ``name`` at another resolution: a library name or a
    script (its ``build`` takes the resolution), or a scene file whose body is an outline (not a mesh file:
    :func:`~mdsr_opt.scenes.scenefile.remeshable`)."""
    p = Path(os.fspath(name))
    return remeshable(p) if p.suffix.lower() in (".toml", ".json") and p.exists() else True
