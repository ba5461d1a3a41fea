"""Humanoid face: an outline with eye and mouth holes, and four expressions as targets.

The paper's introduction and conclusion name humanoid faces as the complex deformations its framework is
for (after the face "cloning" work it cites) but show no face. This scene is one: an egg-shaped face
6 units wide and 8 tall with two eye holes and a mouth hole, meshed mirror-symmetrically about x = 0. Each
expression holds the face only where the muscles that make it are anchored to bone, and drags the points
those muscles move (external driving): ``smile`` (the mouth corners pulled up and out, the upper face
held), ``frown`` (the corners pulled down, the chin held), ``wink`` (the left eye squeezed nearly shut, its
rim drawn to 60 % of its width and 40 % of its height; nothing held) and ``pucker`` (the corners pulled
in; nothing held). Each expression has an animation ``<case>_anim`` (rest, expression, rest).

A face robot carries ONE set of muscles for all its expressions. :func:`one_layout` routes every
expression's target on its own (:data:`EXPRESSION_ROUTING`) and merges the routings into one layout as
:func:`~mdsr_opt.synthesis.poses.design_poses` does (:func:`~mdsr_opt.synthesis.layouts.shared_layout`),
keeping ropes of different expressions that cross for channels at two depths (:data:`CLASHES`); each
case is designed on the muscles of that layout its target shortens (:func:`engaged`; the others' ropes are
paid out), so the run's ``summary.json`` names, per case, muscles ``M0, M1, ...`` of the one layout with
their node chains.

The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no geometry); they
are not the paper's meshes. A face is asked for at least ``MIN_NODES`` = 900 nodes (845 after meshing, for
``coarse`` and ``medium`` alike), the mesh on which the one layout, its ropes 0.16 inside the outline and the
holes, makes all four expressions: smile 80.1 %, frown 91.6 %, wink 72.9 %, pucker 74.8 % of their motion.
The wink needs a rope ringing the eye: the routing lays one round a squeezed hole where the mesh has a ring
of routable nodes round it that turns by at most 45 degrees at every node (on 845 nodes growth comes near
one): on 553 / 1049 / 1423 / 2310 / 2697 / 2949 nodes the wink reaches 78 / 77 / 83 / 77 / 75 / 71 %, and all
four expressions reach 70 % on 845, 1049, 1423 and 2697 nodes. On 662 / 766 / 953 / 1235 / 1615 /
1943 / 2141 nodes no such ring exists (the wink 56-68 %), and the pucker, made by arcs above and below
the lips, falls to 51-66 % on 553, 662, 766, 953, 1235, 1615, 2141, 2310, 2513 and 2949 nodes (smile 74-85 %
except 42 % on 2949, frown 88-96 %); on 2310 nodes (``fine``) its lip arcs cross its corner ropes and are
cut back to the parts clear of them (60 %). A rope kept inside the body cannot draw a hole's rim as far as a
rope on the rim does: the strip between the rope and the hole lags behind.

How well a design makes its expression is :func:`motion_recovered` over :func:`moving_nodes`: the share of
the target motion the muscle-driven face reproduces on every node the expression moves by more than 10 %
of its largest motion, with the whole rim of every hole such a node is on, after rigid alignment.

Run ``python problems/face.py --out out/face`` or ``mdsr run face --out out/face``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from mdsr_opt import Mesh, NeoHookean
from mdsr_opt.scenes.scene import Animation, Case, Scene, mesh_polygon, resolve_resolution, seeds_for
from mdsr_opt.scenes.select import nodes_near
from mdsr_opt.scenes.runscene import run_main

EYE_C, EYE_AX = (1.2, 0.9), (0.65, 0.28)       # right eye centre (the left is mirrored) and semi-axes
MOUTH_C, MOUTH_AX = (0.0, -1.9), (1.1, 0.25)
SKULL_Y = -0.5                                  # the smile holds the face above this line (the skull)
CHIN_Y = -3.3                                   # the frown holds the face below this line (the jaw bone)
ANCHOR_RADIUS = 0.05                             # rigid muscle-end patches smaller than an eye (default ~0.3)
MAX_TURN = 45.0                                 # the routing's tortuosity limit
MIN_NODES = 900                                 # the mesh where the one layout makes all four; "coarse" gets this
SQUEEZE = (0.6, 0.4)                            # the wink draws the eye's rim to these fractions of (width, height)


def ellipse(c, ax, n: int) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([c[0] + ax[0] * np.cos(t), c[1] + ax[1] * np.sin(t)])


def _egg(t: np.ndarray) -> np.ndarray:
    return np.column_stack([3.0 * np.cos(t) * (0.85 + 0.15 * np.sin(t)), 4.0 * np.sin(t)])


def outline(n: int = 48) -> np.ndarray:
    """The face's outer outline, counter-clockwise: an egg, narrower at the chin."""
    return _egg(np.linspace(0, 2 * np.pi, n, endpoint=False) - np.pi / 2)


