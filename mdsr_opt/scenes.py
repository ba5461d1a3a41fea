"""Scenes: the problem library's data model, its registry and the scene-file format.

A :class:`Scene` is everything a designer states about one soft robot: the body (mesh and material),
named node regions, and a list of :class:`Case` s, each one deformation to design for. A case is either

- **external** (``kind == "external"``): anchors held at rest and drag nodes moved to given positions; the
  external-driving equilibrium is the target shape, muscles are routed on it (unless the scene gives
  them) and their contractions designed; or
- **internal** (``kind == "internal"``): the scene's muscles contract by given amounts (the paper's one-,
  two- and four-muscle experiments); the internal-driving equilibrium is the target and the design must
  recover the contractions, a problem with a known answer.

Scenes come from three places, all through :func:`get_problem`:

1. the problem library, one script per scene in the ``problems/`` folder of a source checkout, each with a
   factory ``build(resolution="medium") -> Scene`` (see :func:`problems_dir` for how the folder is found);
2. a Python file path, whose ``build`` is called the same way;
3. a scene file (TOML or JSON, :func:`load_scene`) for users who do not write Python.

:func:`prepare_case` turns a case into a design problem ``(target, muscles)`` for any design method
(the solver-comparison studies use it); :func:`run_scene` runs the whole pipeline and writes figures,
meshes, photographs and a JSON summary.

Resolution
----------
Every factory takes ``resolution``: ``"coarse"`` (about 150 nodes, for tests), ``"medium"`` (about 600,
the default), ``"fine"`` (about 2400), or an integer, the approximate number of mesh nodes wanted.
:func:`mesh_polygon` meets it to within about 15 %.

Example
-------
>>> from mdsr_opt.scenes import get_problem, list_problems
>>> "gecko" in list_problems()
True
>>> scene = get_problem("gecko", resolution="coarse")
>>> [c.name for c in scene.cases]
['bend_left', 'bend_right']
"""

from __future__ import annotations

import importlib.util
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ._checks import as_float_array, as_index_array
from .mesh import Mesh, polygon_area
from .muscles import Muscle, check_muscles

__all__ = ["load_scene", "RESOLUTIONS", "Case", "Animation", "Scene", "CaseSetup", "list_problems", "get_problem",
           "problems_dir", "resolve_resolution", "mesh_polygon", "prepare_case", "nodes_in_box",
           "nodes_near", "nearest_node", "nodes_in_polygon", "edge_path", "arc_map", "rigid_motion"]

#: Named resolutions: approximate number of mesh nodes.
RESOLUTIONS = {"coarse": 150, "medium": 600, "fine": 2400}

#: Said in every problem script: the paper gives no geometry, so the shapes are ours.
SHAPES_ARE_OURS = ("The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no "
                   "geometry); they are not the paper's meshes.")


# ---------------------------------------------------------------------------------------------- data model
@dataclass(frozen=True, eq=False)
class Case:
    """One target deformation of a scene.

    Parameters
    ----------
    name : str
        A short identifier (used for output folders): letters, digits, ``_`` and ``-``.
    anchors : (k,) int array
        External case: nodes held at their rest positions.
    drag_nodes, drag_positions : (d,) int and (d, 2) float arrays
        External case: nodes moved to these positions.
    contractions : (m,) float array, optional
        Internal case: one contraction per scene muscle; the internal-driving equilibrium is the target.
    description : str
        One line for reports.
    """

    name: str
    anchors: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    drag_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    drag_positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    contractions: np.ndarray | None = None
    description: str = ""

    def __post_init__(self):
        _check_name(self.name, "case name")
        anc = as_index_array(np.asarray(self.anchors), f"case {self.name!r}: anchors", shape=(None,))
        dn = as_index_array(np.asarray(self.drag_nodes), f"case {self.name!r}: drag_nodes", shape=(None,))
        dp = as_float_array(np.asarray(self.drag_positions, dtype=float).reshape(-1, 2) if np.size(
            self.drag_positions) else np.zeros((0, 2)), f"case {self.name!r}: drag_positions", shape=(len(dn), 2))
        object.__setattr__(self, "anchors", anc)
        object.__setattr__(self, "drag_nodes", dn)
        object.__setattr__(self, "drag_positions", dp)
        if self.contractions is not None:
            a = as_float_array(np.atleast_1d(self.contractions), f"case {self.name!r}: contractions",
                               shape=(None,))
            if len(anc) or len(dn):
                raise ValueError(f"case {self.name!r}: give either contractions (internal driving) or "
                                 "anchors/drags (external driving), not both")
            if np.any((a < 0) | (a >= 1)):
                raise ValueError(f"case {self.name!r}: contractions must lie in [0, 1), got {a.tolist()}")
            object.__setattr__(self, "contractions", a)
        elif len(anc) + len(dn) < 2:
            raise ValueError(f"case {self.name!r}: an external case needs at least two fixed nodes "
                             "(anchors + drags); an internal case needs contractions")

    @property
    def kind(self) -> str:
        """``"internal"`` when the case gives contractions, else ``"external"``."""
        return "internal" if self.contractions is not None else "external"

    @property
    def drags(self) -> tuple[np.ndarray, np.ndarray]:
        """``(drag_nodes, drag_positions)``, as :func:`~mdsr_opt.solve_external` takes them."""
        return self.drag_nodes, self.drag_positions


