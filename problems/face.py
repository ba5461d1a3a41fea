"""Humanoid face: an outline with eye and mouth holes, and four expressions as targets.

The paper's introduction and conclusion name humanoid faces as the complex deformations its framework is
for (after the face "cloning" work it cites) but show no face. This scene is one: an egg-shaped face
6 units wide and 8 tall with two eye holes and a mouth hole, meshed mirror-symmetrically about x = 0. Each
expression holds the face only where the muscle that makes it is anchored to bone, and drags the points
that muscle moves (external driving): ``smile`` (the mouth corners pulled up and out, the upper face held:
the zygomatici), ``frown`` (the corners pulled down, the chin held: the depressors, found by routing),
``wink`` (the left eye squeezed nearly shut, its rim drawn to 60 % of its width and 40 % of its height:
the orbicularis oculi along both lids; nothing held) and ``pucker`` (the corners pulled in: the orbicularis
oris along both lips; nothing held). The design drives a free body, so a target whose whole rim is held (a
mask glued to a frame, this scene's first version) asks for reactions no muscle inside the face can make:
the design then dents the rim and barely moves the mouth (17-45 % of the drag motion). Each expression has
an animation ``<case>_anim`` (rest, expression, rest).

The shapes are drawn by the mdsr_opt authors from the paper's descriptions (it gives no geometry); they
are not the paper's meshes. A face needs at least ``MIN_NODES`` = 300 nodes: on coarser meshes the
mouth corners are two or three nodes and routing finds no muscle for the smile and the frown, so the
``coarse`` resolution is raised to 300 here.

How well a design makes its expression is :func:`motion_recovered`: the share of the drag motion the
muscle-driven face reproduces, over the dragged nodes, after rigid alignment.

Run ``python problems/face.py --out out/face`` or ``mdsr run face --out out/face``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from mdsr_opt import Mesh, Muscle, NeoHookean
from mdsr_opt.scenes.scene import Animation, Case, Scene, mesh_polygon, resolve_resolution, seeds_for
from mdsr_opt.scenes.select import boundary_path, edge_path, nodes_near
from mdsr_opt.scenes.runscene import run_main

EYE_C, EYE_AX = (1.2, 0.9), (0.65, 0.28)       # right eye centre (the left is mirrored) and semi-axes
MOUTH_C, MOUTH_AX = (0.0, -1.9), (1.1, 0.25)
SKULL_Y = -0.5                                  # the smile holds the face above this line (the skull)
CHIN_Y = -3.3                                   # the frown holds the face below this line (the jaw bone)
ZYGOMATICUS = ((1.1, -1.9), (1.5, -1.3), (1.6, -0.5))   # the right smile muscle's waypoints (left mirrored)
ANCHOR_RADIUS = 0.05                             # rigid muscle-end patches smaller than an eye (default ~0.3)
MAX_TURN = 45.0                                 # the routing's tortuosity limit, obeyed by the laid muscles
MIN_NODES = 300                                 # fewer do not resolve the mouth corners: "coarse" gets this
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


def trimmed(mesh: Mesh, muscle: Muscle, max_turn: float = MAX_TURN) -> Muscle:
    """The muscle without end nodes at which it turns by more than ``max_turn`` (an eye's sharp corner)."""
    v = list(muscle.nodes)
    while len(v) > 3 and turns(mesh, v)[-1] > max_turn:
        v = v[:-1]
    while len(v) > 3 and turns(mesh, v)[0] > max_turn:
        v = v[1:]
    return Muscle(v, name=muscle.name)


def straight_path(mesh: Mesh, way, name: str, max_turn: float = MAX_TURN) -> Muscle:
    """A muscle along mesh edges that follows the polyline ``way`` closely without sharp corners: from the node
    nearest its start, each step takes the neighbour whose edge best points along the polyline (penalised by
    its distance from the polyline), turning by at most ``max_turn`` where any neighbour allows, until the
    node nearest the polyline's end is reached."""
    P = mesh.points
    way = np.asarray(way, dtype=float)
    nbrs: dict[int, set] = {}
    for a, b in mesh.edges.tolist():
        nbrs.setdefault(a, set()).add(b)
        nbrs.setdefault(b, set()).add(a)
    h = float(np.mean(mesh.edge_lengths))
    end = int(np.argmin(np.linalg.norm(P - way[-1], axis=1)))
    v = [int(np.argmin(np.linalg.norm(P - way[0], axis=1)))]
    seg = 0

    def offset(p):  # distance to the polyline
        best = np.inf
        for a, b in zip(way[:-1], way[1:]):
            t = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
            best = min(best, float(np.linalg.norm(p - a - t * (b - a))))
        return best

    while v[-1] != end and len(v) < 10 * len(P):
        x = P[v[-1]]
        while seg < len(way) - 2 and np.dot(x - way[seg + 1], way[seg + 1] - way[seg]) > -0.5 * h:
            seg += 1
        goal = way[seg + 1] - x if np.linalg.norm(way[seg + 1] - x) > 1e-12 else way[-1] - x
        goal = goal / max(np.linalg.norm(goal), 1e-12)
        prev = P[v[-1]] - P[v[-2]] if len(v) > 1 else None
        scored = []
        for w in nbrs[v[-1]] - set(v):
            d = P[w] - x
            d = d / np.linalg.norm(d)
            turn = 0.0 if prev is None else np.degrees(np.arccos(np.clip(np.dot(d, prev / np.linalg.norm(prev)),
                                                                          -1, 1)))
            scored.append((turn > max_turn, -(np.dot(d, goal) - offset(P[w]) / h), w))
        if not scored:
            break
        w = min(scored)[2]
        if seg == len(way) - 2 and np.linalg.norm(P[w] - way[-1]) >= np.linalg.norm(x - way[-1]):
            break  # past the end: stop rather than turn back
        v.append(w)
        if np.linalg.norm(P[v[-1]] - way[-1]) < 0.5 * h:
            break
    return Muscle(v, name=name)


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

    # the smile's muscles: a zygomaticus on each side, from the mouth corner up into the held upper face
    # (routing on this target cuts each into two short pieces and their design stalls at medium resolution)
    zygomatici = tuple(straight_path(mesh, [(s * x, y) for x, y in ZYGOMATICUS], name=f"zygomaticus {side}")
                       for s, side in ((-1, "left"), (1, "right")))
    # the wink: the left eye's rim drawn in about its centre (an orbicularis oculi squeezing it); its muscles
    # run along the upper and the lower lid. Routing lays them a ring of elements outside the rim, where
    # they shrink the eye less. A rope along a flat eye pulls its corners in as much as its lids together
    # (the eye shrinks rather than shuts), so the target narrows the eye as it closes it.
    ex, ey = EYE_AX
    lids = tuple(trimmed(mesh, boundary_path(mesh, (lx - ex, ly), (lx + ex, ly), via=(lx, ly + u * ey),
                                             name=f"{n} lid")) for u, n in ((1, "upper"), (-1, "lower")))
    # the pucker: an orbicularis oris along each lip from corner to corner (routed muscles there are as good
    # on coarse meshes but come out lopsided on finer ones)
    mx, my = MOUTH_C
    lips = tuple(boundary_path(mesh, (mx - MOUTH_AX[0], my), (mx + MOUTH_AX[0], my), via=(mx, my + u * MOUTH_AX[1]),
                               name=f"{n} lip") for u, n in ((1, "upper"), (-1, "lower")))
    squeezed = np.column_stack([lx + SQUEEZE[0] * (P[left_eye, 0] - lx), ly + SQUEEZE[1] * (P[left_eye, 1] - ly)])
    cases = (
        corner_case("smile", 0.25, 0.35, upper_face, "mouth corners pulled up and out, the upper face held",
                    zygomatici),
        corner_case("frown", 0.0, -0.3, chin, "mouth corners pulled down, the chin held"),
        Case("wink", drag_nodes=left_eye, drag_positions=squeezed, muscles=lids,
             description="left eye squeezed nearly shut"),
        corner_case("pucker", -0.3, 0.0, np.zeros(0, dtype=np.int64), "mouth corners pulled in", lips),
    )
    # one animation per expression: an animation of several expressions drives the union of their muscles,
    # and a rope at zero contraction cannot lengthen, so the lips' ropes would hold the smile back (and the
    # forward solves with such taut idle ropes are rejected on their residual)
    anims = tuple(Animation(f"{c}_anim", (("rest", 0.0), (c, 1.0), ("rest", 0.0)), frames_per_step=4)
                  for c in ("smile", "frown", "wink", "pucker"))
    return Scene(
        name="face", title="Humanoid face: smile, frown, wink and pucker by external driving",
        description=__doc__.split("\n\n")[1].replace("\n", " "), mesh=mesh,
        # plane strain, nu = 0.4, E = 1 (units of stress): the library's law, kept so results stay comparable;
        # a cast silicone face is a thin incompressible sheet, NeoHookean(1.0, 0.5, plane="stress"), which moves
        # the nodes of these expressions by up to 6.6 % of the largest motion (default resolution)
        material=NeoHookean(E=1.0, nu=0.4),
        cases=cases, regions=regions,
        routing_options={"K_a": 10.0, "K_b": 4.0, "max_muscles": 4, "n_seeds": seeds_for(mesh)},
        design_options={"method": "flattened", "a_max": 0.6, "anchor_radius": ANCHOR_RADIUS}, animations=anims,
        expected={"max_muscles": 4}, resolution=n, source=__file__)


if __name__ == "__main__":
    raise SystemExit(run_main(build))
