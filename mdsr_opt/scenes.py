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

1. the problem library, one script per scene in the top-level ``problems/`` folder of the source tree
   (installed as the package ``mdsr_opt.problems``), each with a
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
import logging
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ._checks import as_float_array, as_index_array, positive_int
from .rundir import check_interrupt
from .mesh import MAX_TRIANGLES, Mesh, check_polygon, polygon_area
from .muscles import Muscle, check_muscles
from .progress import advance, progress_for_cli

__all__ = ["load_scene", "SceneFileError", "UnknownName", "seeds_for", "RESOLUTIONS", "Case", "Animation",
           "Scene", "CaseSetup", "list_problems", "get_problem", "problems_dir", "resolve_resolution",
           "mesh_polygon", "prepare_case", "nodes_in_box", "nodes_near", "nearest_node", "nodes_in_polygon",
           "edge_path", "boundary_path", "load_problem_module", "arc_map", "arc_rigid", "rigid_motion",
           "run_main", "run_scene", "write_scene", "run_entries", "RUN_FILES", "RESERVED_NAMES",
           "check_output_names", "check_scene_options", "run_case", "write_case", "CaseReport", "CaseRun",
           "SceneReport", "AnimationResult", "animate"]

_LOG = logging.getLogger(__name__)

#: Named resolutions: approximate number of mesh nodes.
RESOLUTIONS = {"coarse": 150, "medium": 600, "fine": 2400}

#: Said in every problem script: the paper gives no geometry, so the shapes are ours.
SHAPES_ARE_OURS = ("The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no "
                   "geometry); they are not the paper's meshes.")


class UnknownName(KeyError, ValueError):
    """An unknown problem, case or region name; the message lists the choices. It is a ``KeyError`` (a
    lookup) and a ``ValueError`` (bad input), so the ``mdsr`` command reports it like other bad input."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


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
    muscles : sequence of Muscle, optional
        External case: lay these muscles instead of routing them on the target (e.g. a muscle along a hole's
        rim that routing does not find); the design then finds their contractions.
    """

    name: str
    anchors: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    drag_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    drag_positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    contractions: np.ndarray | None = None
    description: str = ""
    muscles: tuple | None = None

    def __post_init__(self):
        _check_name(self.name, "case name")
        if self.muscles is not None:
            if self.contractions is not None:
                raise ValueError(f"case {self.name!r}: muscles are for an external case (an internal case "
                                 "drives the scene's muscles)")
            mus = tuple(self.muscles)
            if not mus or not all(isinstance(m, Muscle) for m in mus):
                raise TypeError(f"case {self.name!r}: muscles must be a non-empty sequence of Muscle")
            object.__setattr__(self, "muscles", mus)
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
    units : str
        The length unit of the mesh coordinates (one of :data:`mdsr_opt.export.UNITS`, default ``"mm"``),
        carried into the gait schedule and the fabrication files.
    gait : mdsr_opt.gait.Gait, optional
        A cyclic sequence of cases played on ONE shared muscle layout (:func:`~mdsr_opt.gait.run_gait`).
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
    units: str = "mm"
    gait: Any = None

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
            if c.muscles is not None:
                check_muscles(self.mesh, c.muscles)  # nodes of this mesh, along its edges
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
        check_units_and_gait(self)  # issue 16
        self.routing_options = check_scene_options(self.routing_options, "routing", f"scene {self.name!r}")
        self.design_options = check_scene_options(self.design_options, "design", f"scene {self.name!r}")
        self.expected = dict(self.expected)
        check_output_names(self.case_names, [a.name for a in anims], f"scene {self.name!r}")

    @property
    def case_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.cases)

    def case(self, name: str) -> Case:
        """The case called ``name`` (:class:`UnknownName`, a ``KeyError``, naming the choices otherwise)."""
        for c in self.cases:
            if c.name == name:
                return c
        raise UnknownName(f"scene {self.name!r} has no case {name!r} (cases: {', '.join(self.case_names)})")

    def __repr__(self) -> str:
        return (f"Scene({self.name!r}, {self.mesh.n_nodes} nodes, {len(self.cases)} case(s): "
                f"{', '.join(self.case_names)})")


def check_scene_options(options, kind: str, label: str = "") -> dict:
    """Check a scene's ``routing_options`` (``kind="routing"``) or ``design_options`` (``"design"``): every
    key a keyword of :func:`~mdsr_opt.routing.route_muscles` / :func:`~mdsr_opt.design.design_contractions`,
    every value in its range, solver ``options`` known to the solver. Returns a checked copy.

    Raises ``SceneFileError`` (a ValueError) or ``TypeError`` naming ``label`` and the field.
    """
    if kind not in ("routing", "design"):
        raise ValueError(f"kind must be 'routing' or 'design', got {kind!r}")
    r = _Reader(label or "scene")
    if not isinstance(options, Mapping):
        r.fail(f"{kind}_options", f"expected a dict, got {_tname(options)}", TypeError)
    arrays = {k: options[k] for k in ("initial", "weights") if kind == "design" and k in options}
    rest = {k: v for k, v in options.items() if k not in arrays}
    # per-problem arrays (initial, weights) are checked by design_contractions against the muscles and mesh
    return {**_scene_options(r, rest, kind), **arrays}


#: Names a case or animation may not take: "rest" is the rest pose in keyframes; "summary" names the run's
#: summary files.
RESERVED_NAMES = ("rest", "summary")


def check_output_names(case_names: Sequence[str], animation_names: Sequence[str] = (), label: str = "scene",
                       where: Sequence[str] | None = None) -> None:
    """Refuse case and animation names whose files would collide with each other or with a run's own files
    (:data:`RUN_FILES`; a case writes the folder ``<case>/``, an animation ``<name>.gif`` and
    ``<name>.json``), also on case-insensitive file systems. ``where`` names each name's field (cases
    first, then animations) for the message.
    """
    names = list(case_names) + list(animation_names)
    fields = list(where) if where is not None else \
        [f"case {c!r}" for c in case_names] + [f"animation {a!r}" for a in animation_names]
    taken: dict[str, str] = {f.lower(): f"the run's own file {f!r}" for f in RUN_FILES}
    for i, n in enumerate(names):
        is_case = i < len(case_names)
        kind = "case" if is_case else "animation"
        if n.lower() in RESERVED_NAMES or n.lower().split(".")[0] in RESERVED_NAMES:
            raise SceneFileError(f"{label}: {fields[i]}: the {kind} name {n!r} is reserved ('rest' is the rest "
                                 "pose in keyframes, 'summary' names the run's summary files); choose another")
        for entry in ([n] if is_case else [f"{n}.gif", f"{n}.json"]):
            key = entry.lower()
            if key in taken:
                raise SceneFileError(f"{label}: {fields[i]}: the {kind} {n!r} would write {entry!r}, which is "
                                     f"{taken[key]}; choose another name")
            taken[key] = f"written by the {kind} {n!r}"


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


def seeds_for(mesh: Mesh, minimum: int = 8) -> int:
    """A routing ``n_seeds`` that grows like the square root of the node count (at least ``minimum``).

    ``route_muscles`` seeds from the ``n_seeds`` most contracted edges of the whole mesh. On a finer mesh a
    contracted region holds more edges, so a fixed count lands every seed in the most contracted region
    and a second, slightly weaker region (the other half of an S-bend) gets none. The number of edges
    along a region's length grows like ``sqrt(n_nodes)``, so the seeds do too.
    """
    return max(int(minimum), int(round(math.sqrt(mesh.n_nodes))))


def mesh_polygon(outline: ArrayLike, holes: Sequence[ArrayLike] | None = None,
                 resolution: str | int = "medium", min_angle: float = 30.0, *,
                 max_triangles: int = MAX_TRIANGLES) -> Mesh:
    """Mesh a polygon (with holes) with about the number of nodes ``resolution`` asks for.

    A first mesh at a guessed triangle area is measured and the area rescaled once; the node count then
    lands within about 15 % of the request (the boundary's share of nodes varies with the shape). The
    outline and holes may have either orientation. ``max_triangles`` is passed to
    :meth:`Mesh.from_polygon`, which refuses a request over it before meshing.

    Example
    -------
    >>> m = mesh_polygon([[0, 0], [4, 0], [4, 1], [0, 1]], resolution=300)
    >>> 240 < m.n_nodes < 360
    True
    """
    want = resolve_resolution(resolution)
    outer = check_polygon(outline, "outline")  # counter-clockwise, so its area is positive
    holes = [check_polygon(h, f"holes[{i}]") for i, h in enumerate(holes or [])]
    area = polygon_area(outer) - sum(polygon_area(h) for h in holes)
    if area <= 0.0:
        raise ValueError("the holes cover the whole outline: no material is left to mesh")
    max_triangles = positive_int(max_triangles, "max_triangles")
    if 2 * want > max_triangles:  # a triangle mesh has about two triangles per node
        raise ValueError(f"resolution={want} nodes would make about {2 * want:.3g} triangles, more than the "
                         f"limit max_triangles={max_triangles}; ask for fewer nodes, or raise the limit with "
                         "mesh_polygon(..., max_triangles=)")
    max_area = 2.2 * area / want  # a Triangle quality mesh has about 1 node per (max_area / 2.2)
    kw = dict(holes=holes, min_angle=min_angle, max_triangles=max_triangles)
    mesh = Mesh.from_polygon(outer, max_area=max_area, **kw)
    for _ in range(3):
        ratio = mesh.n_nodes / want
        if abs(ratio - 1.0) <= 0.1:
            break
        max_area *= ratio
        mesh = Mesh.from_polygon(outer, max_area=max_area, **kw)
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


def _snap(mesh: Mesh, p: np.ndarray, boundary: bool, tol: float | None, what: str) -> int:
    """The node nearest ``p``; a ValueError naming ``what`` when it is farther than ``tol`` (default one mean
    edge length)."""
    tol = float(mesh.edge_lengths.mean()) if tol is None else float(tol)
    k = nearest_node(mesh, p, boundary=boundary)
    d = float(np.linalg.norm(mesh.points[k] - p))
    if d > tol:
        raise ValueError(f"{what} {p.tolist()} lies {d:.3g} from the nearest {'boundary ' if boundary else ''}node, "
                         f"more than {tol:.3g} (one mean edge length): is it on the body?")
    return k


def edge_path(mesh: Mesh, waypoints: ArrayLike, name: str | None = None, boundary: bool = False,
              tol: float | None = None) -> Muscle:
    """A muscle through the nodes nearest to ``waypoints``, joined by shortest paths along mesh edges.

    The waypoints are snapped to their nearest nodes (boundary nodes with ``boundary``), each of which must
    lie within ``tol`` (default: one mean edge length) of its waypoint, else a ``ValueError`` names the
    waypoint and the distance; consecutive ones are joined by the shortest edge path (Dijkstra on rest edge
    lengths). The result must be a simple path.
    """
    import networkx as nx

    wp = as_float_array(waypoints, "waypoints", shape=(None, 2))
    if len(wp) < 2:
        raise ValueError("a muscle path needs at least two waypoints")
    G = _edge_graph(mesh)
    ids = [_snap(mesh, p, boundary, tol, f"waypoint {i}") for i, p in enumerate(wp)]
    path = [ids[0]]
    for a, b in zip(ids[:-1], ids[1:]):
        if a == b:
            continue
        path += nx.shortest_path(G, a, b, weight="length")[1:]
    return Muscle(path, name=name)


