"""The problem library's data model: :class:`Scene`, :class:`Case`, :class:`Animation`, resolutions."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence
import numpy as np
from numpy.typing import ArrayLike

from ..body.mesh import MAX_RESOLUTION, MAX_TRIANGLES, Mesh
from ..body.polygons import check_polygon, polygon_area
from ..body.muscles import Muscle, check_muscles, muscle_name_clash
from ..core.checks import as_float_array, as_index_array, node_indices, positive_float, positive_int
from ..core.errors import InputError
from ..mechanics.anchors import body_size, check_anchor_radius
from ..mechanics.obstacles import check_obstacles
from ..synthesis.gait import Gait
from .fixtures import fixture_radius_conflict
from .names import check_name, check_output_names
from .obstacles import check_case_obstacles, check_friction
from .reader import check_scene_options

__all__ = ['UnknownName', 'Case', 'Animation', 'Scene', 'resolve_resolution', 'seeds_for', 'mesh_polygon', 'check_units_and_gait',
           'check_acceptance']


#: Named resolutions: approximate number of mesh nodes.
RESOLUTIONS = {"coarse": 150, "medium": 600, "fine": 2400}

#: A drag may move a node by at most this many body sizes (farther is a units mistake, not a target).
MAX_DRAG_SIZES = 10.0


#: Said in every problem script: the paper gives no geometry, so the shapes are ours.
SHAPES_ARE_OURS = ("The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no "
                   "geometry); they are not the paper's meshes.")


class UnknownName(KeyError, InputError):
    """An unknown problem, case or region name; the message lists the choices. It is a ``KeyError`` (a
    lookup) and an :class:`~mdsr_opt.core.errors.InputError` (a ``ValueError``: bad input), so the ``mdsr``
    command reports it like other bad input."""

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
        rim that routing does not find); the design then finds their contractions. Internal case: the
        muscles its contractions drive instead of the scene's (one contraction each).
    anchor_radius : float, optional
        With ``muscles``: the radius of their end fixtures, which the design uses for this case (default: the
        scene's, :func:`~mdsr_opt.scenes.fixtures.scene_fixture_radius`); e.g. the radius the ropes were fitted
        to when routed. With a fabrication that states them, at most its ``fixture_radius`` and at least its
        ``min_fixture_radius`` (the :class:`Scene` refuses another).
    obstacles : sequence of Disk, HalfPlane, Obstacle, optional
        Rigid obstacles of this case only, added to the scene's (:mod:`~mdsr_opt.scenes.obstacles`).
    friction : float, optional
        Coulomb's coefficient between the body and the obstacles in this case (default: the scene's).
    """

    name: str
    anchors: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    drag_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    drag_positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    contractions: np.ndarray | None = None
    description: str = ""
    muscles: tuple | None = None
    anchor_radius: float | None = None
    obstacles: tuple = ()
    friction: float | None = None

    def __post_init__(self):
        check_name(self.name, "case name")
        try:
            object.__setattr__(self, "obstacles", tuple(check_obstacles(self.obstacles)))
        except TypeError as exc:
            raise TypeError(f"case {self.name!r}: {exc}") from None
        object.__setattr__(self, "friction", check_friction(self.friction, f"case {self.name!r}"))
        if self.anchor_radius is not None:
            if self.muscles is None:
                raise ValueError(f"case {self.name!r}: anchor_radius is the end-fixture radius of the case's own "
                                 "muscles: give muscles too (or set the scene's design anchor_radius)")
            object.__setattr__(self, "anchor_radius", positive_float(self.anchor_radius,
                                                                     f"case {self.name!r}: anchor_radius",
                                                                     allow_zero=True))
        if self.muscles is not None:
            mus = tuple(self.muscles)
            if not mus or not all(isinstance(m, Muscle) for m in mus):
                raise TypeError(f"case {self.name!r}: muscles must be a non-empty sequence of Muscle")
            clash = muscle_name_clash(mus)
            if clash:
                raise ValueError(f"case {self.name!r}: muscle name {clash[0]!r} is used twice (muscles[{clash[1]}] "
                                 f"and muscles[{clash[2]}]): every table, figure and file names a muscle by it")
            object.__setattr__(self, "muscles", mus)
        anc = node_indices(self.anchors, f"case {self.name!r}: anchors")
        dn = node_indices(self.drag_nodes, f"case {self.name!r}: drag_nodes")
        dp = as_float_array(self.drag_positions, f"case {self.name!r}: drag_positions")
        dp = as_float_array(dp.reshape(-1, 2) if dp.size else np.zeros((0, 2)),
                            f"case {self.name!r}: drag_positions", shape=(len(dn), 2))
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
        check_name(self.name, "animation name")
        kf = tuple((str(c), positive_float(f, f"animation {self.name!r}: keyframe fraction for {c!r}",
                                           allow_zero=True)) for c, f in self.keyframes)  # "0.5", True: TypeError
        if len(kf) < 2:
            raise ValueError(f"animation {self.name!r}: needs at least two keyframes")
        for c, f in kf:
            if not (0.0 <= f <= 1.0):
                raise ValueError(f"animation {self.name!r}: keyframe fraction {f} for {c!r} is outside [0, 1]")
        positive_int(self.frames_per_step, f"animation {self.name!r}: frames_per_step")
        positive_float(self.fps, f"animation {self.name!r}: fps")
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
        Keyword arguments for :func:`~mdsr_opt.synthesis.routing.route_muscles`.
    design_options : dict
        Keyword arguments for :func:`~mdsr_opt.synthesis.contractions.design_contractions` (``method``, ``a_max``,
        ``muscle_model``, ``stiffness`` ...).
    animations : tuple of Animation
    expected : dict
        Key figures the scene is known to reach (documentation and tests), e.g. ``{"n_muscles": 2}``.
    resolution : int
        Approximate node count asked for (0 when the mesh was given).
    source : str
        The file the scene came from.
    units : str or None
        The length unit of the mesh coordinates (one of :data:`mdsr_opt.synthesis.export.UNITS`), carried into
        the gait schedule and the fabrication files; None (the default): "body units", no unit is invented.
    gait : mdsr_opt.synthesis.gait.Gait, optional
        A cyclic sequence of cases played on ONE shared muscle layout (:func:`~mdsr_opt.scenes.gaitrun.run_gait`).
    acceptance : dict
        What a case's design must show to succeed (:func:`check_acceptance`): ``max_difference`` (a fraction
        of the body's diameter, default :data:`~mdsr_opt.synthesis.acceptance.MAX_DIFFERENCE`), ``idle_contraction``
        (muscles designed below it are dropped, default
        :data:`~mdsr_opt.synthesis.acceptance.IDLE_CONTRACTION`) and ``bands`` (compute the strokes'
        uncertainty bands, default :data:`~mdsr_opt.synthesis.acceptance.BANDS`).
    obstacles : sequence of Disk, HalfPlane, Obstacle
        Rigid obstacles in every case (a case may add its own), at rest coordinates; every solve of a case
        with obstacles takes them (:func:`~mdsr_opt.scenes.obstacles.case_contact`), and one holding a node
        of the body at rest, or a drag into one, is refused here. ``friction``: Coulomb's coefficient between
        the body and the obstacles (default 0).
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
    units: str | None = None
    gait: Any = None
    acceptance: dict = field(default_factory=dict)
    obstacles: tuple = ()
    friction: float | None = None

    def __post_init__(self):
        from ..mechanics.loadsteps import check_mesh_material

        check_name(self.name, "scene name")
        check_mesh_material(self.mesh, self.material)
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
            if len(c.drag_nodes):
                d = c.drag_positions - self.mesh.points[c.drag_nodes]
                reach = float(np.hypot(d[:, 0], d[:, 1]).max())  # hypot: no overflow for absurd drags
                if reach > MAX_DRAG_SIZES * body_size(self.mesh):
                    raise ValueError(f"scene {self.name!r}, case {c.name!r}: a drag moves a node by {reach:.3g}, "
                                     f"more than {MAX_DRAG_SIZES} times the body's size "
                                     f"({body_size(self.mesh):.3g}); check the drag's units")
            both = np.intersect1d(c.anchors, c.drag_nodes)
            if len(both):
                raise ValueError(f"scene {self.name!r}, case {c.name!r}: node {int(both[0])} is both anchored "
                                 "and dragged")
        self.cases = cases
        if self.muscles is not None:
            self.muscles = (self.muscles,) if isinstance(self.muscles, Muscle) else tuple(self.muscles)
            clash = muscle_name_clash(self.muscles)  # said with the scene's name, before check_muscles says it
            if clash:
                raise ValueError(f"scene {self.name!r}: muscle name {clash[0]!r} is used twice (muscles[{clash[1]}] "
                                 f"and muscles[{clash[2]}]): every table, figure and file names a muscle by it")
            self.muscles = tuple(check_muscles(self.mesh, self.muscles))
            if not self.muscles:
                self.muscles = None
        for c in cases:
            if c.muscles is not None:
                check_muscles(self.mesh, c.muscles)  # nodes of this mesh, along its edges
            if c.anchor_radius is not None:
                try:
                    check_anchor_radius(self.mesh, c.anchor_radius)
                except ValueError as exc:
                    raise ValueError(f"scene {self.name!r}, case {c.name!r}: {exc}") from None
            if c.kind == "internal":
                driven = self.case_muscles(c)
                if driven is None:
                    raise ValueError(f"scene {self.name!r}, case {c.name!r}: an internal case needs the "
                                     "scene's muscles (or its own)")
                if len(c.contractions) != len(driven):
                    raise ValueError(f"scene {self.name!r}, case {c.name!r}: {len(c.contractions)} "
                                     f"contraction(s) for {len(driven)} muscle(s)")
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
        # a rope's channel with its wall deeper than the body holds no rope: refused before any solve (muscles
        # the scene lays are designed as given, so only sizes it states are checked unless a case routes)
        from ..synthesis.fabrication import check_channel_fits

        routes = self.muscles is None or self.gait is not None or any(c.kind == "internal" or c.muscles is not None
                                                                      for c in cases)
        check_channel_fits(self.mesh, self.routing_options.get("fabrication"), routed=routes,
                           where=f"scene {self.name!r}: fabrication")
        conflict = fixture_radius_conflict(  # one end-fixture size: [design] anchor_radius IS fixture_radius
            self.design_options.get("anchor_radius"), self.routing_options,
            {c.name: c.anchor_radius for c in cases},
            {"design": "design_options['anchor_radius']", "fixture": "the fabrication's fixture_radius",
             "min": "the fabrication's min_fixture_radius", "case": "case {!r}: anchor_radius"})
        if conflict:
            raise ValueError(f"scene {self.name!r}: {conflict[0]} {conflict[1]}")
        if self.design_options.get("anchor_radius") is not None:  # the solvers' own check, against this body
            try:
                check_anchor_radius(self.mesh, self.design_options["anchor_radius"])
            except ValueError as exc:
                raise ValueError(f"scene {self.name!r}: design.{exc}") from None
        if self.design_options.get("contact"):  # drags through the body itself: refused here, not mid-run
            for c in cases:
                _check_contact_drags(self, c)
        try:
            self.obstacles = tuple(check_obstacles(self.obstacles))
        except (TypeError, ValueError) as exc:
            raise type(exc)(f"scene {self.name!r}: {exc}") from None
        self.friction = check_friction(self.friction, f"scene {self.name!r}")
        for c in cases:  # an obstacle holding a node at rest, a drag into one: refused here, not mid-run
            check_case_obstacles(self, c)
        if self.friction is not None and not self.obstacles and not any(c.obstacles for c in cases):
            raise ValueError(f"scene {self.name!r}: friction {self.friction:g} is given but no case has obstacles")
        self.expected = dict(self.expected)
        self.acceptance = check_acceptance(self.acceptance, f"scene {self.name!r}: acceptance",
                                           a_max=self.design_options.get("a_max"))
        check_output_names(self.case_names, [a.name for a in anims], f"scene {self.name!r}",
                           gait_names=[self.gait.name] if self.gait is not None else ())

    @property
    def case_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.cases)

    def case_muscles(self, case: Case) -> tuple | None:
        """The muscles an internal ``case`` drives: its own, else the scene's (None: neither)."""
        return case.muscles if case.muscles is not None else self.muscles

    def case(self, name: str) -> Case:
        """The case called ``name`` (:class:`UnknownName`, a ``KeyError``, naming the choices otherwise)."""
        for c in self.cases:
            if c.name == name:
                return c
        raise UnknownName(f"scene {self.name!r} has no case {name!r} (cases: {', '.join(self.case_names)})")

    def __repr__(self) -> str:
        return (f"Scene({self.name!r}, {self.mesh.n_nodes} nodes, {len(self.cases)} case(s): "
                f"{', '.join(self.case_names)})")