@dataclass(frozen=True)
class Animation:
    """A motion made of designed cases, such as the gecko's gait.

    ``keyframes`` are ``(case name, fraction)`` pairs; ``fraction`` scales that case's designed (or given)
    contractions, every other muscle rests at 0. Between keyframes the contractions are interpolated
    linearly over ``frames_per_step`` frames, and every frame is a forward internal-driving solve with the
    muscles of all cases named in the keyframes.
    """

    name: str
    keyframes: tuple[tuple[str, float], ...]
    frames_per_step: int = 6
    fps: float = 8.0

    def __post_init__(self):
        _check_name(self.name, "animation name")
        kf = tuple((str(c), float(f)) for c, f in self.keyframes)
        if len(kf) < 2:
            raise ValueError(f"animation {self.name!r}: needs at least two keyframes")
        for c, f in kf:
            if not (0.0 <= f <= 1.0):
                raise ValueError(f"animation {self.name!r}: keyframe fraction {f} for {c!r} is outside [0, 1]")
        if isinstance(self.frames_per_step, bool) or not isinstance(self.frames_per_step, int) \
                or self.frames_per_step < 1:
            raise ValueError(f"animation {self.name!r}: frames_per_step must be a positive integer")
        object.__setattr__(self, "keyframes", kf)

    @property
    def cases(self) -> tuple[str, ...]:
        """Names of the cases whose muscles take part (no repeats, in order of appearance; ``"rest"`` is
        not a case)."""
        return tuple(dict.fromkeys(c for c, _ in self.keyframes if c != "rest"))