def holes(n: int = 16) -> list[np.ndarray]:
    """The left eye, the right eye and the mouth."""
    return [ellipse((-EYE_C[0], EYE_C[1]), EYE_AX, n), ellipse(EYE_C, EYE_AX, n),
            ellipse(MOUTH_C, MOUTH_AX, max(n, 20))]


def half_outline(k: int) -> np.ndarray:
    """The right half (x >= 0) of the face without the mouth, counter-clockwise: chin, right side, crown,
    down the axis to the mouth, round the right half of the mouth, down the axis to the chin."""
    side = _egg(np.linspace(-np.pi / 2, np.pi / 2, 3 * k // 2 + 1))
    side[[0, -1], 0] = 0.0
    top, bottom = MOUTH_C[1] + MOUTH_AX[1], MOUTH_C[1] - MOUTH_AX[1]
    n_up = max(3, int(round((4.0 - top) / (8.0 / k))))
    down = np.column_stack([np.zeros(n_up - 2), np.linspace(4.0, top, n_up)[1:-1]])
    t = np.linspace(np.pi / 2, -np.pi / 2, max(k // 2, 10) + 1)[1:-1]
    mouth = np.column_stack([MOUTH_C[0] + MOUTH_AX[0] * np.cos(t), MOUTH_C[1] + MOUTH_AX[1] * np.sin(t)])
    n_lo = max(3, int(round((bottom + 4.0) / (8.0 / k))))
    chin = np.column_stack([np.zeros(n_lo - 2), np.linspace(bottom, -4.0, n_lo)[1:-1]])
    return np.vstack([side, down, [[0.0, top]], mouth, [[0.0, bottom]], chin])


def symmetric_mesh(n: int) -> Mesh:
    """A face mesh of about ``n`` nodes that the reflection x -> -x maps onto itself, node for node: the
    right half meshed and mirrored, nodes on the axis shared."""
    k = max(10, int(np.sqrt(n) * 0.8))
    half = mesh_polygon(half_outline(k), [ellipse(EYE_C, EYE_AX, k)], resolution=n // 2 + k // 2)
    P, T = half.points, half.triangles
    on_axis = np.abs(P[:, 0]) < 1e-12
    P = P.copy()
    P[on_axis, 0] = 0.0
    off = np.flatnonzero(~on_axis)
    mirror = np.arange(len(P))
    mirror[off] = len(P) + np.arange(len(off))
    points = np.vstack([P, P[off] * (-1.0, 1.0)])
    tris = np.vstack([T, mirror[T][:, ::-1]])  # the reflection reverses orientation: flip to keep CCW
    return Mesh(points, tris)


def turns(mesh: Mesh, nodes) -> np.ndarray:
    """The turning angle (degrees) at each interior node of a node chain, at rest."""
    d = np.diff(mesh.points[list(nodes)], axis=0)
    a = np.arctan2(d[:, 1], d[:, 0])
    return np.degrees(np.abs((np.diff(a) + np.pi) % (2 * np.pi) - np.pi))


def motion_recovered(rest: ArrayLike, target: ArrayLike, driven: ArrayLike, nodes: ArrayLike) -> float:
    """The share of the drag motion a design reproduces.

    ``1 - ||driven[D] - target[D]|| / ||target[D] - rest[D]||`` (Frobenius norms over the dragged nodes
    ``D``), where ``driven`` is the muscle-driven state rigidly aligned onto the target (the design's
    ``x_aligned``) and ``target`` is in the rest frame (an external case's anchors and drags keep it there).
    1 is a perfect expression, 0 is no better than the rest face; it can be negative.

    Raises
    ------
    ValueError
        Shapes that disagree, no nodes, or a target in which the nodes do not move.
    """
    X, T, x = (np.asarray(a, dtype=float) for a in (rest, target, driven))
    if X.ndim != 2 or X.shape[1] != 2 or T.shape != X.shape or x.shape != X.shape:
        raise ValueError(f"rest, target and driven must all be (n, 2) arrays, got {X.shape}, {T.shape}, {x.shape}")
    D = np.asarray(nodes, dtype=np.int64).ravel()
    if D.size == 0:
        raise ValueError("nodes is empty: name the dragged nodes")
    motion = float(np.linalg.norm(T[D] - X[D]))
    if motion == 0.0:
        raise ValueError("the target does not move these nodes: the recovered share is undefined")
    return 1.0 - float(np.linalg.norm(x[D] - T[D])) / motion


#: routing of the expressions' own layouts, merged into the face's one layout: a smaller ``K_a`` and
#: ``min_length`` than the scene's default, since the smile's contracted units are short (at the default
#: ``min_length`` routing finds no smile muscle at all). The ropes run inside the body (the default
#: fabrication: at least 2 % of the face's diameter, 0.16, from the outline and the holes), so no rope can
#: lie on an eye's or the mouth's rim: the wink and the pucker are made by ring-shaped ropes around the hole
#: (orbicularis oculi, oris), whose hoop contraction comes with a radial stretch about as large; routing
#: seeds them with ``compression_ratio`` 0.4 (at 1 the wink routes no muscle at all), and up to 6 muscles
#: per expression keep both lips' ropes for the pucker
EXPRESSION_ROUTING = {"K_a": 1.0, "min_length": 0.2, "compression_ratio": 0.4, "max_muscles": 6}

#: ropes of different expressions that cross are kept as routed, for channels at two depths (design_poses'
#: ``clashes="keep"``; the layout is then no success in one layer): the pucker's lip arcs cross the smile's and
#: the frown's corner ropes, and fitted beside them in one layer (the default, "resolve") the pucker recovers
#: 63 / 63 / 44 / 68 % of its motion on 845 / 1049 / 1423 / 2697 nodes instead of 75 / 74 / 71 / 73 %
CLASHES = "keep"


#: the layouts made so far, per mesh (building the face solves its four targets and routes them)
_LAYOUTS: dict = {}


def one_layout(mesh: Mesh, material, cases, routing_options, anchor_radius=None) -> tuple:
    """The face's ONE muscle layout: every expression's target (external driving) routed on its own
    (:func:`~mdsr_opt.synthesis.layouts.route_poses`, the pipeline's routing), the
    routings merged by :func:`~mdsr_opt.synthesis.layouts.shared_layout` (round-robin by rank, duplicates
    dropped), as :func:`~mdsr_opt.synthesis.poses.design_poses` lays it, the ropes fitted to end fixtures of
    the design's ``anchor_radius`` (as design_poses fits them). Returns ``(muscles, targets)``;
    a target that does not solve raises ``RuntimeError`` naming it."""
    from mdsr_opt.mechanics.equilibrium import solve_external
    from mdsr_opt.synthesis.fabrication import check_fabrication
    from mdsr_opt.synthesis.layouts import route_poses, shared_layout

    key = (mesh.n_nodes, mesh.points.tobytes())
    if key not in _LAYOUTS:
        routing_options = {**routing_options,
                           "fabrication": check_fabrication(routing_options.get("fabrication"), anchor_radius)}
        targets = {}
        for c in cases:
            res = solve_external(mesh, material, c.anchors, c.drags)
            if not res.success:
                raise RuntimeError(f"face: the target of {c.name!r} did not solve: {res.status}")
            targets[c.name] = res.x
        own, _ = route_poses(mesh, targets, routing_options)  # every target routed as design_poses routes it
        # merged as design_poses merges them: a rope that cannot be moulded beside a kept one (channels closer
        # than a channel and a wall, crossing ropes, fixtures of anchor_radius that overlap) merged into it
        fab = routing_options["fabrication"]
        muscles, _ = shared_layout(mesh, own, fabrication=None if fab is False else fab.for_body(mesh),
                                   fixture_radius=anchor_radius, notes=[], clashes=CLASHES)
        _LAYOUTS[key] = (muscles, targets)
    return _LAYOUTS[key]


def engaged(muscles, mesh: Mesh, target) -> tuple:
    """The muscles of the layout whose path shortens in ``target``: the ones this expression pulls (the
    others' servos pay their ropes out, as :func:`~mdsr_opt.synthesis.poses.design_poses` does)."""
    return tuple(m for m in muscles if m.length(target) < m.rest_length(mesh) * (1.0 - 1e-9))


def moving_nodes(mesh: Mesh, target: ArrayLike, fraction: float = 0.1) -> np.ndarray:
    """The nodes an expression moves noticeably: farther than ``fraction`` of the largest target motion
    (in the case's frame: held nodes stay), and the whole rim of every hole (eye, mouth) any of them is on."""
    T = np.asarray(target, dtype=float)
    motion = np.linalg.norm(T - mesh.points, axis=1)
    moving = motion > fraction * motion.max()
    for loop in mesh.boundary_loops[1:]:
        if moving[loop].any():
            moving[loop] = True
    return np.flatnonzero(moving)


def build(resolution="medium") -> Scene:
    """The face scene: cases ``smile``, ``frown``, ``wink``, ``pucker``; animations ``<case>_anim``."""
    n = max(MIN_NODES, resolve_resolution(resolution))
    mesh = symmetric_mesh(n)
    P = mesh.points
    b = mesh.boundary_nodes
    skull = np.sort(np.asarray(mesh.boundary_loops[0]))
    mouth_rim = np.intersect1d(b, nodes_near(mesh, MOUTH_C, MOUTH_AX[0] + 0.05))
    lx, ly = -EYE_C[0], EYE_C[1]
    left_eye = np.intersect1d(b, nodes_near(mesh, (lx, ly), EYE_AX[0] + 0.05))
    corners = [nodes_near(mesh, (s * MOUTH_AX[0] + MOUTH_C[0], MOUTH_C[1]), 0.22) for s in (-1, 1)]
    corners = [np.intersect1d(c, mouth_rim) for c in corners]

    upper_face = np.flatnonzero(P[:, 1] > SKULL_Y)
    chin = np.flatnonzero(P[:, 1] < CHIN_Y)
    lid = left_eye[P[left_eye, 1] > ly + 1e-9]
    regions = {"rim": skull, "mouth_corners": np.concatenate(corners), "left_upper_lid": lid,
               "mouth": mouth_rim, "left_eye": left_eye, "upper_face": upper_face, "chin": chin}

    def corner_case(name, dx, dy, held, text, muscles=None):
        nodes = np.concatenate(corners)
        pos = np.vstack([P[corners[0]] + (-dx, dy), P[corners[1]] + (dx, dy)])
        return Case(name, anchors=held, drag_nodes=nodes, drag_positions=pos, description=text, muscles=muscles)

    squeezed = np.column_stack([lx + SQUEEZE[0] * (P[left_eye, 0] - lx), ly + SQUEEZE[1] * (P[left_eye, 1] - ly)])
    drawn = (
        corner_case("smile", 0.25, 0.35, upper_face, "mouth corners pulled up and out, the upper face held"),
        corner_case("frown", 0.0, -0.3, chin, "mouth corners pulled down, the chin held"),
        Case("wink", drag_nodes=left_eye, drag_positions=squeezed, description="left eye squeezed nearly shut"),
        corner_case("pucker", -0.3, 0.0, np.zeros(0, dtype=np.int64), "mouth corners pulled in"),
    )
    # plane strain, nu = 0.4, E = 1 (units of stress): the library's law, kept so results stay comparable;
    # a cast silicone face is a thin incompressible sheet, NeoHookean(1.0, 0.5, plane="stress"), which moves
    # the nodes of these expressions by up to 6.6 % of the largest motion (default resolution)
    material = NeoHookean(E=1.0, nu=0.4)
    routing = {"K_a": 10.0, "K_b": 4.0, "max_muscles": 4, "n_seeds": seeds_for(mesh)}
    layout, targets = one_layout(mesh, material, drawn, {**routing, **EXPRESSION_ROUTING}, ANCHOR_RADIUS)
    # every expression is designed on the muscles of the one layout it pulls
    cases = tuple(Case(c.name, anchors=c.anchors, drag_nodes=c.drag_nodes, drag_positions=c.drag_positions,
                       description=c.description, muscles=engaged(layout, mesh, targets[c.name])) for c in drawn)
    # one animation per expression: an animation of several expressions drives the union of their muscles,
    # and a rope at zero contraction cannot lengthen, so the lips' ropes would hold the smile back (and the
    # forward solves with such taut idle ropes are rejected on their residual)
    anims = tuple(Animation(f"{c}_anim", (("rest", 0.0), (c, 1.0), ("rest", 0.0)), frames_per_step=4)
                  for c in ("smile", "frown", "wink", "pucker"))
    return Scene(
        name="face", title="Humanoid face: smile, frown, wink and pucker by external driving",
        description=__doc__.split("\n\n")[1].replace("\n", " "), mesh=mesh, material=material,
        cases=cases, regions=regions,
        routing_options=routing,
        design_options={"method": "flattened", "a_max": 0.6, "anchor_radius": ANCHOR_RADIUS}, animations=anims,
        expected={"max_muscles": 4}, resolution=n, source=__file__)


if __name__ == "__main__":
    raise SystemExit(run_main(build))