# ---------------------------------------------------------------------------------------------- resolution
def check_acceptance(acceptance, label: str = "acceptance", a_max=None) -> dict:
    """A scene's ``acceptance`` with every key filled in: ``max_difference`` (in (0, 1], a fraction of the
    diameter), ``idle_contraction`` (in [0, 1), below the design's ``a_max``: default
    :data:`~mdsr_opt.synthesis.acceptance.A_MAX`) and ``bands`` (bool). TypeError/ValueError naming ``label``
    and the key otherwise (an unknown key too)."""
    from ..synthesis.acceptance import (A_MAX, BANDS, IDLE_CONTRACTION, MAX_DIFFERENCE, check_idle_contraction,
                                        check_max_difference)

    if not isinstance(acceptance, dict):
        raise TypeError(f"{label} must be a dict, got {type(acceptance).__name__}")
    known = {"max_difference": MAX_DIFFERENCE, "idle_contraction": IDLE_CONTRACTION, "bands": BANDS}
    for k in acceptance:
        if k not in known:
            raise ValueError(f"{label}: unknown key {k!r} (keys: {', '.join(known)})")
    out = {**known, **acceptance}
    out["max_difference"] = check_max_difference(out["max_difference"], f"{label}.max_difference")
    out["idle_contraction"] = check_idle_contraction(out["idle_contraction"], f"{label}.idle_contraction",
                                                     a_max=A_MAX if a_max is None else a_max)
    if not isinstance(out["bands"], (bool, np.bool_)):
        raise TypeError(f"{label}.bands must be true or false, got {type(out['bands']).__name__}")
    out["bands"] = bool(out["bands"])
    return out