@dataclass(eq=False)
class Scene:
    """A soft robot and the deformations to design it for.

    Attributes
    ----------
    name : str
        Registry name (the problem script's stem, or the scene file's ``name``).
    mesh : Mesh
    material : NeoHookean or LinearElastic
    cases : tuple of Case
    title, description : str
        For reports; ``description`` says where the shape comes from.
    muscles : tuple of Muscle, optional
        Given muscles: required by internal cases, and used instead of routing by external cases when set.
    regions : dict of str to int arrays
        Named node sets (for figures and scene files).
    routing_options : dict
        Keyword arguments for :func:`~mdsr_opt.routing.route_muscles`.
    design_options : dict
        Keyword arguments for :func:`~mdsr_opt.design.design_contractions` (``method``, ``a_max``,
        ``muscle_model``, ``stiffness`` ...).
    animations : tuple of Animation
    expected : dict
        Key figures the scene is known to reach (documentation and tests), e.g. ``{"n_muscles": 2}``.
    resolution : int
        Approximate node count asked for (0 when the mesh was given).
    source : str
        The file the scene came from.
    """

    name: str
    mesh: Mesh
    material: Any
    cases: tuple
    title: str = ""
    description: str = ""
    muscles: tuple | None = None
    regions: dict = field(default_factory=dict)
    routing_options: dict = field(default_factory=dict)
    design_options: dict = field(default_factory=dict)
    animations: tuple = ()
    expected: dict = field(default_factory=dict)
    resolution: int = 0
    source: str = ""

    def __post_init__(self):
        from .equilibrium import _check_mesh_material

        _check_name(self.name, "scene name")
        _check_mesh_material(self.mesh, self.material)
        cases = tuple(self.cases)
        if not cases:
            raise ValueError(f"scene {self.name!r}: needs at least one case")
        for i, c in enumerate(cases):
            if not isinstance(c, Case):
                raise TypeError(f"scene {self.name!r}: cases[{i}] must be a Case, got {type(c).__name__}")
        names = [c.name for c in cases]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"scene {self.name!r}: case name {sorted(dup)[0]!r} is used twice")
        n = self.mesh.n_nodes
        for c in cases:
            for what, idx in (("anchors", c.anchors), ("drag_nodes", c.drag_nodes)):
                if len(idx) and (idx.min() < 0 or idx.max() >= n):
                    raise ValueError(f"scene {self.name!r}, case {c.name!r}: {what} has a node out of range "
                                     f"[0, {n})")
            both = np.intersect1d(c.anchors, c.drag_nodes)
            if len(both):
                raise ValueError(f"scene {self.name!r}, case {c.name!r}: node {int(both[0])} is both anchored "
                                 "and dragged")
        self.cases = cases
        if self.muscles is not None:
            self.muscles = tuple(check_muscles(self.mesh, self.muscles))
            if not self.muscles:
                self.muscles = None
        for c in cases:
            if c.kind == "internal":
                if self.muscles is None:
                    raise ValueError(f"scene {self.name!r}, case {c.name!r}: an internal case needs the "
                                     "scene's muscles")
                if len(c.contractions) != len(self.muscles):
                    raise ValueError(f"scene {self.name!r}, case {c.name!r}: {len(c.contractions)} "
                                     f"contraction(s) for {len(self.muscles)} muscle(s)")
        self.regions = {str(k): as_index_array(np.asarray(v), f"region {k!r}", n=n, shape=(None,))
                        for k, v in dict(self.regions).items()}
        anims = tuple(self.animations)
        for a in anims:
            if not isinstance(a, Animation):
                raise TypeError(f"scene {self.name!r}: animations must be Animation objects")
            for c in a.cases:
                if c not in names:
                    raise ValueError(f"scene {self.name!r}, animation {a.name!r}: unknown case {c!r} "
                                     f"(cases: {', '.join(names)})")
        self.animations = anims
        self.routing_options = dict(self.routing_options)
        self.design_options = dict(self.design_options)
        self.expected = dict(self.expected)

    @property
    def case_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.cases)

    def case(self, name: str) -> Case:
        """The case called ``name`` (``KeyError`` naming the choices otherwise)."""
        for c in self.cases:
            if c.name == name:
                return c
        raise KeyError(f"scene {self.name!r} has no case {name!r} (cases: {', '.join(self.case_names)})")

    def __repr__(self) -> str:
        return (f"Scene({self.name!r}, {self.mesh.n_nodes} nodes, {len(self.cases)} case(s): "
                f"{', '.join(self.case_names)})")


def _check_name(name, what: str) -> None:
    if not isinstance(name, str) or not name:
        raise TypeError(f"{what} must be a non-empty string, got {name!r}")
    if not all(ch.isalnum() or ch in "_-." for ch in name) or name.startswith("."):
        raise ValueError(f"{what} {name!r} may hold only letters, digits, '_', '-' and '.' (it names files)")


# ---------------------------------------------------------------------------------------------- resolution
def resolve_resolution(resolution: str | int) -> int:
    """The approximate node count for ``resolution`` (a name of :data:`RESOLUTIONS` or an integer >= 20)."""
    if isinstance(resolution, str):
        if resolution not in RESOLUTIONS:
            raise ValueError(f"resolution must be one of {', '.join(map(repr, RESOLUTIONS))} or a node count, "
                             f"got {resolution!r}")
        return RESOLUTIONS[resolution]
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)):
        raise TypeError(f"resolution must be a name or an integer node count, got {type(resolution).__name__}")
    if resolution < 20:
        raise ValueError(f"resolution must be at least 20 nodes, got {resolution}")
    return int(resolution)


def mesh_polygon(outline: ArrayLike, holes: Sequence[ArrayLike] | None = None,
                 resolution: str | int = "medium", min_angle: float = 30.0) -> Mesh:
    """Mesh a polygon (with holes) with about the number of nodes ``resolution`` asks for.

    A first mesh at a guessed triangle area is measured and the area rescaled once; the node count then
    lands within about 15 % of the request (the boundary's share of nodes varies with the shape).

    Example
    -------
    >>> m = mesh_polygon([[0, 0], [4, 0], [4, 1], [0, 1]], resolution=300)
    >>> 240 < m.n_nodes < 360
    True
    """
    want = resolve_resolution(resolution)
    outer = np.asarray(outline, dtype=float)
    area = polygon_area(outer) - sum(polygon_area(np.asarray(h, dtype=float)) for h in (holes or []))
    max_area = 2.2 * area / want  # a Triangle quality mesh has about 1 node per (max_area / 2.2)
    mesh = Mesh.from_polygon(outer, max_area=max_area, holes=holes, min_angle=min_angle)
    for _ in range(3):
        ratio = mesh.n_nodes / want
        if abs(ratio - 1.0) <= 0.1:
            break
        max_area *= ratio
        mesh = Mesh.from_polygon(outer, max_area=max_area, holes=holes, min_angle=min_angle)
    return mesh


