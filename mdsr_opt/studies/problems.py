"""The study problems: strips stretched, bent, compressed and contracted, and library scenes."""

from __future__ import annotations

import math
import os
from pathlib import Path
from dataclasses import dataclass
from typing import Callable
import numpy as np

from ..body.material import LinearElastic, NeoHookean
from ..body.mesh import Mesh
from ..body.muscles import Muscle
from ..core.checks import did_you_mean

__all__ = ['Setup', 'StudyProblem', 'list_study_problems', 'get_study_problem', 'build_setup']


#: Material models by name, simplest first (the fidelity helper tries them in this order).
MATERIALS = {"linear": LinearElastic, "neo-hookean": NeoHookean}


#: Geometry of the study strip: length and width.
STRIP = (4.0, 1.0)


# ============================================================================================== problems
@dataclass
class Setup:
    """One problem instance: a body and how it is driven.

    Attributes
    ----------
    mesh : Mesh
    E, nu, thickness : float
        Material parameters (the material *model* is chosen per run).
    anchors : (k,) int array or None
        External driving: nodes held at rest.
    drags : (indices, positions) or None
        External driving: nodes moved to positions.
    muscles : tuple of Muscle
        Internal driving: the muscles.
    contractions : (m,) array or None
        Internal driving: their contractions (also the known answer of a design recovery).
    muscle_model, stiffness : as in :func:`~mdsr_opt.solve_internal`.
    """

    mesh: Mesh
    E: float = 1.0
    nu: float = 0.3
    thickness: float = 1.0
    anchors: np.ndarray | None = None
    drags: tuple | None = None
    muscles: tuple = ()
    contractions: np.ndarray | None = None
    muscle_model: str = "springs"
    stiffness: float = 10.0

    @property
    def mode(self) -> str:
        """``"internal"`` (muscles) or ``"external"`` (anchors and drags)."""
        return "internal" if self.contractions is not None else "external"

    def material(self, name: str):
        """The material model ``name`` (see :data:`MATERIALS`) with this setup's parameters."""
        return MATERIALS[check_name(name, MATERIALS, "material")](self.E, self.nu, self.thickness)


@dataclass(frozen=True)
class StudyProblem:
    """A study problem: a factory of setups by mesh resolution and load.

    Attributes
    ----------
    name, description : str
    build : callable ``(resolution, load) -> Setup``
        ``resolution`` is the approximate number of mesh nodes wanted.
    default_load : float
    load_label : str
        What ``load`` means, for tables and charts.
    design : bool
        Internal driving with known contractions: design methods can recover them.
    mirror : callable ``(k, 2) -> (k, 2)`` or None
        A reflection that maps the problem (rest body, supports and loads) onto itself: its solutions come
        in mirror pairs (a strip buckled up or down), compared as one (:func:`~mdsr_opt.studies.runs.fill_accuracy`).
    """

    name: str
    description: str
    build: Callable[[int, float], Setup]
    default_load: float
    load_label: str
    design: bool = False
    mirror: Callable[[np.ndarray], np.ndarray] | None = None


def _strip_mesh(resolution: int) -> Mesh:
    """A structured 4 x 1 strip with ``ny`` cells across, ``ny`` the power of two whose node count
    ``(4 ny + 1)(ny + 1)`` is nearest to ``resolution`` (27, 85, 297, 1105, 4257, ... nodes): the meshes nest,
    so every coarse node is a node of the finer meshes."""
    L, W = STRIP
    ny_est = (-5.0 + math.sqrt(25.0 + 16.0 * (max(resolution, 10) - 1.0))) / 8.0
    ny = 2 ** max(0, round(math.log2(max(ny_est, 1.0))))
    return Mesh.rectangle(L, W, round(L / W) * ny, ny)