def boundary_path(mesh: Mesh, start: ArrayLike, end: ArrayLike, via: ArrayLike | None = None,
                  name: str | None = None, inset: int = 0, tol: float | None = None) -> Muscle:
    """A muscle along a boundary loop from the boundary node nearest ``start`` to the one nearest ``end``.

    ``start`` and ``end`` must lie within ``tol`` (default: one mean edge length) of a boundary node, else a
    ``ValueError`` names the point and the distance. Of the two ways round the loop, the one passing
    nearest ``via`` is taken (default: the shorter one). ``inset`` drops that many nodes at each end (a
    muscle that stops short of a corner).
    """
    a = _snap(mesh, as_float_array(start, "start", shape=(2,)), True, tol, "start")
    b = _snap(mesh, as_float_array(end, "end", shape=(2,)), True, tol, "end")
    if a == b:
        raise ValueError("start and end snap to the same boundary node")
    for loop in mesh.boundary_loops:
        loop = [int(v) for v in loop]
        if a in loop and b in loop:
            break
    else:
        raise ValueError("start and end lie on different boundary loops")
    i, j = loop.index(a), loop.index(b)
    k = len(loop)
    fwd = [loop[(i + t) % k] for t in range((j - i) % k + 1)]
    bwd = [loop[(i - t) % k] for t in range((i - j) % k + 1)]
    if via is None:
        path = min(fwd, bwd, key=lambda p: Muscle(p).rest_length(mesh))
    else:
        v = as_float_array(via, "via", shape=(2,))
        path = min(fwd, bwd, key=lambda p: float(np.linalg.norm(mesh.points[p] - v, axis=1).min()))
    if inset:
        path = path[inset:-inset]
    return Muscle(path, name=name)


def load_problem_module(path: str | os.PathLike):
    """Load a problem script as a module by file path (e.g. to reuse a body's outline in another scene)."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"no such problem script: {p}")
    return _load_module(p)


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


def arc_rigid(points: ArrayLike, root: ArrayLike, origin: ArrayLike, direction: ArrayLike, length: float,
              angle: float) -> np.ndarray:
    """Move ``points`` rigidly with the frame of a bent limb's centre line at ``root`` (see :func:`arc_map`).

    Feet, a head or a tail attached to a bending spine follow it without being squashed: the group turns
    by the centre line's tangent angle at ``root`` (projected on the centre line) and moves with that
    centre-line point.
    """
    P = as_float_array(points, "points", shape=(None, 2))
    o = as_float_array(origin, "origin", shape=(2,))
    d = as_float_array(direction, "direction", shape=(2,))
    d = d / np.linalg.norm(d)
    s = float(np.clip((as_float_array(root, "root", shape=(2,)) - o) @ d, 0.0, length))
    c0 = o + s * d
    c1 = arc_map(c0[None], o, d, length, angle)[0]
    return rigid_motion(P, angle * s / length, c0, c1 - c0)


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
        spec = importlib.util.find_spec(f"{__package__}.problems")
    except ImportError:  # pragma: no cover - a broken parent package
        spec = None
    if spec is not None and spec.submodule_search_locations:
        for loc in spec.submodule_search_locations:
            if Path(loc).is_dir():
                return Path(loc)
    here = Path(__file__).resolve().parents[1] / "problems"
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


def _problem_files() -> dict[str, Path]:
    return {k: p for k, p in _library_files().items() if not _is_figure(p)}


def figure_scripts() -> dict[str, Path]:
    """The library's figure scripts (``mdsr run NAME`` calls their ``run_figure(out, resolution, log)``)."""
    return {k: p for k, p in _library_files().items() if _is_figure(p)}


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


def get_problem(name: str | os.PathLike, resolution: str | int | None = None) -> Scene:
    """Build a scene by library name, from a problem script path, or from a scene file.

    Parameters
    ----------
    name : str or path
        A name from :func:`list_problems`, a ``.py`` file with a ``build`` factory, or a ``.toml`` /
        ``.json`` scene file (:func:`load_scene`).
    resolution : {"coarse", "medium", "fine"} or int, optional
        Approximate node count (see the module docstring); default ``"medium"`` for scripts and the file's
        own ``body.resolution`` for scene files. A scene file that gives ``max_area`` or a mesh file keeps
        its own mesh.

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
            return _build_from(p, "medium" if resolution is None else resolution)
        return load_scene(p, resolution=resolution)
    files = _problem_files()
    if s not in files:
        where = problems_dir()
        lib = ", ".join(files) if files else f"none found (problems folder: {where})"
        raise UnknownName(f"unknown problem {s!r}; the library has: {lib}")
    return _build_from(files[s], "medium" if resolution is None else resolution)


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
    warnings : list of str
        The routing's warnings (why it found no muscle, for instance).
    """

    scene: Scene
    case: Case
    target: np.ndarray
    muscles: tuple
    known_contractions: np.ndarray | None
    target_result: Any
    routing: Any = None
    times: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)

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
                             model=scene.design_options.get("muscle_model", "cable"),
                             stiffness=scene.design_options.get("stiffness", 10.0),
                             anchor_radius=scene.design_options.get("anchor_radius"))
    t1 = time.perf_counter()
    routing = None
    muscles: tuple = ()
    notes: list[str] = []
    if res.success:
        own = case.kind == "external" and case.muscles is not None
        # a case with its own muscles is routed too, as a diagnostic (what routing would have laid)
        if case.kind == "external" and (scene.muscles is None or own) or case.kind == "internal" and route_internal:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", RoutingWarning)
                routing = route_muscles(scene.mesh, res.x, **scene.routing_options)
            notes = [str(w.message) for w in caught if issubclass(w.category, RoutingWarning)]
        if own:
            muscles = tuple(case.muscles)
        elif case.kind == "external" and scene.muscles is None:
            muscles = tuple(routing.muscles)
        else:
            muscles = tuple(scene.muscles)
    t2 = time.perf_counter()
    return CaseSetup(scene=scene, case=case, target=res.x.copy(), muscles=muscles, known_contractions=known,
                     target_result=res, routing=routing, times={"target": t1 - t0, "routing": t2 - t1},
                     warnings=notes)


# ---------------------------------------------------------------------------------------------- the pipeline
@dataclass
class CaseReport:
    """Key figures of one case run through the pipeline (JSON-ready scalars and short lists).

    Attributes
    ----------
    scene, case, kind : names and ``"external"``/``"internal"``.
    n_nodes, n_muscles : mesh size and number of muscles designed.
    success : the target solve, the routing (at least one muscle) and the design all succeeded.
    message : why not, when ``success`` is False.
    target_success, target_status : the solve that made the target.
    contractions : designed (commanded) contractions; known_contractions : internal cases' true ones.
    achieved, stroke : per muscle, the contraction reached along its node chain in the driven state
        (``1 - L/L0``) and the rope length pulled in (``achieved * L0``, length units).
    contraction_error : internal cases: largest ``|designed - known|``.
    difference : the design's difference to the target (a length, weighted RMS after rigid alignment);
        relative_difference : over ``mesh.size`` (the rest bounding-box diagonal).
    initial_difference : difference at the design's starting point.
    design_success, design_status, verified, gap : the design, its verification and the forward check's
        largest node distance between the design's state and a fresh forward solve from rest.
    routing : ``n_units`` and per-muscle ``contraction`` / ``n_edges``; internal cases also ``recovered``,
        the fraction of the true muscles' edges that routing on the target covers.
    photo : contour metrics of the SYNTHETIC photograph of the driven body: ``target`` compares the target's
        outline and holes with it (:func:`~mdsr_opt.evaluate.compare_loops`), ``self`` the driven state's
        (the measuring chain's floor); each with ``mean_px``, ``std_px``, ``max_px``, ``ratio`` over every
        loop, ``outer_mean_px`` and ``mean_norm`` of the outline alone, and ``n_unmatched`` holes. These photograph the design model itself (a mirror). ``prototype``
        (when a virtual prototype was given) holds the validation against a DIFFERENT, finer model
        (:func:`~mdsr_opt.prototype.validate_case`): ``driving`` (Table 2/3) and ``design`` (Table 4), holes
        included.
    times : seconds per stage; files : files written (relative to the scene's folder).
    """

    scene: str
    case: str
    kind: str
    n_nodes: int
    n_muscles: int = 0
    success: bool = False
    message: str = ""
    target_success: bool = False
    target_status: str = ""
    contractions: list = field(default_factory=list)
    achieved: list = field(default_factory=list)
    stroke: list = field(default_factory=list)
    known_contractions: list | None = None
    contraction_error: float | None = None
    difference: float | None = None
    relative_difference: float | None = None
    initial_difference: float | None = None
    design_success: bool | None = None
    design_status: str = ""
    verified: bool | None = None
    gap: float | None = None
    routing: dict | None = None
    photo: dict | None = None
    times: dict = field(default_factory=dict)
    files: list = field(default_factory=list)


@dataclass
class CaseRun:
    """A case's report with the arrays behind it (the setup, the design, the photograph)."""

    report: CaseReport
    setup: CaseSetup | None = None
    design: Any = None
    photo: Any = None
    comparison: Any = None
    prototype_photos: dict = field(default_factory=dict)


@dataclass
class SceneReport:
    """The outcome of :func:`run_scene`: one :class:`CaseReport` per case, animations, timing."""

    scene: str
    title: str
    n_nodes: int
    cases: list
    animations: dict = field(default_factory=dict)
    out: str = ""
    time: float = 0.0

    @property
    def success(self) -> bool:
        """Every case succeeded and every animation's forward solves succeeded."""
        return all(c.success for c in self.cases) and all(a.get("success", False)
                                                             for a in self.animations.values())

    def table(self) -> str:
        """A Markdown table of the key figures, one row per case."""
        head = ("| scene | case | kind | nodes | muscles | achieved contractions | strokes | difference | "
                "diff/size (%) | design | photo d (px) | ratio (%) | prototype d (px) | time (s) |")
        rows = [head, "| --- | --- | --- | ---: | ---: | --- | --- | ---: | ---: | --- | ---: | ---: | ---: | ---: |"]
        for c in self.cases:
            a = ", ".join(f"{v:.3f}" for v in (c.achieved or c.contractions)) if c.contractions else "-"
            s = ", ".join(f"{v:.4g}" for v in c.stroke) if c.stroke else "-"
            d = "-" if c.difference is None else f"{c.difference:.4g}"
            r = "-" if c.relative_difference is None else f"{100 * c.relative_difference:.2f}"
            ok = "ok" if c.success else "FAILED"
            ph = (c.photo or {}).get("target")
            pd = "-" if not ph else f"{ph['mean_px']:.2f}"
            pr = "-" if not ph else f"{100 * ph['ratio']:.2f}"
            pt = ((c.photo or {}).get("prototype") or {}).get("design") or {}
            pp = f"{pt['mean_px']:.2f}" if pt.get("success") else "-"
            rows.append(f"| {c.scene} | {c.case} | {c.kind} | {c.n_nodes} | {c.n_muscles} | {a} | {s} | {d} | {r} | "
                        f"{ok} | {pd} | {pr} | {pp} | {c.times.get('total', 0.0):.1f} |")
        return "\n".join(rows)

    def to_dict(self) -> dict:
        from dataclasses import asdict

        return {"format": "mdsr_opt.scene_run/1", "scene": self.scene, "title": self.title,
                "n_nodes": self.n_nodes, "success": self.success, "time": self.time,
                "cases": [asdict(c) for c in self.cases], "animations": self.animations}