# ---------------------------------------------------------------------------------------------- node selection
def nodes_in_box(mesh: Mesh, xmin: float = -math.inf, ymin: float = -math.inf, xmax: float = math.inf,
                 ymax: float = math.inf, boundary: bool = False) -> np.ndarray:
    """Nodes with ``xmin <= x <= xmax`` and ``ymin <= y <= ymax`` (boundary nodes only with ``boundary``)."""
    P = mesh.points
    eps = 1e-9 * mesh.size
    sel = (P[:, 0] >= xmin - eps) & (P[:, 0] <= xmax + eps) & (P[:, 1] >= ymin - eps) & (P[:, 1] <= ymax + eps)
    idx = np.flatnonzero(sel)
    if boundary:
        idx = np.intersect1d(idx, mesh.boundary_nodes)
    return idx.astype(np.int64)


def nodes_near(mesh: Mesh, point: ArrayLike, radius: float, boundary: bool = False) -> np.ndarray:
    """Nodes within ``radius`` of ``point`` (boundary nodes only with ``boundary``)."""
    p = as_float_array(point, "point", shape=(2,))
    idx = np.flatnonzero(np.linalg.norm(mesh.points - p, axis=1) <= radius)
    if boundary:
        idx = np.intersect1d(idx, mesh.boundary_nodes)
    return idx.astype(np.int64)


def nearest_node(mesh: Mesh, point: ArrayLike, boundary: bool = False, tol: float | None = None) -> int:
    """The node nearest to ``point``; with ``tol``, a ``ValueError`` when it lies farther than ``tol``."""
    p = as_float_array(point, "point", shape=(2,))
    cand = mesh.boundary_nodes if boundary else np.arange(mesh.n_nodes)
    d = np.linalg.norm(mesh.points[cand] - p, axis=1)
    k = int(np.argmin(d))
    if tol is not None and d[k] > tol:
        raise ValueError(f"no {'boundary ' if boundary else ''}node within {tol:.3g} of {p.tolist()} "
                         f"(nearest at {d[k]:.3g}): is the point on the body?")
    return int(cand[k])


def nodes_in_polygon(mesh: Mesh, polygon: ArrayLike, boundary: bool = False) -> np.ndarray:
    """Nodes inside (or on) ``polygon``."""
    from matplotlib.path import Path as _MplPath  # geometry only, no plotting

    poly = as_float_array(polygon, "polygon", shape=(None, 2))
    inside = _MplPath(poly).contains_points(mesh.points, radius=1e-9 * mesh.size) | \
        _MplPath(poly).contains_points(mesh.points, radius=-1e-9 * mesh.size)
    idx = np.flatnonzero(inside)
    if boundary:
        idx = np.intersect1d(idx, mesh.boundary_nodes)
    return idx.astype(np.int64)


def edge_path(mesh: Mesh, waypoints: ArrayLike, name: str | None = None, boundary: bool = False) -> Muscle:
    """A muscle through the nodes nearest to ``waypoints``, joined by shortest paths along mesh edges.

    The waypoints are snapped to their nearest nodes (boundary nodes with ``boundary``); consecutive ones
    are joined by the shortest edge path (Dijkstra on rest edge lengths). The result must be a simple path.
    """
    import networkx as nx

    wp = as_float_array(waypoints, "waypoints", shape=(None, 2))
    if len(wp) < 2:
        raise ValueError("a muscle path needs at least two waypoints")
    G = _edge_graph(mesh)
    ids = [nearest_node(mesh, p, boundary=boundary) for p in wp]
    path = [ids[0]]
    for a, b in zip(ids[:-1], ids[1:]):
        if a == b:
            continue
        path += nx.shortest_path(G, a, b, weight="length")[1:]
    return Muscle(path, name=name)


def _edge_graph(mesh: Mesh):
    import networkx as nx

    G = mesh.__dict__.get("_scene_edge_graph")
    if G is None:
        G = nx.Graph()
        for (i, j), l0 in zip(mesh.edges.tolist(), mesh.edge_lengths.tolist()):
            G.add_edge(i, j, length=l0)
        mesh.__dict__["_scene_edge_graph"] = G
    return G