def _ends(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    P = mesh.points
    return np.flatnonzero(P[:, 0] < 1e-9), np.flatnonzero(P[:, 0] > STRIP[0] - 1e-9)


def _arc(points: np.ndarray, angle: float) -> np.ndarray:
    """Strip points mapped onto a circular arc that bends the strip through ``angle`` radians (towards +y)."""
    L = STRIP[0]
    R = L / angle
    th = points[:, 0] / L * angle
    rr = R - points[:, 1]
    return np.column_stack([rr * np.sin(th), R - rr * np.cos(th)])


def _strip_mirror(p: np.ndarray) -> np.ndarray:
    """The reflection of the study strip about its mid-line ``y = W / 2``."""
    return np.column_stack([p[:, 0], STRIP[1] - p[:, 1]])


def _stretch(resolution: int, load: float) -> Setup:
    mesh = _strip_mesh(resolution)
    left, right = _ends(mesh)
    return Setup(mesh, anchors=left, drags=(right, mesh.points[right] + [load * STRIP[1], 0.0]))


def _bend(resolution: int, load: float) -> Setup:
    if not load > 0:
        raise ValueError(f"strip-bend needs a positive angle in degrees, got {load}")
    mesh = _strip_mesh(resolution)
    left, right = _ends(mesh)
    return Setup(mesh, anchors=left, drags=(right, _arc(mesh.points[right], math.radians(load))))


def _compress(resolution: int, load: float) -> Setup:
    mesh = _strip_mesh(resolution)
    left, right = _ends(mesh)
    return Setup(mesh, anchors=left, drags=(right, mesh.points[right] - [load * STRIP[0], 0.0]))


def _contract(resolution: int, load: float) -> Setup:
    if not 0 <= load < 1:
        raise ValueError(f"strip-contract needs a contraction in [0, 1), got {load}")
    mesh = _strip_mesh(resolution)
    P = mesh.points
    bottom = np.flatnonzero(P[:, 1] < 1e-9)
    bottom = bottom[np.argsort(P[bottom, 0])]
    return Setup(mesh, muscles=(Muscle(bottom, name="bottom"),), contractions=np.array([float(load)]))


#: The study's own problems (a 4 x 1 strip, E = 1, nu = 0.3).
PROBLEMS: dict[str, StudyProblem] = {p.name: p for p in (
    StudyProblem("strip-stretch", "left end anchored, right end pulled along the strip by `load` widths",
                 _stretch, 1.0, "stretch (widths)", mirror=_strip_mirror),
    StudyProblem("strip-bend", "left end anchored, right end dragged onto a circular arc of `load` degrees",
                 _bend, 90.0, "bend (degrees)"),
    StudyProblem("strip-compress", "left end anchored, right end pushed towards it by `load` lengths "
                 "(buckles beyond about 0.2)", _compress, 0.3, "compression (lengths)", mirror=_strip_mirror),
    StudyProblem("strip-contract", "free strip, a muscle along its lower edge contracts by `load`; design "
                 "methods recover the contraction", _contract, 0.3, "contraction", design=True),
)}


def _scene_problem(name: str) -> StudyProblem | None:
    """A problem-library case ``"<scene>/<case>"`` as a study problem (None when the library is absent).

    ``load`` scales the case: drag displacements (external) or contractions (internal); 1 is the case as
    written. ``resolution`` is passed to the scene's factory (approximate node count).
    """
    if "/" not in name:
        return None
    try:
        from ..scenes.library import get_problem, list_problems
    except ImportError:  # pragma: no cover - the library is optional
        return None
    scene_name, case_name = name.rsplit("/", 1)  # "<library scene>/<case>" or "<scene file path>/<case>"
    if scene_name not in list_problems() and not (is_scene_path(scene_name) and os.path.isfile(scene_name)):
        return None

    def build(resolution: int, load: float) -> Setup:
        sc = get_problem(scene_name, resolution=int(resolution))
        case = sc.case(case_name)
        mat = sc.material
        opts = sc.design_options
        common = dict(E=mat.E, nu=mat.nu, thickness=mat.thickness,
                      muscle_model=opts.get("muscle_model", "springs"), stiffness=opts.get("stiffness", 10.0))
        if case.kind == "internal":
            return Setup(sc.mesh, muscles=tuple(sc.muscles), contractions=load * case.contractions, **common)
        rest = sc.mesh.points[case.drag_nodes]
        return Setup(sc.mesh, anchors=case.anchors,
                     drags=(case.drag_nodes, rest + load * (case.drag_positions - rest)), **common)

    try:
        sc = get_problem(scene_name, resolution="coarse")
        case = sc.case(case_name)
    except (KeyError, ValueError):
        return None
    where = "scene file" if is_scene_path(scene_name) else "problem library: scene"
    return StudyProblem(name, f"{where} {scene_name!r}, case {case_name!r}", build, 1.0,
                        "load (x case)", design=case.kind == "internal")


def is_scene_path(name: str) -> bool:
    """Whether a scene named on the command line is a file (a scene file or a problem script, as
    :func:`~mdsr_opt.scenes.library.get_problem` reads it), not a library name."""
    return Path(name).suffix.lower() in (".py", ".toml", ".json")


def list_study_problems() -> list[str]:
    """Names of the study problems: the built-in strips, then ``scene/case`` of the problem library."""
    names = list(PROBLEMS)
    try:
        from ..scenes.library import get_problem, list_problems
    except ImportError:  # pragma: no cover
        return names
    for s in list_problems():
        try:
            sc = get_problem(s, resolution="coarse")
        except Exception:  # pragma: no cover - a broken library script must not break the study list
            continue
        names += [f"{s}/{c}" for c in sc.case_names]
    return names


def get_study_problem(name: str) -> StudyProblem:
    """A study problem by name; an unknown name is an error that lists the valid ones."""
    if not isinstance(name, str):
        raise TypeError(f"problem name must be a string, got {type(name).__name__}")
    if name in PROBLEMS:
        return PROBLEMS[name]
    p = _scene_problem(name)
    if p is None:
        valid = list_study_problems()
        hint = did_you_mean(name, valid)
        raise ValueError(f"unknown study problem {name!r}{hint}; valid: {', '.join(valid)}")
    return p


def build_setup(problem: str, resolution: int, load: float | None = None) -> Setup:
    """Build problem ``problem`` at ``resolution`` (approximate node count) and ``load`` (default: its own)."""
    p = get_study_problem(problem)
    return p.build(int(resolution), p.default_load if load is None else float(load))


def check_name(name, valid, what: str) -> str:
    if not isinstance(name, str) or name not in valid:
        raise ValueError(f"unknown {what} {name!r}; valid: {', '.join(valid)}")
    return name