def _finite(v):
    from .design import _finite_or_none

    return _finite_or_none(v)


def _edge_set(muscles) -> set:
    return {(min(a, b), max(a, b)) for m in muscles for a, b in m.segments.tolist()}


def run_case(scene: Scene, case: Case | str, *, method: str | None = None, photo: bool = True,
             photo_resolution: tuple[int, int] = (500, 500), log: Callable[[str], None] | None = None,
             prefix: str = "", prototype: Any = None) -> CaseRun:
    """Run one case through the pipeline (nothing is written).

    Target (external or internal driving) -> contraction graph and muscles (:func:`prepare_case`) ->
    contractions (:func:`~mdsr_opt.design.design_contractions` with the scene's ``design_options``, its
    verification being the forward check) -> SYNTHETIC photograph of the driven body and contour metrics
    (:mod:`mdsr_opt.evaluate`).

    With ``prototype`` (a :class:`~mdsr_opt.prototype.VirtualPrototype` of the scene) and ``photo``, the
    case is also validated against the virtual prototype (:func:`~mdsr_opt.prototype.validate_case`): the
    paper's Table 2 or 3 (the case's own driving) and Table 4 (the design) in ``report.photo["prototype"]``.

    A failure at any stage is reported, not raised: ``report.success`` is False and ``report.message``
    says where and why. Bad input (``TypeError``/``ValueError`` from the checks) still raises.
    """
    import time

    from .design import design_contractions

    say = log or (lambda s: None)
    if isinstance(case, str):
        case = scene.case(case)
    mesh = scene.mesh
    rep = CaseReport(scene=scene.name, case=case.name, kind=case.kind, n_nodes=mesh.n_nodes)
    run = CaseRun(report=rep)
    t0 = time.perf_counter()
    what = ("external driving" if case.kind == "external" else
            f"internal driving at {', '.join(f'{a:.0%}' for a in case.contractions)}")
    setup = prepare_case(scene, case)
    check_interrupt()  # Ctrl-C swallowed inside a solve stops here, never reported as a failed case
    run.setup = setup
    tr = setup.target_result
    rep.target_success, rep.target_status = bool(tr.success), str(tr.status)
    rep.times.update(setup.times)
    say(f"{prefix}target by {what}: {tr.status} ({tr.iterations} iterations, {len(tr.steps)} load step(s), "
        f"{setup.times['target']:.2f} s)")
    if setup.routing is not None:
        rr = setup.routing
        rep.routing = {"n_units": rr.n_units,
                       "muscles": [{"n_edges": s.n_edges, "contraction": s.contraction,
                                    "nonuniformity": s.nonuniformity} for s in rr.stats]}
        if case.kind == "internal":
            # the muscle edges that contract in the target: an edge inside a muscle's rigid end patch keeps
            # its length, so no routing can see it (it is counted apart as hidden)
            true = _edge_set(scene.muscles)
            X0, Y = scene.mesh.points, np.asarray(setup.target)
            seen = {e for e in true
                    if np.linalg.norm(Y[e[1]] - Y[e[0]]) < (1 - 1e-3) * np.linalg.norm(X0[e[1]] - X0[e[0]])}
            rep.routing["recovered"] = len(seen & _edge_set(rr.muscles)) / max(len(seen), 1)
            rep.routing["hidden_edges"] = len(true - seen)
    if not tr.success:
        rep.message = f"target solve failed: {tr.status}"
        rep.times["total"] = time.perf_counter() - t0
        say(f"{prefix}FAILED: {rep.message}")
        return run
    if not setup.muscles:
        why = "; ".join(setup.warnings) or "does the target shorten any edge?"
        rep.message = f"routing found no muscle on the target ({why})"
        rep.times["total"] = time.perf_counter() - t0
        say(f"{prefix}FAILED: {rep.message}")
        return run
    rep.n_muscles = len(setup.muscles)
    if setup.routing is not None and case.kind == "external" and scene.muscles is None and case.muscles is None:
        say(f"{prefix}routing: {rep.n_muscles} muscle(s) from {setup.routing.n_units} unit(s) "
            f"({setup.times['routing']:.2f} s)")
    opts = dict(scene.design_options)
    if method is not None:
        opts["method"] = method
    t1 = time.perf_counter()
    try:
        res = design_contractions(mesh, scene.material, setup.muscles, setup.target, **opts)
        check_interrupt()
    except RuntimeError as exc:  # a solver inside the design failed hard (SolverFailure, CasADi errors)
        rep.message = f"design failed: {type(exc).__name__}: {exc}"
        rep.times["total"] = time.perf_counter() - t0
        say(f"{prefix}FAILED: {rep.message}")
        return run
    run.design = res
    rep.times["design"] = time.perf_counter() - t1
    rep.contractions = [float(a) for a in res.contractions]
    rep.achieved = [float(a) for a in res.achieved]
    rep.stroke = [float(s) for s in res.stroke]
    rep.difference = float(res.difference)
    rep.relative_difference = float(res.difference) / mesh.size
    rep.initial_difference = float(res.initial_difference)
    rep.design_success, rep.design_status = bool(res.success), str(res.status)
    if res.verification is not None:
        rep.verified, rep.gap = bool(res.verification.passed), float(res.verification.gap)
    if setup.known_contractions is not None:
        rep.known_contractions = [float(a) for a in setup.known_contractions]
        rep.contraction_error = float(np.abs(res.contractions - setup.known_contractions).max())
    a = ", ".join(f"{v:.3f}" for v in res.contractions)
    ach = ", ".join(f"{v:.3f}" for v in res.achieved)
    st = ", ".join(f"{v:.4g}" for v in res.stroke)
    say(f"{prefix}design ({res.method}, {res.muscle_model}): commanded a = [{a}], achieved [{ach}], "
        f"strokes [{st}], difference {res.difference:.3g} "
        f"({100 * rep.relative_difference:.2f} % of size), {'verified' if res.success else 'FAILED: ' + res.status}"
        f" ({rep.times['design']:.1f} s)")
    if photo:
        from .evaluate import compare_loops, contour_loops_from_image, render_photo, simulated_loops

        t2 = time.perf_counter()
        try:
            ph = render_photo(mesh, res.x_aligned, resolution=photo_resolution, seed=0)
            loops = contour_loops_from_image(ph.image)
            # every boundary loop is measured: the outline and each hole against its photographed counterpart
            cmp_t = compare_loops(simulated_loops(mesh, setup.target), loops)
            cmp_s = compare_loops(simulated_loops(mesh, res.x_aligned), loops)
        except ValueError as exc:  # e.g. a body too thin to segment at this resolution
            rep.photo = {"error": str(exc)}
            say(f"{prefix}photograph: could not measure ({exc})")
        else:
            def figures(c):
                return {"mean_px": c.mean_px, "std_px": c.std_px, "max_px": c.max_px, "ratio": c.ratio,
                        "mean_norm": c.outer.mean_norm, "outer_mean_px": c.outer.mean_px,
                        "n_unmatched": c.n_unmatched}

            rep.photo = {"synthetic": True, "resolution": list(photo_resolution),
                         "target": figures(cmp_t), "self": figures(cmp_s)}
            run.photo, run.comparison = ph, cmp_t.outer
            say(f"{prefix}SYNTHETIC photograph: target outline d = {cmp_t.mean_px:.2f} px "
                f"(sd {cmp_t.std_px:.2f}, ratio {100 * cmp_t.ratio:.2f} %); measuring floor "
                f"{cmp_s.mean_px:.2f} px")
        if prototype is not None:
            from .prototype import validate_case

            metrics, shots = validate_case(prototype, setup, res, log=say, prefix=prefix)
            rep.photo = dict(rep.photo or {}, prototype=metrics)
            run.prototype_photos = shots
        rep.times["photo"] = time.perf_counter() - t2
        check_interrupt()
    rep.success = bool(res.success)
    if not res.success:
        rep.message = f"design not verified: {res.status}"
    rep.times["total"] = time.perf_counter() - t0
    return run


def write_case(scene: Scene, run: CaseRun, folder: str | os.PathLike, mesh_format: str = "vtu") -> list[str]:
    """Write a case's figures, meshes and photograph into ``folder``; returns the file names.

    Files: ``target.png`` (target with anchors and drags), ``graph.png`` (contraction graph),
    ``muscles.png`` (muscles over rest and target), ``design.png`` (driven state over the target),
    ``photo.png``/``photo.json`` (the SYNTHETIC photograph) and ``overlay.png`` (contour metrics), and the
    meshes ``target.<fmt>`` and ``driven.<fmt>`` (states as displacements). Every file is written
    atomically; what a failed stage did not produce is not written.
    """
    from . import plot
    from .io import write_mesh
    from .routing import contraction_graph

    fmt = "." + mesh_format.lstrip(".")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    setup, mesh, case = run.setup, scene.mesh, run.setup.case if run.setup else None
    files: list[str] = []
    if setup is None:
        return files
    mat = scene.material
    x = setup.target
    if setup.target_result.success:
        energy = mat.psi(mesh.deformation_gradients(x))
        title = (f"{scene.name} / {case.name}: target by "
                 f"{'external driving' if case.kind == 'external' else 'internal driving'}")
        fig = plot.plot_target(mesh, x, anchors=case.anchors, drag_nodes=case.drag_nodes,
                               drag_positions=case.drag_positions if len(case.drag_nodes) else None,
                               muscles=setup.muscles if case.kind == "internal" else (), values=energy,
                               title=title)
        files.append(plot.save_figure(fig, folder / "target.png", close=True))
        write_mesh(folder / f"target{fmt}", mesh, x=x, material=mat)
        files.append(str(folder / f"target{fmt}"))
        graph = setup.routing.graph if setup.routing is not None else contraction_graph(mesh, x)
        seeds = setup.routing.seeds if setup.routing is not None else None
        files.append(plot.save_figure(plot.plot_contraction_graph(mesh, x, graph, seeds=seeds),
                                      folder / "graph.png", close=True))
        if setup.muscles:
            files.append(plot.save_figure(plot.plot_routing(mesh, x, setup.muscles), folder / "muscles.png",
                                          close=True))
    if run.design is not None:
        res = run.design
        files.append(plot.save_figure(plot.plot_design(mesh, res, x, setup.muscles), folder / "design.png",
                                      close=True))
        write_mesh(folder / f"driven{fmt}", mesh, x=res.x_aligned, material=mat)
        files.append(str(folder / f"driven{fmt}"))
    for key, ph in run.prototype_photos.items():  # the virtual prototype's photographs (Tables 2-4)
        files.append(str(ph.save(folder / f"prototype_{key}.png")))
        files.append(str(folder / f"prototype_{key}.json"))
    if run.photo is not None:
        files.append(str(run.photo.save(folder / "photo.png")))
        files.append(str(folder / "photo.json"))
        fig = plot.plot_overlay(run.photo.image, mesh, x, run.comparison, synthetic=True,
                                title="target outline on the driven body's photo")
        files.append(plot.save_figure(fig, folder / "overlay.png", close=True))
    return [os.path.relpath(f, folder.parent) for f in files]


