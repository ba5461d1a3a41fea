"""Shared scenes for the tests: small, fast, and each with a known answer.

Slow cases (``@pytest.mark.slow``) are left out of the default run. ``python -m pytest -m slow`` runs only
them, ``--slow`` runs everything; any ``-m`` expression decides on its own (the deselection below applies
only when no ``-m`` is given, so it never fights the command line).
"""

from __future__ import annotations

import importlib.util
import os
import signal
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")  # tests write figures, never show them (subprocesses inherit it)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from mdsr_opt import Mesh, NeoHookean

#: the project's root (benchmarks under tests/benchmarks, problem scripts under problems/)
ROOT = Path(__file__).resolve().parents[1]


def load_script(relative: str):
    """The module of a script that is no package (a benchmark, a problem script), by its path from the root:
    the tests check the cases those scripts define, so each case has one copy."""
    path = ROOT / relative
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


#: the head of a scene file of a 4 x 1 strip with its end regions ``left`` and ``right`` (scene-file tests add
#: their muscles and cases)
STRIP_HEAD = """name = "strip"
[body]
outline = [[0, 0], [4, 0], [4, 1], [0, 1]]
resolution = 80
[regions]
left = { box = [-0.1, -0.1, 0.1, 1.1] }
right = { box = [3.9, -0.1, 4.1, 1.1] }
"""


def outline_finger(folder) -> Path:
    """tests/data/finger.toml with its muscle moved onto the outline (not mouldable: a FabricationWarning),
    written into ``folder``."""
    text = (Path(__file__).parent / "data" / "finger.toml").read_text()
    path_line = next(line for line in text.splitlines() if line.startswith("path = "))
    scene = Path(folder) / "finger_outline.toml"
    scene.parent.mkdir(parents=True, exist_ok=True)
    scene.write_text(text.replace(path_line, "boundary = { from = [0, 1], to = [3.5, 1] }"))
    return scene


def pytest_sessionstart(session):
    """The Ctrl-C tests need Ctrl-C delivered: a suite started with SIGINT ignored (under ``nohup``, or as a
    background job of a non-interactive shell) gets Python's usual handler back, which the processes the
    tests start then inherit as the default. (tests/test_interrupt.py checks an ignored SIGINT on its own.)"""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_addoption(parser):
    parser.addoption("--slow", action="store_true", default=False,
                     help="also run the slow cases (by default they are left out unless -m selects them)")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--slow") or config.getoption("markexpr"):
        return
    slow = [it for it in items if it.get_closest_marker("slow") is not None]
    if slow:
        config.hook.pytest_deselected(items=slow)
        items[:] = [it for it in items if it.get_closest_marker("slow") is None]


@pytest.fixture(scope="session")
def strip():
    """A 4 x 1 strip meshed by Triangle (about 190 nodes)."""
    return Mesh.from_polygon([[0, 0], [4, 0], [4, 1], [0, 1]], max_area=0.02)


@pytest.fixture(scope="session")
def material():
    return NeoHookean(E=1.0, nu=0.3)


def ends(mesh, length=4.0):
    P = mesh.points
    left = np.nonzero(P[:, 0] < 1e-9)[0]
    right = np.nonzero(P[:, 0] > length - 1e-9)[0]
    return left, right


def arc_map(points, length=4.0, angle=np.pi / 2):
    """Map a strip's rest points onto a circular arc bending it through ``angle`` (towards +y)."""
    R = length / angle
    th = points[:, 0] / length * angle
    rr = R - points[:, 1]
    return np.column_stack([rr * np.sin(th), R - rr * np.cos(th)])


def rotation(theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def assert_matches_central_differences(energy, gradient, hessian, x, h=1e-6, gtol=1e-7, htol=1e-6):
    """``gradient`` against central differences of ``energy``, and ``hessian`` (dense) against those of
    ``gradient``, coordinate by coordinate at ``x``."""
    g, H = gradient(x), hessian(x)
    for k in range(len(x)):
        e = np.zeros(len(x))
        e[k] = h
        assert (energy(x + e) - energy(x - e)) / (2 * h) == pytest.approx(g[k], abs=gtol)
        assert np.allclose((gradient(x + e) - gradient(x - e)) / (2 * h), H[:, k], atol=htol)