# ---------------------------------------------------------------------------------------------- target helpers
def rigid_motion(points: ArrayLike, angle: float = 0.0, center: ArrayLike = (0.0, 0.0),
                 shift: ArrayLike = (0.0, 0.0)) -> np.ndarray:
    """Rotate ``points`` by ``angle`` (radians, counter-clockwise) about ``center``, then shift them."""
    P = as_float_array(points, "points", shape=(None, 2))
    c = as_float_array(center, "center", shape=(2,))
    s = as_float_array(shift, "shift", shape=(2,))
    R = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    return (P - c) @ R.T + c + s


def arc_map(points: ArrayLike, origin: ArrayLike, direction: ArrayLike, length: float,
            angle: float) -> np.ndarray:
    """Where bending a straight limb onto a circular arc puts ``points``.

    The limb starts at ``origin`` and runs along ``direction``; its centre line (through ``origin``) of
    length ``length`` is bent through ``angle`` radians (positive: towards the left of ``direction``) onto
    an arc, keeping lengths along the centre line. A point at distance ``s`` along and ``t`` to the left of
    the centre line goes to the arc point at ``s``, offset ``t`` along the arc's normal. Points with
    ``s <= 0`` stay; points beyond ``length`` continue straight along the tangent.
    """
    P = as_float_array(points, "points", shape=(None, 2))
    o = as_float_array(origin, "origin", shape=(2,))
    d = as_float_array(direction, "direction", shape=(2,))
    d = d / np.linalg.norm(d)
    nrm = np.array([-d[1], d[0]])
    s = (P - o) @ d
    t = (P - o) @ nrm
    if abs(angle) < 1e-12:
        return P.copy()
    R = length / angle  # signed radius
    sc = np.clip(s, 0.0, length)
    th = sc / R
    # arc point of the centre line and its normal, in the limb frame (u along d, v along nrm)
    u = R * np.sin(th) + (s - sc) * np.cos(th)
    v = R * (1.0 - np.cos(th)) + (s - sc) * np.sin(th)
    uu = u - t * np.sin(th)
    vv = v + t * np.cos(th)
    out = o + np.outer(uu, d) + np.outer(vv, nrm)
    keep = s <= 0
    out[keep] = P[keep]
    return out


# ---------------------------------------------------------------------------------------------- registry
def problems_dir() -> Path | None:
    """The folder of problem scripts.

    In order: the environment variable ``MDSR_PROBLEMS``; the ``problems/`` folder of the source checkout
    the package was imported from (an editable install or running from the repository); ``./problems`` in
    the working directory (a regular install run from a checkout). ``None`` when there is none.
    """
    env = os.environ.get("MDSR_PROBLEMS")
    if env:
        p = Path(env)
        if not p.is_dir():
            raise FileNotFoundError(f"MDSR_PROBLEMS={env!r} is not a folder")
        return p
    here = Path(__file__).resolve().parents[1] / "problems"
    if here.is_dir():
        return here
    cwd = Path.cwd() / "problems"
    if cwd.is_dir():
        return cwd
    return None


def _problem_files() -> dict[str, Path]:
    d = problems_dir()
    if d is None:
        return {}
    return {p.stem: p for p in sorted(d.glob("*.py")) if not p.stem.startswith("_")}


def list_problems() -> list[str]:
    """Names of the scenes in the problem library (sorted)."""
    return sorted(_problem_files())


def _load_module(path: Path):
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


def _build_from(path: Path, resolution) -> Scene:
    mod = _load_module(path)
    build = getattr(mod, "build", None)
    if not callable(build):
        raise ValueError(f"{path} defines no factory build(resolution=...) -> Scene")
    scene = build(resolution=resolution)
    if not isinstance(scene, Scene):
        raise TypeError(f"{path}: build() must return a Scene, got {type(scene).__name__}")
    if not scene.source:
        scene.source = str(path)
    return scene


