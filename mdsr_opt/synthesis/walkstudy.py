"""A walk's refinement study: one muscle layout and one stroke schedule, walked on nested refinements of the mesh
they were designed on, so that only the mesh changes from one level to the next.

Each level splits every triangle of the last into four through its edge midpoints
(:func:`~mdsr_opt.mechanics.quadratic.split_mesh`): the outline, the nodes of the coarser levels and so every
rope's rest polyline stay where they were (a rope through nodes ``a, b`` runs through ``a``, the midpoint of
``ab``, ``b``), the strokes keep their meaning (the same rest lengths), and a foot is the same piece of the body
(its nodes and the midpoints of the edges between them). A layout designed anew on each mesh would change the
ropes, the strokes and the feet with it, and the study would not show the mesh's own error. The feet's weight
rests on the area they cover (:func:`~mdsr_opt.synthesis.walk.node_loads`), the same on every level.

The levels start from a base mesh that resolves what is smallest: a rope's end patch (``anchor_radius``, 4 % of
the body's size by default) narrower than the design mesh's edges holds a single node, a point force under which
the body's displacement grows without bound as the mesh refines, so the body bends less and less for the same
strokes until the patch spans several elements. ``local`` refines the mesh near the ropes' ends first (red-green:
nested and conforming, :func:`refine_walker` with ``near``). :func:`richardson` estimates the limit from the
last three levels.

:func:`walk_refinement` walks a stroke schedule on ``levels`` such meshes; :func:`walk_scene_refinement` designs
nothing, it takes a scene's gait schedule of a given layout (on the scene's mesh) and walks it on the refinements.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..body.mesh import Mesh
from ..body.muscles import Muscle, check_muscles
from ..core.checks import as_float_array, positive_int
from ..mechanics.quadratic import split_mesh
from .walk import foot_groups, scene_schedule, schedule_cycle, walk

__all__ = ["refine_walker", "walk_refinement", "walk_scene_refinement", "richardson"]


def _split_edges(mesh: Mesh, marked) -> np.ndarray:
    """The rows of ``mesh.edges`` to split so that the triangles ``marked`` (bool per triangle) split into four
    and the mesh stays conforming: every edge of a marked triangle, then every edge of a triangle with two split
    edges, until none has two (red-green closure: a triangle is split into four or halved through one edge)."""
    t = mesh.triangles
    te = mesh.edge_rows(t[:, [0, 1, 2]].ravel(), t[:, [1, 2, 0]].ravel()).reshape(-1, 3)
    split = np.zeros(len(mesh.edges), dtype=bool)
    split[te[np.asarray(marked, dtype=bool)].ravel()] = True
    while True:
        grow = split[te].sum(1) == 2
        if not grow.any():
            return split
        split[te[grow].ravel()] = True


def _split_local(mesh: Mesh, split) -> tuple:
    """``mesh`` with the edges ``split`` (bool per row of ``mesh.edges``, closed by :func:`_split_edges`) halved:
    a triangle with three split edges becomes four (through its edge midpoints), one with one split edge two
    (through that midpoint and the opposite corner); ``(fine, mid)`` with ``mid[row]`` the fine node at the
    midpoint of edge ``row`` (-1 where it is not split). The nodes of ``mesh`` keep their indices."""
    P, E, t = mesh.points, np.asarray(mesh.edges, dtype=np.int64), mesh.triangles
    rows = np.flatnonzero(split)
    mid = np.full(len(E), -1, dtype=np.int64)
    mid[rows] = mesh.n_nodes + np.arange(len(rows))
    pts = np.vstack([P, 0.5 * (P[E[rows, 0]] + P[E[rows, 1]])])
    m = mid[mesh.edge_rows(t[:, [0, 1, 2]].ravel(), t[:, [1, 2, 0]].ravel()).reshape(-1, 3)]
    cnt = (m >= 0).sum(1)
    if (cnt == 2).any():
        raise ValueError("the split edges are not closed: a triangle has two split edges")
    a, b, c = t[:, 0], t[:, 1], t[:, 2]
    r = cnt == 3
    out = [t[cnt == 0],
           np.column_stack([a[r], m[r, 0], m[r, 2]]), np.column_stack([m[r, 0], b[r], m[r, 1]]),
           np.column_stack([m[r, 2], m[r, 1], c[r]]), np.column_stack([m[r, 0], m[r, 1], m[r, 2]])]
    for k in range(3):  # one split edge k (corners k, k+1): two triangles through its midpoint
        g = (cnt == 1) & (m[:, k] >= 0)
        v0, v1, v2 = t[g, k], t[g, (k + 1) % 3], t[g, (k + 2) % 3]
        out += [np.column_stack([v0, m[g, k], v2]), np.column_stack([m[g, k], v1, v2])]
    return Mesh(pts, np.vstack(out)), mid


def refine_walker(mesh: Mesh, muscles: Sequence, node_sets: Mapping | None = None, state=None, *,
                  near=None, distance: float | None = None) -> tuple:
    """``mesh`` split once with its muscles, node sets and a state carried over: ``(mesh, muscles, node_sets,
    state)``. Without ``near`` every triangle splits into four
    (:func:`~mdsr_opt.mechanics.quadratic.split_mesh`); with ``near`` ((k, 2) points) and ``distance`` only the
    triangles with a corner within ``distance`` of one of them do, their neighbours closing the mesh (a
    neighbour with one split edge halves through it, one with two splits into four: the refinement stays
    nested and conforming). A muscle runs through the same nodes and the midpoints of its split segments; a
    node set (a foot) keeps its nodes and gains the midpoints of the split edges between two of them; the state
    (n, 2) is interpolated linearly (exact on the split mesh; None stays None)."""
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    mus = check_muscles(mesh, muscles)
    E = np.asarray(mesh.edges, dtype=np.int64)
    if near is None:
        fine, mid = split_mesh(mesh), mesh.n_nodes + np.arange(len(E))
    else:
        C = np.asarray(near, dtype=float).reshape(-1, 2)
        d = float(distance) if distance is not None else np.nan
        if not len(C) or not np.isfinite(C).all() or not (np.isfinite(d) and d > 0):
            raise ValueError("near must be finite points (k, 2), at least one, and distance a length > 0, got "
                             f"{len(C)} point(s) and distance {distance!r}")
        close = (np.hypot(*(mesh.points[:, None, :] - C[None, :, :]).transpose(2, 0, 1)) <= d).any(1)
        fine, mid = _split_local(mesh, _split_edges(mesh, close[mesh.triangles].any(1)))
    out_mus = []
    for m in mus:
        seg = m.segments
        sm = mid[mesh.edge_rows(seg[:, 0], seg[:, 1])]
        path = [m.nodes[0]]
        for k in range(len(seg)):
            path += ([int(sm[k])] if sm[k] >= 0 else []) + [int(seg[k, 1])]
        out_mus.append(Muscle(path, name=m.name))
    sets = {}
    for k, v in dict(node_sets or {}).items():
        v = np.unique(np.asarray(v, dtype=np.int64).reshape(-1))
        if not len(v) or v.min() < 0 or v.max() >= mesh.n_nodes:
            raise ValueError(f"node set {k!r}: node indices must be in [0, {mesh.n_nodes}), at least one")
        inside = np.zeros(mesh.n_nodes, dtype=bool)
        inside[v] = True
        sets[k] = np.concatenate([v, mid[inside[E].all(1) & (mid >= 0)]])
    x = None
    if state is not None:
        X = np.asarray(state, dtype=float)
        if X.shape != mesh.points.shape or not np.isfinite(X).all():
            raise ValueError(f"state must be finite positions of the mesh's {mesh.n_nodes} nodes, got shape "
                             f"{X.shape}")
        rows = np.flatnonzero(mid >= 0)
        x = np.vstack([X, 0.5 * (X[E[rows, 0]] + X[E[rows, 1]])])
    return fine, out_mus, sets, x


def walk_refinement(mesh: Mesh, material, muscles: Sequence, strokes, *, levels: int = 3, feet=None,
                    feet_groups: Mapping | None = None, start=None, local: Sequence = (), progress=None,
                    **kwargs) -> list:
    """:func:`~mdsr_opt.synthesis.walk.walk` of the same strokes on a base mesh and on ``levels - 1`` nested
    refinements of it (:func:`refine_walker`, every triangle split into four): ``[(mesh, WalkResult), ...]``,
    coarsest first. The base mesh is ``mesh``, or with ``local`` (distances, length units) ``mesh`` refined
    near the ropes' ends first, one round per distance (:func:`refine_walker` with ``near`` the end nodes): a
    rope's end patch (``anchor_radius``) smaller than the mesh's edges holds one node, a point force, and is
    resolved on no level of a coarse mesh's refinements that one can afford. ``feet`` and ``feet_groups``
    (node indices of ``mesh``) and ``start`` ((n, 2), the body in the cycle's first frame) are carried to every
    level; ``kwargs`` go to :func:`~mdsr_opt.synthesis.walk.walk` (``mu``, ``cycles``, ``touching``,
    ``weight``, ``anchor_radius``, ``units``...). ``progress(level, mesh, result)``, if given, is called after
    each level."""
    levels = positive_int(levels, "levels")
    local = as_float_array(local, "local").reshape(-1).tolist()
    if not all(np.isfinite(d) and d > 0 for d in local):
        raise ValueError(f"local must be distances > 0 (one per round of refinement near the ropes' ends), "
                         f"got {local!r}")
    sets = {("group", k): v for k, v in dict(feet_groups or {}).items()}
    if feet is not None:
        sets[("feet",)] = feet
    out = []
    m, mus, x = mesh, list(muscles), None if start is None else np.asarray(start, dtype=float)
    ends = np.array([mesh.points[[u.nodes[0], u.nodes[-1]]] for u in check_muscles(mesh, mus)]).reshape(-1, 2)
    for d in local:
        m, mus, sets, x = refine_walker(m, mus, sets, x, near=ends, distance=d)
    for level in range(levels):
        if level:
            m, mus, sets, x = refine_walker(m, mus, sets, x)
        groups = {k[1]: v for k, v in sets.items() if k[0] == "group"}
        r = walk(m, material, mus, strokes, feet=sets.get(("feet",)), feet_groups=groups or None, start=x,
                 **kwargs)
        out.append((m, r))
        if progress is not None:
            progress(level, m, r)
    return out


def walk_scene_refinement(scene, layout, *, levels: int = 3, sequence=None, frames_per_step: int | None = None,
                          feet: str = "region", from_rest: bool = False, local: Sequence = (), progress=None,
                          **kwargs) -> tuple:
    """A scene's gait (the schedule of ``layout`` on the scene's mesh, solved once by
    :func:`~mdsr_opt.synthesis.gait.gait_schedule`) walked on the scene's mesh and its nested refinements
    (:func:`walk_refinement`): ``(schedule, [(mesh, WalkResult), ...])``. ``feet`` as in
    :func:`~mdsr_opt.synthesis.walk.walk_scene`; the walk starts from the schedule's first frame (solved on the
    scene's mesh, settled on each level), or with ``from_rest`` from the rest shape (as when ``anchor_radius``,
    passed on to :func:`~mdsr_opt.synthesis.walk.walk`, is not the layout's); ``local`` as in
    :func:`walk_refinement`; ``kwargs`` go to :func:`~mdsr_opt.synthesis.walk.walk`."""
    sch, region = scene_schedule(scene, layout, sequence=sequence, frames_per_step=frames_per_step, feet=feet)
    S, touching = schedule_cycle(sch, kwargs.get("touching"))
    if touching is not None:
        kwargs["touching"] = touching
    start = sch.states[0] if bool(sch.frame_success[0]) and not from_rest else None
    kwargs.setdefault("units", sch.units)
    kwargs.setdefault("anchor_radius", layout.anchor_radius)
    groups = foot_groups(scene.mesh, region) if region is not None else None
    runs = walk_refinement(scene.mesh, scene.material, layout.muscles, S, levels=levels,
                           feet=region if feet == "region" else None, feet_groups=groups, start=start,
                           local=local, progress=progress, **kwargs)
    return sch, runs


def richardson(values) -> dict:
    """The convergence of a quantity over nested refinements (each halving the mesh size), coarsest first:
    ``changes`` from one level to the next and their ``ratios``; from the last two changes (``d`` the last,
    ``q`` its ratio to the one before, ``v`` the last value), when they shrink (``|q| < 1``): with one sign
    (``q > 0``) the observed ``order`` ``log2(1/q)``, the ``extrapolated`` limit ``v + d q / (1 - q)`` (the
    changes continued as a geometric series) and its ``error`` ``|d q / (1 - q)|``; with alternating signs the
    limit ``v`` with the error ``|d|`` (order None). Else (changes that do not shrink) those three are None."""
    v = as_float_array(values, "values").reshape(-1)
    if len(v) < 2 or not np.isfinite(v).all():
        raise ValueError(f"values must be two finite numbers or more, got {v.tolist()}")
    d = np.diff(v)
    ratios = [float(d[k + 1] / d[k]) if d[k] != 0 else float("nan") for k in range(len(d) - 1)]
    out = {"values": v.tolist(), "changes": d.tolist(), "ratios": ratios, "order": None, "extrapolated": None,
           "error": None}
    if ratios and 0.0 < ratios[-1] < 1.0:
        q = ratios[-1]
        tail = float(d[-1] * q / (1.0 - q))
        out.update(order=float(np.log2(1.0 / q)), extrapolated=float(v[-1] + tail), error=abs(tail))
    elif ratios and -1.0 < ratios[-1] <= 0.0:
        out.update(extrapolated=float(v[-1]), error=float(abs(d[-1])))
    return out