@dataclass
class AnimationResult:
    """The frames of an :class:`Animation`: forward internal-driving solves of interpolated contractions.

    Attributes
    ----------
    name : str
    muscles : tuple of Muscle
        The muscles of every case in the animation (each once).
    contractions : (frames, m) ndarray
        The contractions of every frame.
    states : list of (n, 2) ndarrays
        The equilibrium of every frame (aligned to the rest shape).
    success : bool
        Every frame's forward solve succeeded.
    failed_frames : list of int
    message : str
        Why the animation could not be made (empty otherwise).
    """

    name: str
    muscles: tuple = ()
    contractions: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    states: list = field(default_factory=list)
    success: bool = False
    failed_frames: list = field(default_factory=list)
    message: str = ""

    def to_dict(self) -> dict:
        """JSON-ready: no states (they are in the GIF), the muscles and per-frame contractions."""
        return {"name": self.name, "success": self.success, "message": self.message,
                "n_frames": len(self.states), "failed_frames": list(self.failed_frames),
                "muscles": [{"nodes": list(m.nodes), "name": m.name} for m in self.muscles],
                "contractions": np.asarray(self.contractions).tolist()}


def animate(scene: Scene, animation: Animation | str, designs: Mapping[str, tuple]) -> AnimationResult:
    """Forward-solve every frame of an animation.

    Parameters
    ----------
    scene : Scene
    animation : Animation or its name in ``scene.animations``.
    designs : mapping of case name to ``(muscles, contractions)``
        The designed muscles and contractions of every case the animation names (from :func:`run_case`:
        ``(run.setup.muscles, run.design.contractions)``).

    Each keyframe ``(case, f)`` sets that case's muscles to ``f`` times its contractions and every other
    muscle to 0 (``"rest"`` sets all to 0); frames in between interpolate linearly. Muscles shared by
    several cases (equal node paths) are one muscle.
    """
    from .equilibrium import solve_internal

    if isinstance(animation, str):
        found = [a for a in scene.animations if a.name == animation]
        if not found:
            raise UnknownName(f"scene {scene.name!r} has no animation {animation!r} "
                              f"(animations: {', '.join(a.name for a in scene.animations) or 'none'})")
        animation = found[0]
    union: list[Muscle] = []
    slots: dict[str, list[int]] = {}
    for cname in animation.cases:
        if cname not in designs:
            return AnimationResult(animation.name, message=f"case {cname!r} has no design in this run")
        mus, a = designs[cname]
        if len(mus) != len(a):
            raise ValueError(f"designs[{cname!r}]: {len(a)} contraction(s) for {len(mus)} muscle(s)")
        idx = []
        for m in mus:
            if m not in union:
                union.append(m)
            idx.append(union.index(m))
        slots[cname] = idx
    a_of = {}
    for cname, idx in slots.items():
        v = np.zeros(len(union))
        v[idx] = np.asarray(designs[cname][1], dtype=float)
        a_of[cname] = v
    keys = [np.zeros(len(union)) if c == "rest" else f * a_of[c] for c, f in animation.keyframes]
    frames = []
    for k0, k1 in zip(keys[:-1], keys[1:]):
        for j in range(animation.frames_per_step):
            frames.append(k0 + (k1 - k0) * j / animation.frames_per_step)
    frames.append(keys[-1])
    opts = scene.design_options
    model, stiffness = opts.get("muscle_model", "cable"), opts.get("stiffness", 10.0)
    states, fails = [], []
    for i, a in enumerate(frames):
        res = solve_internal(scene.mesh, scene.material, union, a, model=model, stiffness=stiffness,
                             anchor_radius=opts.get("anchor_radius"))
        check_interrupt()
        if not res.success:
            fails.append(i)
        states.append(res.x)
    return AnimationResult(animation.name, tuple(union), np.array(frames), states, not fails, fails,
                           "" if not fails else f"{len(fails)} forward solve(s) failed")


def run_scene(scene: Scene, out: str | os.PathLike, *, cases: Sequence[str] | None = None,
              method: str | None = None, photos: bool = True, figures: bool = True,
              animations: bool = True, mesh_format: str = "vtu", photo_resolution: tuple[int, int] = (500, 500),
              log: Callable[[str], None] | None = _LOG.info, overwrite: bool = False,
              prototype: bool = True, prototype_seed: int = 0) -> SceneReport:
    """Run the whole pipeline on a scene's cases and write everything into ``out``.

    For every case (or those named in ``cases``): target, contraction graph, muscles, contractions,
    forward check, SYNTHETIC photograph and contour metrics (:func:`run_case`), then its figures, meshes
    and photograph into ``out/<case>/`` (:func:`write_case`). Then each animation (forward solves of
    interpolated contractions) as ``out/<animation>.gif`` with ``out/<animation>.json``; the rest mesh
    with its regions as ``out/rest.png``; and last ``out/summary.json`` and ``out/summary.md`` (the table).

    Parameters
    ----------
    scene : Scene
    out : folder (created).
    cases : names of the cases to run (default all); animations needing a case not run are skipped.
    method : design method overriding the scene's ``design_options["method"]``.
    photos, figures, animations : turn the photographs, the figures and the animations off.
    mesh_format : ``"vtu"``, ``"vtk"`` or ``"xdmf"`` (through meshio).
    photo_resolution : (width, height) of the synthetic photographs.
    log : progress messages (default: this module's logger at INFO level; ``None`` for silence).
    prototype, prototype_seed : with ``photos``, validate every case against a virtual prototype
        (:class:`~mdsr_opt.prototype.VirtualPrototype`, drawn from ``prototype_seed``) and write the paper's
        Tables 2-4 as ``out/validation.md``.
    overwrite : bool
        ``out`` must be empty or new; with ``overwrite`` the files of an earlier run there are removed first
        (only those it recorded; see :class:`~mdsr_opt.rundir.RunFolder`, which also locks the folder
        against a second run and removes the temporaries of an interrupted one).

    Returns
    -------
    SceneReport
        ``.success`` is False when a target solve, the routing, a design or an animation frame failed;
        the reasons are in each case's ``message`` and in ``summary.json``. Nothing is hidden.

    Raises
    ------
    OutputFolderError (a ValueError)
        ``out`` is a file, cannot be written, holds other files (without ``overwrite``) or is locked by
        another run.
    KeyboardInterrupt
        Passed on at once (never recorded as a failed case); the files already complete stay.
    """
    from .rundir import RunFolder, noting_interrupts

    names = _check_run(scene, cases, mesh_format)
    with noting_interrupts(), RunFolder(out, overwrite=overwrite,
                                        command=f"run_scene({scene.name!r}, {os.fspath(out)!r})") as folder:
        folder.begin(run_entries(scene, names))
        report = write_scene(scene, out, cases=names, method=method, photos=photos, figures=figures,
                             animations=animations, mesh_format=mesh_format, photo_resolution=photo_resolution,
                             log=log, prototype=prototype, prototype_seed=prototype_seed)
        folder.finish("complete" if report.success else "complete, some cases failed")
    return report


def _check_run(scene, cases, mesh_format) -> tuple[str, ...]:
    from .io import FORMATS

    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")
    if "." + str(mesh_format).lstrip(".") not in FORMATS or mesh_format.lstrip(".") == "msh":
        raise ValueError(f"mesh_format must be 'vtu', 'vtk' or 'xdmf', got {mesh_format!r}")
    if isinstance(cases, str):
        cases = [cases]
    names = scene.case_names if cases is None else tuple(dict.fromkeys(cases))
    for c in names:
        scene.case(c)  # KeyError naming the choices
    return names


#: Files every scene run writes directly into its folder; case folders and animation files go beside them.
RUN_FILES = ("rest.png", "summary.json", "summary.md", "validation.md")


def run_entries(scene: Scene, cases: Sequence[str] | None = None) -> list[str]:
    """The names a run of ``scene`` may write directly into its folder: :data:`RUN_FILES`, one folder per
    case run and ``<animation>.gif`` / ``<animation>.json`` per animation."""
    names = scene.case_names if cases is None else tuple(cases)
    out = list(RUN_FILES) + list(names)
    for a in scene.animations:
        out += [f"{a.name}.gif", f"{a.name}.json"]
    if scene.gait is not None:
        out.append(scene.gait.name)  # the gait's folder: layout, schedule, animation, fabrication files
    return out