def get_problem(name: str | os.PathLike, resolution: str | int = "medium") -> Scene:
    """Build a scene by library name, from a problem script path, or from a scene file.

    Parameters
    ----------
    name : str or path
        A name from :func:`list_problems`, a ``.py`` file with a ``build`` factory, or a ``.toml`` /
        ``.json`` scene file (:func:`load_scene`).
    resolution : {"coarse", "medium", "fine"} or int
        Approximate node count (see the module docstring). A scene file that gives ``max_area`` or a mesh
        file keeps its own.

    Raises
    ------
    KeyError
        An unknown name (the message lists the library).
    FileNotFoundError
        A path that does not exist.
    """
    resolve_resolution(resolution)
    s = os.fspath(name)
    p = Path(s)
    if p.suffix.lower() in (".py", ".toml", ".json") or os.sep in s or "/" in s:
        if not p.exists():
            raise FileNotFoundError(f"no such scene file: {s}")
        if p.suffix.lower() == ".py":
            return _build_from(p, resolution)
        return load_scene(p, resolution=resolution)
    files = _problem_files()
    if s not in files:
        where = problems_dir()
        lib = ", ".join(files) if files else f"none found (problems folder: {where})"
        raise KeyError(f"unknown problem {s!r}; the library has: {lib}")
    return _build_from(files[s], resolution)


# ---------------------------------------------------------------------------------------------- design problem
@dataclass
class CaseSetup:
    """A case turned into a design problem: the target shape and the muscles to design contractions for.

    Attributes
    ----------
    scene, case : the scene and the case.
    target : (n, 2) ndarray
        The target shape (external- or internal-driving equilibrium).
    muscles : tuple of Muscle
        Routed on the target (external cases without scene muscles) or the scene's.
    known_contractions : (m,) ndarray or None
        Internal cases: the contractions that made the target (the design's exact answer).
    target_result : EquilibriumResult
        The solve that made the target.
    routing : RoutingResult or None
        The routing on the target (for internal cases a diagnostic: what routing would have chosen).
    times : dict
        Seconds for ``target`` and ``routing``.
    """

    scene: Scene
    case: Case
    target: np.ndarray
    muscles: tuple
    known_contractions: np.ndarray | None
    target_result: Any
    routing: Any = None
    times: dict = field(default_factory=dict)

    @property
    def success(self) -> bool:
        """The target solve succeeded and there is at least one muscle."""
        return bool(self.target_result.success) and len(self.muscles) > 0


def prepare_case(scene: Scene, case: Case | str, *, route_internal: bool = True) -> CaseSetup:
    """Solve a case's target and lay its muscles: the input of any design method.

    External cases: :func:`~mdsr_opt.solve_external` with the case's anchors and drags, then
    :func:`~mdsr_opt.routing.route_muscles` with the scene's ``routing_options`` (unless the scene gives
    muscles). Internal cases: :func:`~mdsr_opt.solve_internal` with the scene's muscles at the case's
    contractions, using the scene's ``design_options`` ``muscle_model`` and ``stiffness`` so the design can
    recover them exactly; routing runs as a diagnostic when ``route_internal``.

    A failed target solve is not raised: ``target_result.success`` is False and ``muscles`` is empty.
    """
    import time
    import warnings

    from .equilibrium import solve_external, solve_internal
    from .routing import RoutingWarning, route_muscles

    if isinstance(case, str):
        case = scene.case(case)
    t0 = time.perf_counter()
    known = None
    if case.kind == "external":
        res = solve_external(scene.mesh, scene.material, case.anchors, case.drags)
    else:
        known = case.contractions.copy()
        res = solve_internal(scene.mesh, scene.material, scene.muscles, known,
                             model=scene.design_options.get("muscle_model", "springs"),
                             stiffness=scene.design_options.get("stiffness", 10.0))
    t1 = time.perf_counter()
    routing = None
    muscles: tuple = ()
    if res.success:
        if case.kind == "external" and scene.muscles is None or case.kind == "internal" and route_internal:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RoutingWarning)
                routing = route_muscles(scene.mesh, res.x, **scene.routing_options)
        if case.kind == "external" and scene.muscles is None:
            muscles = tuple(routing.muscles)
        else:
            muscles = tuple(scene.muscles)
    t2 = time.perf_counter()
    return CaseSetup(scene=scene, case=case, target=res.x.copy(), muscles=muscles, known_contractions=known,
                     target_result=res, routing=routing, times={"target": t1 - t0, "routing": t2 - t1})


# ---------------------------------------------------------------------------------------------- scene files
def load_scene(path: str | os.PathLike, resolution: str | int = "medium") -> Scene:
    """Read a scene file (TOML or JSON); see the README's scene-file section for the format."""
    raise NotImplementedError("scene files are coming in the next commit")


def run_main(build: Callable[..., Scene], argv: Sequence[str] | None = None) -> int:
    """The ``__main__`` of a problem script: ``--out DIR --resolution R [--case NAME ...]``."""
    raise NotImplementedError("the pipeline runner is coming in the next commit")