def resolve_resolution(resolution: str | int) -> int:
    """The approximate node count for ``resolution`` (a name of :data:`RESOLUTIONS` or an integer from 20
    to :data:`~mdsr_opt.body.mesh.MAX_RESOLUTION`)."""
    if isinstance(resolution, str):
        if resolution not in RESOLUTIONS and resolution.strip().lstrip("+-").isdigit() and int(resolution) < 20:
            # a count typed as text (the command line's ``--resolution -5``): the count's own message
            raise ValueError(f"resolution must be at least 20 nodes, got {int(resolution)}")
        if resolution not in RESOLUTIONS:
            raise ValueError(f"resolution must be one of {', '.join(map(repr, RESOLUTIONS))} or a node count, "
                             f"got {resolution!r}")
        return RESOLUTIONS[resolution]
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)):
        raise TypeError(f"resolution must be a name or an integer node count, got {type(resolution).__name__}")
    if resolution < 20:
        raise ValueError(f"resolution must be at least 20 nodes, got {resolution}")
    if resolution > MAX_RESOLUTION:
        raise ValueError(f"resolution must be at most {MAX_RESOLUTION} nodes (a solve's memory grows with the "
                         f"nodes: about 3 GB at {MAX_RESOLUTION}), got {resolution}")
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


def check_units_and_gait(scene: Scene) -> None:
    """Check a scene's ``units`` (a known length unit, or None: body units) and ``gait`` (a Gait naming its
    cases)."""
    from ..synthesis.export import check_units

    scene.units = None if scene.units is None else check_units(scene.units)
    if scene.gait is None:
        return
    if not isinstance(scene.gait, Gait):
        raise TypeError(f"scene {scene.name!r}: gait must be a mdsr_opt.synthesis.gait.Gait, "
                        f"got {type(scene.gait).__name__}")
    names = scene.case_names
    for c in scene.gait.poses:
        if c not in names:
            raise ValueError(f"scene {scene.name!r}, gait {scene.gait.name!r}: unknown case {c!r} "
                             f"(cases: {', '.join(names)}, or 'rest')")


def _check_contact_drags(scene: Scene, case: Case) -> None:
    """With ``contact = true``: refuse an external case whose anchors and drags push prescribed parts of the
    body through each other (:func:`~mdsr_opt.mechanics.selfprescribed.check_prescribed_self`), naming it."""
    from ..mechanics.contactsteps import DEFAULT_GAP, check_gap
    from ..mechanics.selfprescribed import check_prescribed_self

    if case.kind != "external" or not len(case.drag_nodes):
        return
    P = scene.mesh.points
    nodes = np.concatenate([case.anchors, case.drag_nodes])
    rest, final = P[nodes], np.vstack([P[case.anchors], case.drag_positions])
    gap = scene.design_options.get("contact_gap") or DEFAULT_GAP * body_size(scene.mesh)
    try:
        check_gap(gap, body_size(scene.mesh))
        check_prescribed_self(scene.mesh, nodes, lambda s: rest + s * (final - rest), gap,
                              anchored=len(case.anchors))
    except ValueError as exc:
        raise ValueError(f"scene {scene.name!r}, case {case.name!r}: {exc}") from None