def write_scene(scene: Scene, out: str | os.PathLike, *, cases: Sequence[str] | None = None,
                method: str | None = None, photos: bool = True, figures: bool = True,
                animations: bool = True, mesh_format: str = "vtu", photo_resolution: tuple[int, int] = (500, 500),
                log: Callable[[str], None] | None = _LOG.info, prototype: bool = True,
                prototype_seed: int = 0) -> SceneReport:
    """:func:`run_scene` without the folder's guard: runs and writes into ``out`` as it stands (the caller
    holds a :class:`~mdsr_opt.rundir.RunFolder`). Same parameters and result."""
    import time

    from . import plot
    from .io import atomic_path, write_json

    names = _check_run(scene, cases, mesh_format)
    say = log or (lambda s: None)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    say(f"{scene.name}: {scene.title or scene.name} ({scene.mesh.n_nodes} nodes, {len(names)} case(s))")
    if figures:
        plot.save_figure(plot.plot_scene(scene.mesh, scene.regions, title=f"{scene.name}: rest mesh "
                                         f"({scene.mesh.n_nodes} nodes) and regions"), out / "rest.png",
                         close=True)
    proto = None
    if photos and prototype:
        from .prototype import VirtualPrototype

        proto = VirtualPrototype.for_scene(scene, seed=prototype_seed, photo_resolution=photo_resolution)
        d = proto.describe()
        say(f"{scene.name}: virtual prototype: {d['nodes']} nodes ({d['design_nodes']} in the design model), "
            f"E x {d['E_factor']:.3f}, nu {d['nu']:.3f} ({d['nu_shift']:+.3f}), exact cable, seed {d['seed']}")
    runs: dict[str, CaseRun] = {}
    for i, cname in enumerate(names):
        prefix = f"[{scene.name} {i + 1}/{len(names)} {cname}] "
        check_interrupt()
        run = run_case(scene, cname, method=method, photo=photos, photo_resolution=photo_resolution, log=say,
                       prefix=prefix, prototype=proto)
        if figures:
            run.report.files = write_case(scene, run, out / cname, mesh_format=mesh_format)
        runs[cname] = run
        advance(log)  # the progress bar of `mdsr run` (no-op for a plain callable)
    anim_out: dict[str, dict] = {}
    if animations:
        for anim in scene.animations:
            if any(c not in runs for c in anim.cases):
                continue
            designs = {c: (runs[c].setup.muscles, runs[c].design.contractions) for c in anim.cases
                       if runs[c].design is not None}
            res = animate(scene, anim, designs)
            data = res.to_dict()
            if res.states:
                say(f"[{scene.name}] animation {anim.name}: {len(res.states)} frames, {len(res.muscles)} muscle(s), "
                    + ("all forward solves succeeded" if res.success else f"{res.message} (frames "
                       f"{res.failed_frames})"))
                if figures:
                    act = res.contractions / scene.design_options.get("a_max", 0.6)
                    # titles state the contraction each frame reached along the muscles' node chains
                    reached = [[1.0 - m.length(x) / m.rest_length(scene.mesh) for m in res.muscles]
                               for x in res.states]
                    titles = [f"{scene.name} {anim.name}: frame {k + 1}/{len(act)}, achieved ["
                              + ", ".join(f"{v:.2f}" for v in f) + "]" for k, f in enumerate(reached)]
                    plot.save_animation(scene.mesh, res.states, out / f"{anim.name}.gif", muscles=res.muscles,
                                        activations=act, titles=titles, fps=anim.fps)
                    data["gif"] = f"{anim.name}.gif"
            else:
                say(f"[{scene.name}] animation {anim.name}: not made ({res.message})")
            anim_out[anim.name] = data
            write_json(out / f"{anim.name}.json", _finite(data))
            advance(log)
    if animations and scene.gait is not None:  # issue 16: one layout, gait schedule, fabrication files
        gait_info = _run_gait(scene, out, runs, figures=figures, log=say)
        if gait_info is not None:
            anim_out[scene.gait.name] = gait_info
    report = SceneReport(scene=scene.name, title=scene.title, n_nodes=scene.mesh.n_nodes,
                         cases=[runs[c].report for c in names], animations=anim_out, out=str(out),
                         time=time.perf_counter() - t0)
    summary = report.to_dict()
    summary.update({"description": scene.description, "source": scene.source, "resolution": scene.resolution,
                    "mesh": {k: float(v) for k, v in scene.mesh.quality().items()},
                    "material": {"kind": scene.material.kind, "E": scene.material.E, "nu": scene.material.nu,
                                 "thickness": scene.material.thickness},
                    "routing_options": scene.routing_options, "design_options": scene.design_options,
                    "photographs": "SYNTHETIC (rendered by mdsr_opt.evaluate.render_photo), not camera images"
                    if photos else None,
                    "expected": scene.expected})
    write_json(out / "summary.json", _finite(summary))
    with atomic_path(out / "summary.md") as tmp:
        Path(tmp).write_text(f"# {scene.title or scene.name}\n\n{report.table()}\n")
    if proto is not None:
        from .prototype import validation_tables

        with atomic_path(out / "validation.md") as tmp:
            Path(tmp).write_text(validation_tables([report]))
    say(f"{scene.name}: {'all cases succeeded' if report.success else 'SOME CASES FAILED'} in {report.time:.1f} s; "
        f"results in {out}")
    return report


def run_main(build: Callable[..., Scene], argv: Sequence[str] | None = None) -> int:
    """The ``__main__`` of a problem script: ``[--out DIR] [--resolution R] [--case NAME ...]``.

    Returns the process exit code: 0 when every case succeeded, 1 otherwise.
    """
    import argparse

    p = argparse.ArgumentParser(description=(build.__doc__ or "").strip().split("\n")[0])
    p.add_argument("--out", default=None, help="output folder (default: out/<scene>)")
    p.add_argument("--resolution", default="medium", type=_parse_resolution,
                   help="coarse, medium, fine or a node count (default medium)")
    p.add_argument("--case", action="append", default=None, help="run only this case (repeatable)")
    p.add_argument("--method", default=None, choices=("flattened", "nested", "derivative-free"),
                   help="design method (default: the scene's, normally flattened)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the files of an earlier run in --out (without it, a non-empty --out is refused)")
    a = p.parse_args(argv)
    try:
        if a.out is not None:
            from .rundir import check_out_path

            check_out_path(a.out)
        scene = build(resolution=a.resolution)
        with progress_for_cli(a, _n_units(scene, a.case, True), scene.name, unit="case") as log:
            rep = run_scene(scene, a.out or os.path.join("out", scene.name), cases=a.case, method=a.method,
                            overwrite=a.overwrite, log=log)
    except KeyboardInterrupt:
        print(f"{p.prog}: interrupted; the files already complete are kept", file=sys.stderr)
        return 130
    except (ValueError, TypeError, OSError) as exc:
        print(f"{p.prog}: error: {exc}", file=sys.stderr)
        return 2
    print(rep.table())
    return 0 if rep.success else 1


def _parse_resolution(text: str):
    return int(text) if text.isdigit() else text


def _parse_seed(text: str) -> int:
    import argparse

    try:
        v = int(text)
    except ValueError:
        v = -1
    if v < 0:
        raise argparse.ArgumentTypeError(f"a seed is a non-negative integer, got {text!r}")
    return v


def _parse_size(text: str) -> tuple[int, int]:
    import argparse

    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.isdigit() and int(p) >= 64 for p in parts):
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT with both at least 64, got {text!r}")
    return int(parts[0]), int(parts[1])


# ---------------------------------------------------------------------------------------------- scene files
_TOP_KEYS = ("name", "title", "description", "body", "material", "regions", "muscles", "routing", "design",
             "cases", "animations", "expected", "units", "gait")
_BODY_KEYS = ("outline", "holes", "mesh", "resolution", "max_area", "min_angle")
_MATERIAL_KEYS = ("model", "E", "nu", "thickness")
_REGION_KEYS = ("nodes", "box", "near", "radius", "polygon", "boundary", "loop")
_MUSCLE_KEYS = ("name", "nodes", "path", "boundary")
_CASE_KEYS = ("name", "description", "anchors", "drags", "contractions")
_DRAG_KEYS = ("nodes", "at", "to", "by", "rotate", "about")
_ANIM_KEYS = ("name", "keyframes", "frames_per_step", "fps")


class SceneFileError(ValueError):
    """A scene file is malformed; the message names the file and the field."""


class _Reader:
    """Field-path-aware checks for one scene file."""

    def __init__(self, path: Path):
        self.path = path
        self.label = path.name if isinstance(path, Path) else str(path)

    def fail(self, where: str, msg: str, kind: type = SceneFileError):
        err = kind(f"{self.label}: {where}: {msg}")
        raise err

    def keys(self, d, allowed: Sequence[str], where: str, required: Sequence[str] = ()) -> dict:
        import difflib

        if not isinstance(d, Mapping):
            self.fail(where, f"expected a table/object, got {_tname(d)}", TypeError)
        for k in d:
            if k not in allowed:
                close = difflib.get_close_matches(str(k), allowed, n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else f" (allowed: {', '.join(allowed)})"
                self.fail(_join(where, k), f"unknown field{hint}")
        for k in required:
            if k not in d:
                self.fail(_join(where, k), "missing (required)")
        return dict(d)

    def number(self, v, where: str, positive: bool = False) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(where, f"expected a number, got {_tname(v)}", TypeError)
        v = float(v)
        if not math.isfinite(v):
            self.fail(where, f"must be finite, got {v}")
        if positive and v <= 0:
            self.fail(where, f"must be > 0, got {v}")
        return v

    def string(self, v, where: str) -> str:
        if not isinstance(v, str) or not v:
            self.fail(where, f"expected a non-empty string, got {_tname(v)}", TypeError)
        return v

    def point(self, v, where: str) -> np.ndarray:
        if not isinstance(v, (list, tuple)) or len(v) != 2:
            self.fail(where, f"expected a point [x, y], got {v!r}", TypeError if not isinstance(v, (list, tuple))
                      else SceneFileError)
        return np.array([self.number(c, f"{where}[{i}]") for i, c in enumerate(v)])

    def points(self, v, where: str, at_least: int = 1) -> np.ndarray:
        if not isinstance(v, (list, tuple)):
            self.fail(where, f"expected a list of points [[x, y], ...], got {_tname(v)}", TypeError)
        if len(v) < at_least:
            self.fail(where, f"needs at least {at_least} point(s), got {len(v)}")
        return np.array([self.point(p, f"{where}[{i}]") for i, p in enumerate(v)]).reshape(-1, 2)


def _join(where: str, key) -> str:
    return f"{where}.{key}" if where else str(key)


def _tname(v) -> str:
    return "a list" if isinstance(v, list) else "a table" if isinstance(v, Mapping) else type(v).__name__


def _read_file(path: Path) -> dict:
    suffix = path.suffix.lower()
    text = path.read_bytes()
    if suffix == ".json":
        import json

        try:
            data = json.loads(text.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise SceneFileError(f"{path.name}: not valid JSON: {exc}") from None
    elif suffix == ".toml":
        if sys.version_info >= (3, 11):
            import tomllib
        else:  # pragma: no cover - Python 3.10
            import tomli as tomllib
        try:
            data = tomllib.loads(text.decode("utf-8"))
        except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise SceneFileError(f"{path.name}: not valid TOML: {exc}") from None
    else:
        raise SceneFileError(f"{path.name}: a scene file ends in .toml or .json, not {suffix or 'nothing'}")
    if not isinstance(data, dict):
        raise SceneFileError(f"{path.name}: the top level must be a table/object, got {_tname(data)}")
    return data


def load_scene(path: str | os.PathLike, resolution: str | int | None = None) -> Scene:
    """Read a scene file (TOML or JSON) into a :class:`Scene`, checking every field.

    The format (TOML shown; JSON has the same structure)::

        name = "finger"                       # required: letters, digits, _ - .
        title = "A finger bent by its tip"    # optional, as is description

        [body]                                # required: outline (+ holes) or mesh
        outline = [[0, 0], [4, 0], [4, 1], [0, 1]]
        holes = [[[1, 0.4], [1.4, 0.4], [1.4, 0.6]]]
        resolution = "coarse"                 # or a node count; or max_area = 0.02
        # mesh = "finger.vtu"                 # a mesh file (any meshio format), relative to this file

        [material]                            # optional: neo-hookean, E = 1, nu = 0.3, thickness = 1
        model = "neo-hookean"                 # or "linear"
        E = 1.0
        nu = 0.4

        [regions]                             # named node sets
        base = { box = [-1, -1, 0, 2] }       # [xmin, ymin, xmax, ymax]
        tip = { near = [4, 0.5], radius = 0.3, boundary = true }
        # also: nodes = [...], polygon = [[x, y], ...], loop = 0 (a boundary loop)

        [[muscles]]                           # optional; internal cases need them
        name = "lower"
        boundary = { from = [0, 0], to = [4, 0] }      # or path = [[x, y], ...], or nodes = [...]

        [routing]                             # keyword arguments of route_muscles
        max_muscles = 2
        [design]                              # keyword arguments of design_contractions
        a_max = 0.6

        [[cases]]
        name = "bend"
        anchors = "base"                      # a region, node indices or [x, y] points
        drags = [{ nodes = "tip", by = [-1.0, 1.5] },
                 { at = [4, 0], to = [3, 1.8] }]       # to / by / rotate (degrees) + about
        [[cases]]
        name = "contract"
        contractions = [0.3]                  # an internal case: one per muscle

        [[animations]]
        name = "wave"
        keyframes = [["rest", 0], ["bend", 1], ["rest", 0]]

    Node references (``anchors``, a drag's ``nodes``, a region's ``nodes``) are a region name, a list of
    region names, a list of node indices, or a list of ``[x, y]`` points, each snapped to the nearest node
    (which must lie within one mean edge length). A drag moves its nodes ``to`` a point (one node; for
    several, their centroid goes there), ``by`` a displacement, or ``rotate`` (degrees, anticlockwise)
    ``about`` a point and then ``by``. Every error names the file and the field, e.g.
    ``scene.toml: cases[1].drags[0].by: expected a point [x, y], got [1]``; unknown fields are errors
    (with a suggestion).

    Parameters
    ----------
    path : a ``.toml`` or ``.json`` file.
    resolution : optional
        Overrides the file's ``body.resolution`` (not ``max_area`` or a mesh file).

    Raises
    ------
    FileNotFoundError
        The file (or its mesh file) does not exist.
    SceneFileError (a ValueError), TypeError
        A malformed file.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such scene file: {path}")
    if path.is_dir():
        raise SceneFileError(f"{path} is a folder, not a scene file (a .toml or .json file)")
    try:
        data = _read_file(path)
    except PermissionError:
        raise SceneFileError(f"{path}: cannot read the scene file (permission denied)") from None
    r = _Reader(path)
    top = r.keys(data, _TOP_KEYS, "", required=("name", "body", "cases"))
    name = r.string(top["name"], "name")
    try:
        _check_name(name, "name")
    except ValueError as exc:
        r.fail("name", str(exc))
    mesh, res_used = _scene_mesh(r, top["body"], path, resolution)
    material = _scene_material(r, top.get("material", {}))
    regions: dict[str, np.ndarray] = {}
    reg_in = top.get("regions", {})
    r.keys(reg_in, list(reg_in) if isinstance(reg_in, Mapping) else (), "regions")
    for rname, spec in reg_in.items():
        regions[rname] = _scene_region(r, mesh, spec, f"regions.{rname}", regions)
    muscles = None
    if "muscles" in top:
        mus_in = top["muscles"]
        if not isinstance(mus_in, list):
            r.fail("muscles", f"expected a list of muscles ([[muscles]] tables), got {_tname(mus_in)}", TypeError)
        muscles = tuple(_scene_muscle(r, mesh, m, f"muscles[{i}]", regions) for i, m in enumerate(mus_in))
    routing = _scene_options(r, top.get("routing", {}), "routing")
    design = _scene_options(r, top.get("design", {}), "design")
    cases_in = top["cases"]
    if not isinstance(cases_in, list) or not cases_in:
        r.fail("cases", "expected a non-empty list of cases ([[cases]] tables)",
               TypeError if not isinstance(cases_in, list) else SceneFileError)
    cases = []
    seen = set()
    for i, c in enumerate(cases_in):
        case = _scene_case(r, mesh, c, f"cases[{i}]", regions, muscles)
        if case.name in seen:
            r.fail(f"cases[{i}].name", f"{case.name!r} is used by an earlier case")
        seen.add(case.name)
        cases.append(case)
    anims = []
    for i, a in enumerate(top.get("animations", []) if isinstance(top.get("animations", []), list)
                          else r.fail("animations", "expected a list of animations", TypeError)):
        anims.append(_scene_animation(r, a, f"animations[{i}]", seen))
    check_output_names([c.name for c in cases], [a.name for a in anims], path.name,
                       [f"cases[{i}].name" for i in range(len(cases))]
                       + [f"animations[{i}].name" for i in range(len(anims))])
    units, gait = parse_units_and_gait(r, top, seen)  # issue 16
    expected = top.get("expected", {})
    if not isinstance(expected, Mapping):
        r.fail("expected", f"expected a table, got {_tname(expected)}", TypeError)
    try:
        return Scene(name=name, mesh=mesh, material=material, cases=tuple(cases),
                     title=str(top.get("title", "")), description=str(top.get("description", "")),
                     muscles=muscles, regions=regions, routing_options=routing, design_options=design,
                     animations=tuple(anims), expected=dict(expected), resolution=res_used, source=str(path),
                     units=units, gait=gait)
    except (ValueError, TypeError) as exc:  # cross-field checks of Scene (contraction counts...)
        raise SceneFileError(f"{path.name}: {exc}") from None


def _scene_mesh(r: _Reader, body, path: Path, resolution) -> tuple[Mesh, int]:
    b = r.keys(body, _BODY_KEYS, "body")
    if ("outline" in b) == ("mesh" in b):
        r.fail("body", "give exactly one of outline (a polygon) and mesh (a mesh file)")
    if "mesh" in b:
        for k in ("holes", "resolution", "max_area", "min_angle"):
            if k in b:
                r.fail(f"body.{k}", "only applies to an outline, not to a mesh file")
        from .io import read_mesh

        mpath = path.parent / r.string(b["mesh"], "body.mesh")
        if not mpath.exists():
            raise FileNotFoundError(f"{path.name}: body.mesh: no such mesh file: {mpath}")
        try:
            return read_mesh(mpath).mesh, 0
        except ValueError as exc:
            r.fail("body.mesh", str(exc))
    outline = r.points(b["outline"], "body.outline", at_least=3)
    holes_in = b.get("holes", [])
    if not isinstance(holes_in, list):
        r.fail("body.holes", f"expected a list of polygons, got {_tname(holes_in)}", TypeError)
    holes = [r.points(h, f"body.holes[{i}]", at_least=3) for i, h in enumerate(holes_in)]
    min_angle = r.number(b.get("min_angle", 30.0), "body.min_angle", positive=True)
    if "max_area" in b and "resolution" in b:
        r.fail("body", "give max_area or resolution, not both")
    try:
        if "max_area" in b:
            return Mesh.from_polygon(outline, max_area=r.number(b["max_area"], "body.max_area", positive=True),
                                     holes=holes, min_angle=min_angle), 0
        res = resolution if resolution is not None else b.get("resolution", "medium")
        try:
            n = resolve_resolution(res)
        except (ValueError, TypeError) as exc:
            r.fail("body.resolution", str(exc), type(exc) if isinstance(exc, TypeError) else SceneFileError)
        return mesh_polygon(outline, holes, resolution=n, min_angle=min_angle), n
    except SceneFileError:
        raise
    except ValueError as exc:  # self-intersecting outline, hole outside, ...
        r.fail("body.outline" if "holes" not in str(exc) else "body.holes", str(exc))


def _scene_material(r: _Reader, spec):
    from .material import LinearElastic, NeoHookean

    m = r.keys(spec, _MATERIAL_KEYS, "material")
    kinds = {"neo-hookean": NeoHookean, "neohookean": NeoHookean, "linear": LinearElastic}
    model = m.get("model", "neo-hookean")
    if model not in kinds:
        r.fail("material.model", f"unknown material {model!r} (choose 'neo-hookean' or 'linear')")
    vals = {k: r.number(m[k], f"material.{k}") for k in ("E", "nu", "thickness") if k in m}
    try:
        return kinds[model](vals.get("E", 1.0), vals.get("nu", 0.3), vals.get("thickness", 1.0))
    except ValueError as exc:
        field_ = next((k for k in ("E", "nu", "thickness") if str(exc).startswith(k)), "")
        r.fail(f"material.{field_}" if field_ else "material", str(exc))


def _node_ref(r: _Reader, mesh: Mesh, v, where: str, regions: dict) -> np.ndarray:
    """A region name, region names, node indices or [x, y] points -> node indices."""
    tol = float(mesh.edge_lengths.mean())
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not v:
        r.fail(where, f"expected a region name, node indices or [x, y] points, got {v!r}",
               TypeError if not isinstance(v, list) else SceneFileError)
    out = []
    for i, item in enumerate(v):
        w = f"{where}[{i}]"
        if isinstance(item, str):
            if item not in regions:
                r.fail(w, f"unknown region {item!r} (regions: {', '.join(regions) or 'none defined'})")
            out.extend(regions[item].tolist())
        elif isinstance(item, bool):
            r.fail(w, "expected a node index, a region name or a point, got a boolean", TypeError)
        elif isinstance(item, int):
            if not 0 <= item < mesh.n_nodes:
                r.fail(w, f"node index {item} out of range [0, {mesh.n_nodes})")
            out.append(item)
        elif isinstance(item, list):
            p = r.point(item, w)
            try:
                out.append(nearest_node(mesh, p, tol=tol))
            except ValueError as exc:
                r.fail(w, str(exc))
        else:
            r.fail(w, f"expected a node index, a region name or a point [x, y], got {_tname(item)}", TypeError)
    return np.unique(np.asarray(out, dtype=np.int64))


def _scene_region(r: _Reader, mesh: Mesh, spec, where: str, regions: dict) -> np.ndarray:
    s = r.keys(spec, _REGION_KEYS, where)
    sel = [k for k in ("nodes", "box", "near", "polygon", "loop") if k in s]
    if len(sel) != 1:
        r.fail(where, "give exactly one of nodes, box, near, polygon, loop (boundary = true may restrict it)")
    kind = sel[0]
    bnd = s.get("boundary", False)
    if not isinstance(bnd, bool):
        r.fail(f"{where}.boundary", f"expected true or false, got {bnd!r}", TypeError)
    if "radius" in s and kind != "near":
        r.fail(f"{where}.radius", "only applies to near")
    if kind == "nodes":
        idx = _node_ref(r, mesh, s["nodes"], f"{where}.nodes", regions)
        if bnd:
            idx = np.intersect1d(idx, mesh.boundary_nodes)
    elif kind == "box":
        v = s["box"]
        if not isinstance(v, list) or len(v) != 4:
            r.fail(f"{where}.box", f"expected [xmin, ymin, xmax, ymax], got {v!r}")
        x0, y0, x1, y1 = (r.number(c, f"{where}.box[{i}]") for i, c in enumerate(v))
        if x0 > x1 or y0 > y1:
            r.fail(f"{where}.box", "needs xmin <= xmax and ymin <= ymax")
        idx = nodes_in_box(mesh, x0, y0, x1, y1, boundary=bnd)
    elif kind == "near":
        p = r.point(s["near"], f"{where}.near")
        if "radius" not in s:
            r.fail(f"{where}.radius", "missing (required with near)")
        idx = nodes_near(mesh, p, r.number(s["radius"], f"{where}.radius", positive=True), boundary=bnd)
    elif kind == "polygon":
        idx = nodes_in_polygon(mesh, r.points(s["polygon"], f"{where}.polygon", at_least=3), boundary=bnd)
    else:
        k = s["loop"]
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < len(mesh.boundary_loops):
            r.fail(f"{where}.loop", f"expected a boundary loop index in [0, {len(mesh.boundary_loops)}), got {k!r}")
        idx = np.sort(np.asarray(mesh.boundary_loops[k], dtype=np.int64))
    if len(idx) == 0:
        r.fail(where, "selects no node of the mesh")
    return np.asarray(idx, dtype=np.int64)


def _scene_muscle(r: _Reader, mesh: Mesh, spec, where: str, regions: dict) -> Muscle:
    m = r.keys(spec, _MUSCLE_KEYS, where)
    sel = [k for k in ("nodes", "path", "boundary") if k in m]
    if len(sel) != 1:
        r.fail(where, "give exactly one of nodes (indices), path (waypoints) and boundary ({from, to, via})")
    name = r.string(m["name"], f"{where}.name") if "name" in m else None
    try:
        if "nodes" in m:
            v = m["nodes"]
            if not isinstance(v, list) or any(isinstance(i, bool) or not isinstance(i, int) for i in v):
                r.fail(f"{where}.nodes", "expected a list of node indices", TypeError)
            mus = Muscle(tuple(v), name=name)
            mus.check_on(mesh)
            return mus
        if "path" in m:
            return edge_path(mesh, r.points(m["path"], f"{where}.path", at_least=2), name=name)
        b = r.keys(m["boundary"], ("from", "to", "via"), f"{where}.boundary", required=("from", "to"))
        via = r.point(b["via"], f"{where}.boundary.via") if "via" in b else None
        return boundary_path(mesh, r.point(b["from"], f"{where}.boundary.from"),
                             r.point(b["to"], f"{where}.boundary.to"), via=via, name=name)
    except SceneFileError:
        raise
    except ValueError as exc:
        r.fail(f"{where}.{sel[0]}", str(exc))


def _scene_options(r: _Reader, spec, where: str) -> dict:
    import inspect

    from .design import design_contractions
    from .routing import route_muscles

    fn = route_muscles if where == "routing" else design_contractions
    allowed = [p.name for p in inspect.signature(fn).parameters.values() if p.kind == p.KEYWORD_ONLY]
    if where == "design":
        allowed = [a for a in allowed if a not in ("initial", "weights")]
    opts = r.keys(spec, allowed, where)
    checks = _ROUTING_CHECKS if where == "routing" else _DESIGN_CHECKS
    for k, v in opts.items():
        if k in checks:  # a keyword added to the function later and not known here passes unchecked
            opts[k] = checks[k](r, v, f"{where}.{k}")
    if where == "design" and "options" in opts:
        opts["options"] = _solver_options(r, opts["options"], opts)
    return opts


def _real(lo: float, hi: float, lo_open: bool = False, hi_open: bool = False, what: str = ""):
    def check(r: _Reader, v, where: str) -> float:
        x = r.number(v, where)
        if x < lo or x > hi or (lo_open and x == lo) or (hi_open and x == hi):
            rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
            r.fail(where, f"must lie in {rng}{what}, got {x:g}")
        return x
    return check


def _positive(allow_zero: bool = False):
    def check(r: _Reader, v, where: str) -> float:
        x = r.number(v, where)
        if x < 0 or (x == 0 and not allow_zero):
            r.fail(where, f"must be {'>= 0' if allow_zero else '> 0'}, got {x:g}")
        return x
    return check


def _integer(minimum: int = 1):
    def check(r: _Reader, v, where: str) -> int:
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            r.fail(where, f"expected an integer, got {v!r}", TypeError)
        if v < minimum:
            r.fail(where, f"must be an integer >= {minimum}, got {v}")
        return v
    return check


def _choice(*choices: str):
    def check(r: _Reader, v, where: str) -> str:
        if v not in choices:
            r.fail(where, f"must be one of {', '.join(map(repr, choices))}, got {v!r}",
                   SceneFileError if isinstance(v, str) else TypeError)
        return v
    return check


def _boolean(r: _Reader, v, where: str) -> bool:
    if not isinstance(v, bool):
        r.fail(where, f"expected true or false, got {v!r}", TypeError)
    return v


def _table(r: _Reader, v, where: str) -> dict:
    if not isinstance(v, Mapping):
        r.fail(where, f"expected a table of solver options, got {_tname(v)}", TypeError)
    return dict(v)


#: Scene-file checks of ``[design]`` (the ranges design_contractions enforces) and ``[routing]``.
_DESIGN_CHECKS = {
    "method": _choice("flattened", "nested", "derivative-free"),
    "a_max": _real(0.0, 1.0, lo_open=True, hi_open=True, what=" (a fraction of the rest length)"),
    "interior_weight": _real(0.3, 0.7),
    "muscle_model": _choice("springs", "cable"),
    "stiffness": _positive(),
    "tol": _positive(),
    "max_iter": _integer(1),
    "hessian": _choice("exact", "gauss-newton"),
    "scaling": _choice("auto", "size"),
    "warm_start": _boolean,
    "outer": _choice("nelder-mead", "powell"),
    "options": _table,
    "inner_tol": _positive(),
    "verify": _boolean,
    "gap_rtol": _positive(),
    "derivatives": _choice("assembled", "casadi"),
}
_ROUTING_CHECKS = {
    "K_a": _positive(allow_zero=True),
    "K_b": _positive(allow_zero=True),
    "K_h": _positive(allow_zero=True),
    "n_seeds": _integer(1),
    "max_muscles": _integer(1),
    "min_length": _positive(allow_zero=True),
    "min_contraction": _real(0.0, 1.0, hi_open=True, what=" (a fraction of the rest length)"),
}


def _solver_options(r: _Reader, options: dict, design: dict) -> dict:
    """``[design.options]``: IPOPT's options (flattened, without the ``ipopt.`` prefix) or scipy's
    ``minimize`` options (nested: L-BFGS-B; derivative-free: Nelder-Mead or Powell), each checked against
    the solver (:func:`~mdsr_opt.backends.check_options`)."""
    from .backends import check_options

    method = design.get("method", "flattened")
    for k, v in options.items():
        w = f"design.options.{k}"
        try:
            if method == "flattened":
                check_options("ipopt", {f"ipopt.{k}": v})
            else:
                sp = "L-BFGS-B" if method == "nested" else \
                    {"nelder-mead": "Nelder-Mead", "powell": "Powell"}[design.get("outer", "nelder-mead")]
                check_options(f"scipy:{sp}", {k: v})
        except (ValueError, TypeError) as exc:
            r.fail(w, str(exc).replace("'ipopt.", "'"))
    return options


def _scene_case(r: _Reader, mesh: Mesh, spec, where: str, regions: dict, muscles) -> Case:
    c = r.keys(spec, _CASE_KEYS, where, required=("name",))
    name = r.string(c["name"], f"{where}.name")
    try:
        _check_name(name, "case name")
    except ValueError as exc:
        r.fail(f"{where}.name", str(exc))
    desc = str(c.get("description", ""))
    if "contractions" in c:
        for k in ("anchors", "drags"):
            if k in c:
                r.fail(f"{where}.{k}", "an internal case (with contractions) has no anchors or drags")
        v = c["contractions"]
        if not isinstance(v, list):
            r.fail(f"{where}.contractions", f"expected a list of numbers, got {_tname(v)}", TypeError)
        a = [r.number(x, f"{where}.contractions[{i}]") for i, x in enumerate(v)]
        if muscles is None:
            r.fail(f"{where}.contractions", "an internal case needs muscles ([[muscles]])")
        if len(a) != len(muscles):
            r.fail(f"{where}.contractions", f"needs one value per muscle ({len(muscles)}), got {len(a)}")
        for i, x in enumerate(a):
            if not 0.0 <= x < 1.0:
                r.fail(f"{where}.contractions[{i}]", f"must lie in [0, 1), got {x}")
        return Case(name, contractions=a, description=desc)
    anchors = (_node_ref(r, mesh, c["anchors"], f"{where}.anchors", regions) if "anchors" in c
               else np.zeros(0, dtype=np.int64))
    drags_in = c.get("drags", [])
    if not isinstance(drags_in, list):
        r.fail(f"{where}.drags", f"expected a list of drags, got {_tname(drags_in)}", TypeError)
    nodes, pos = [], []
    for i, d in enumerate(drags_in):
        idx, p = _scene_drag(r, mesh, d, f"{where}.drags[{i}]", regions)
        nodes.append(idx)
        pos.append(p)
    dn = np.concatenate(nodes) if nodes else np.zeros(0, dtype=np.int64)
    dp = np.vstack(pos) if pos else np.zeros((0, 2))
    if len(np.unique(dn)) != len(dn):
        vals, counts = np.unique(dn, return_counts=True)
        r.fail(f"{where}.drags", f"node {int(vals[counts > 1][0])} is dragged twice")
    both = np.intersect1d(anchors, dn)
    if len(both):
        r.fail(where, f"node {int(both[0])} is both anchored and dragged")
    if len(anchors) + len(dn) < 2:
        r.fail(where, "an external case needs at least two fixed nodes (anchors + drags); an internal case "
               "needs contractions")
    return Case(name, anchors=anchors, drag_nodes=dn, drag_positions=dp, description=desc)


def _scene_drag(r: _Reader, mesh: Mesh, spec, where: str, regions: dict) -> tuple[np.ndarray, np.ndarray]:
    d = r.keys(spec, _DRAG_KEYS, where)
    if ("nodes" in d) == ("at" in d):
        r.fail(where, "give exactly one of nodes (region, indices or points) and at (a point)")
    idx = (_node_ref(r, mesh, d["nodes"], f"{where}.nodes", regions) if "nodes" in d
           else _node_ref(r, mesh, [d["at"]], f"{where}.at", regions))
    P = mesh.points[idx]
    if "to" in d:
        for k in ("by", "rotate", "about"):
            if k in d:
                r.fail(f"{where}.{k}", "cannot be combined with to")
        return idx, P - P.mean(0) + r.point(d["to"], f"{where}.to")
    if "by" not in d and "rotate" not in d:
        r.fail(where, "say where the nodes go: to (a point), by (a displacement) or rotate (+ about)")
    if "about" in d and "rotate" not in d:
        r.fail(f"{where}.about", "only applies with rotate")
    ang = math.radians(r.number(d["rotate"], f"{where}.rotate")) if "rotate" in d else 0.0
    about = r.point(d["about"], f"{where}.about") if "about" in d else P.mean(0)
    shift = r.point(d["by"], f"{where}.by") if "by" in d else np.zeros(2)
    return idx, rigid_motion(P, ang, about, shift)


def _scene_animation(r: _Reader, spec, where: str, case_names: set) -> Animation:
    a = r.keys(spec, _ANIM_KEYS, where, required=("name", "keyframes"))
    kf = a["keyframes"]
    if not isinstance(kf, list):
        r.fail(f"{where}.keyframes", f"expected a list of [case, fraction] pairs, got {_tname(kf)}", TypeError)
    pairs = []
    for i, k in enumerate(kf):
        w = f"{where}.keyframes[{i}]"
        if not isinstance(k, list) or len(k) != 2 or not isinstance(k[0], str):
            r.fail(w, f"expected [case name, fraction], got {k!r}")
        if k[0] != "rest" and k[0] not in case_names:
            r.fail(w, f"unknown case {k[0]!r} (cases: {', '.join(sorted(case_names))}, or 'rest')")
        pairs.append((k[0], r.number(k[1], f"{w}[1]")))
    fps_ = a.get("frames_per_step", 6)
    if isinstance(fps_, bool) or not isinstance(fps_, int) or fps_ < 1:
        r.fail(f"{where}.frames_per_step", f"expected a positive integer, got {fps_!r}")
    try:
        return Animation(r.string(a["name"], f"{where}.name"), tuple(pairs), frames_per_step=fps_,
                         fps=r.number(a.get("fps", 8.0), f"{where}.fps", positive=True))
    except ValueError as exc:
        r.fail(where, str(exc))


# ---------------------------------------------------------------------------------------------- the command
def _doc_line(path: Path) -> str:
    import ast

    try:
        doc = ast.get_docstring(ast.parse(path.read_text()))
    except SyntaxError:
        return "(cannot be parsed)"
    return (doc or "").strip().split("\n")[0]


def _cmd_list(a) -> int:
    files = _problem_files()
    if not files:
        print(f"no problem library found (looked in $MDSR_PROBLEMS, the installed package and the source checkout); "
              f"run a scene file with `mdsr run PATH`")
        return 1
    print(f"problem library: {problems_dir()}")
    w = max(len(n) for n in files)
    for name, path in files.items():
        line = f"  {name:<{w}}  {_doc_line(path)}"
        if a.cases:
            scene = _build_from(path, "coarse")
            kinds = ", ".join(f"{c.name} ({c.kind})" for c in scene.cases)
            line += f"\n  {'':<{w}}  cases: {kinds}" + (
                f"; animations: {', '.join(x.name for x in scene.animations)}" if scene.animations else "")
        print(line)
    for name, path in figure_scripts().items():
        print(f"  {name:<{w}}  {_doc_line(path)} (figure)")
    print("run one with: mdsr run NAME --out DIR   (or a scene file: mdsr run PATH.toml --out DIR)")
    return 0


def _n_units(scene: Scene, cases, animations: bool) -> int:
    """Units of work of ``run_scene`` for the progress bar: one per case and per animation made."""
    names = set(scene.case_names if cases is None else cases)
    return len(names) + (sum(set(x.cases) <= names for x in scene.animations) if animations else 0)


def _cmd_run(a) -> int:
    import time

    names = list(a.scenes)
    if names == ["all"]:
        names = list_problems()
        if not names:
            raise ValueError("no problem library found: `mdsr run all` needs the problems/ folder")
    from .rundir import RunFolder

    t0 = time.perf_counter()
    # the folder first (a one-line error for an empty, unwritable, busy or non-empty --out), then every
    # scene (all input errors), and only then any solving or writing
    figs = figure_scripts()
    if any(n in figs for n in names):  # a figure script runs on its own (e.g. mdsr run figure6)
        if len(names) != 1:
            raise ValueError(f"run a figure script ({', '.join(n for n in names if n in figs)}) on its own")
        module = _load_module(figs[names[0]])
        with RunFolder(a.out, overwrite=a.overwrite, command=getattr(a, "command_line", "")) as folder:
            folder.begin(getattr(module, "OUTPUTS", ()))
            with progress_for_cli(a, 0, names[0], unit="step") as log:
                code = int(module.run_figure(a.out, resolution=a.resolution or "medium", log=log))
            folder.finish("complete" if code == 0 else "complete, some designs failed")
        return code
    with RunFolder(a.out, overwrite=a.overwrite, command=getattr(a, "command_line", "")) as folder:
        scenes = [get_problem(n, resolution=a.resolution) for n in names]
        seen = set()
        for s in scenes:
            if s.name in seen:
                raise ValueError(f"scene {s.name!r} is named twice")
            seen.add(s.name)
        if a.case:
            for s in scenes:
                for c in a.case:
                    s.case(c)  # an unknown --case names the scene's cases
        folder.begin(run_entries(scenes[0], a.case) if len(scenes) == 1 else [s.name for s in scenes] + ["tables.md"])
        reports = []
        with progress_for_cli(a, sum(_n_units(s, a.case, not a.no_animations) for s in scenes), "mdsr run",
                              unit="case") as log:
            for k, scene in enumerate(scenes):
                out = Path(a.out) if len(scenes) == 1 else Path(a.out) / scene.name
                if len(scenes) > 1:
                    log(f"=== scene {k + 1}/{len(scenes)}: {scene.name} ===")
                reports.append(write_scene(scene, out, cases=a.case, method=a.method, photos=not a.no_photos,
                                           figures=not a.no_figures, animations=not a.no_animations,
                                           mesh_format=a.format, photo_resolution=a.photo_size, log=log,
                                           prototype=not a.no_prototype, prototype_seed=a.prototype_seed))
        if len(scenes) > 1 and not a.no_photos and not a.no_prototype:
            from .io import atomic_path
            from .prototype import validation_tables

            with atomic_path(Path(a.out) / "tables.md") as tmp:
                Path(tmp).write_text(validation_tables(reports))
        folder.finish("complete" if all(r.success for r in reports) else "complete, some cases failed")
    lines = reports[0].table().split("\n")
    for r in reports[1:]:
        lines += r.table().split("\n")[2:]
    ok = all(r.success for r in reports)
    n_cases = sum(len(r.cases) for r in reports)
    n_bad = sum(not c.success for r in reports for c in r.cases)
    print("\n" + "\n".join(lines))
    for r in reports:
        for c in r.cases:
            if not c.success:
                print(f"FAILED {r.scene}/{c.case}: {c.message}")
        for name, an in r.animations.items():
            if not an.get("success", False):
                print(f"FAILED {r.scene}/{name} (animation): {an.get('message') or an.get('failed_frames')}")
    print(f"{n_cases - n_bad}/{n_cases} case(s) succeeded in {time.perf_counter() - t0:.1f} s; "
          f"results in {a.out}; photographs are SYNTHETIC")
    return 0 if ok else 1


def add_cli(sub) -> None:
    """Register ``mdsr list`` and ``mdsr run``."""
    p = sub.add_parser("list", help="list the problem library (the paper's robots as scenes)")
    p.add_argument("--cases", action="store_true", help="also build each scene (coarse) and list its cases")
    p.set_defaults(func=_cmd_list)

    q = sub.add_parser("run", help="run scenes through the whole pipeline: target, muscles, contractions, "
                       "forward check, synthetic photograph, contour metrics, validation against a virtual prototype (the "
                       "paper's Tables 2-4 in validation.md, and tables.md for several scenes); figures, meshes, JSON")
    q.add_argument("scenes", nargs="+", metavar="NAME|PATH",
                   help="library names (see mdsr list), 'all', problem scripts (.py) or scene files (.toml/.json)")
    q.add_argument("--out", required=True,
                   help="output folder (one sub-folder per scene when several); it must be new or empty, and "
                   "is locked while the run writes into it: a second run into it stops with an error")
    q.add_argument("--overwrite", action="store_true",
                   help="replace the files of an earlier mdsr run in --out (only the files that run recorded; a "
                   "folder holding other files is still refused). Without it a non-empty --out is refused, so "
                   "one folder never mixes two runs")
    q.add_argument("--resolution", type=_parse_resolution, default=None,
                   help="coarse (~150 nodes), medium (~600, default), fine (~2400) or a node count")
    q.add_argument("--case", action="append", default=None, help="run only this case (repeatable)")
    q.add_argument("--method", choices=("flattened", "nested", "derivative-free"), default=None,
                   help="design method (default: the scene's, normally flattened)")
    q.add_argument("--format", choices=("vtu", "vtk", "xdmf"), default="vtu", help="mesh files (default vtu)")
    q.add_argument("--no-photos", action="store_true", help="skip the synthetic photographs and contour metrics")
    q.add_argument("--photo-size", type=_parse_size, default=(500, 500), metavar="WxH",
                   help="size of the synthetic photographs in pixels (default 500x500, as in the paper)")
    q.add_argument("--no-prototype", action="store_true",
                   help="skip the virtual prototype (a 3x finer mesh, perturbed material, the exact cable, the "
                   "synthetic camera) against which the paper's Tables 2-4 are computed (validation.md per scene, "
                   "tables.md for several scenes)")
    q.add_argument("--prototype-seed", type=_parse_seed, default=0,
                   help="seed of the virtual prototype's material perturbation and camera (default 0)")
    q.add_argument("--no-figures", action="store_true", help="write only the JSON and Markdown summaries")
    q.add_argument("--no-animations", action="store_true", help="skip the animations (GIF)")
    q.add_argument("--quiet", action="store_true", help="print only the summary table")
    q.set_defaults(func=_cmd_run)


# ---------------------------------------------------------------------------------------------- issue 16: units, gait
_GAIT_KEYS = ("name", "poses", "frames_per_step", "max_muscles", "step_time", "cyclic", "fps")


def check_units_and_gait(scene: Scene) -> None:
    """Check a scene's ``units`` (a known length unit) and ``gait`` (a Gait naming its cases)."""
    from .export import check_units
    from .gait import Gait

    scene.units = check_units(scene.units)
    if scene.gait is None:
        return
    if not isinstance(scene.gait, Gait):
        raise TypeError(f"scene {scene.name!r}: gait must be a mdsr_opt.gait.Gait, got {type(scene.gait).__name__}")
    names = scene.case_names
    for c in scene.gait.poses:
        if c not in names:
            raise ValueError(f"scene {scene.name!r}, gait {scene.gait.name!r}: unknown case {c!r} "
                             f"(cases: {', '.join(names)}, or 'rest')")


def parse_units_and_gait(r: _Reader, top: Mapping, case_names: set):
    """The scene file's ``units = "mm"`` and ``[gait]`` table (``name``, ``poses`` = case names or "rest",
    ``frames_per_step``, ``max_muscles``, ``step_time``, ``cyclic``, ``fps``)."""
    from .export import UNITS
    from .gait import Gait

    units = top.get("units", "mm")
    if not isinstance(units, str) or units not in UNITS:
        r.fail("units", f"unknown units {units!r}: expected one of {', '.join(UNITS)}")
    if "gait" not in top:
        return units, None
    g = r.keys(top["gait"], _GAIT_KEYS, "gait", required=("poses",))
    poses = g["poses"]
    if not isinstance(poses, list) or not poses or not all(isinstance(p, str) for p in poses):
        r.fail("gait.poses", f"expected a non-empty list of case names, got {poses!r}")
    for i, p in enumerate(poses):
        if p != "rest" and p not in case_names:
            r.fail(f"gait.poses[{i}]", f"unknown case {p!r} (cases: {', '.join(sorted(case_names))}, or 'rest')")
    for key in ("frames_per_step", "max_muscles"):
        v = g.get(key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
            r.fail(f"gait.{key}", f"expected a positive integer, got {v!r}")
    if not isinstance(g.get("cyclic", True), bool):
        r.fail("gait.cyclic", f"expected true or false, got {g['cyclic']!r}")
    try:
        return units, Gait(r.string(g.get("name", "gait"), "gait.name"), tuple(poses),
                           frames_per_step=g.get("frames_per_step", 6), max_muscles=g.get("max_muscles"),
                           step_time=r.number(g.get("step_time", 1.0), "gait.step_time", positive=True),
                           cyclic=g.get("cyclic", True), fps=r.number(g.get("fps", 8.0), "gait.fps", positive=True))
    except (ValueError, TypeError) as exc:
        r.fail("gait", str(exc))


def _run_gait(scene: Scene, out, runs, figures: bool, log):
    from .gait import run_gait

    return run_gait(scene, out, runs, figures=figures, log=log)

