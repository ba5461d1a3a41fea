"""A walk's refinement study: one muscle layout and one stroke schedule, walked on nested refinements of the mesh
they were designed on, so that only the mesh changes from one level to the next.

Each level splits every triangle of the last into four through its edge midpoints
(:func:`~mdsr_opt.mechanics.quadratic.split_mesh`): the outline, the nodes of the coarser levels and so every
rope's rest polyline stay where they were (a rope through nodes ``a, b`` runs through ``a``, the midpoint of
``ab``, ``b``), the strokes keep their meaning (the same rest lengths), and a foot is the same piece of the body
(its nodes and the midpoints of the edges between them). A layout designed anew on each mesh would change the
ropes, the strokes and the feet with it, and the study would not show the mesh's own error.

:func:`walk_refinement` walks a stroke schedule on ``levels`` such meshes; :func:`walk_scene_refinement` designs
nothing, it takes a scene's gait schedule of a given layout (on the scene's mesh) and walks it on the refinements.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..body.mesh import Mesh
from ..body.muscles import Muscle, check_muscles
from ..core.checks import positive_int
from ..mechanics.quadratic import split_mesh
from .walk import foot_groups, scene_schedule, walk

__all__ = ["refine_walker", "walk_refinement", "walk_scene_refinement"]


def _midpoints(mesh: Mesh, a, b) -> np.ndarray:
    """The node of the split mesh at the midpoint of each edge ``(a[k], b[k])`` of ``mesh`` (edges, as
    :func:`~mdsr_opt.body.muscles.check_muscles` checks a muscle's segments)."""
    return mesh.n_nodes + mesh.edge_rows(np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64))


def refine_walker(mesh: Mesh, muscles: Sequence, node_sets: Mapping | None = None, state=None) -> tuple:
    """``mesh`` split once (:func:`~mdsr_opt.mechanics.quadratic.split_mesh`) with its muscles, node sets and a
    state carried over: ``(mesh, muscles, node_sets, state)``. A muscle runs through the same nodes and the
    midpoints of its segments; a node set (a foot) keeps its nodes and gains the midpoints of the mesh edges
    between two of them; the state (n, 2) is interpolated linearly (exact on the split mesh; None stays None)."""
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    mus = check_muscles(mesh, muscles)
    fine = split_mesh(mesh)
    out_mus = []
    for m in mus:
        seg = m.segments
        mid = _midpoints(mesh, seg[:, 0], seg[:, 1])
        path = np.empty(2 * len(seg) + 1, dtype=np.int64)
        path[0::2], path[1::2] = m.nodes, mid
        out_mus.append(Muscle(path.tolist(), name=m.name))
    E = np.asarray(mesh.edges, dtype=np.int64)
    sets = {}
    for k, v in dict(node_sets or {}).items():
        v = np.unique(np.asarray(v, dtype=np.int64).reshape(-1))
        if not len(v) or v.min() < 0 or v.max() >= mesh.n_nodes:
            raise ValueError(f"node set {k!r}: node indices must be in [0, {mesh.n_nodes}), at least one")
        inside = np.zeros(mesh.n_nodes, dtype=bool)
        inside[v] = True
        sets[k] = np.concatenate([v, mesh.n_nodes + np.flatnonzero(inside[E].all(1))])
    x = None
    if state is not None:
        X = np.asarray(state, dtype=float)
        if X.shape != mesh.points.shape or not np.isfinite(X).all():
            raise ValueError(f"state must be finite positions of the mesh's {mesh.n_nodes} nodes, got shape "
                             f"{X.shape}")
        x = np.vstack([X, 0.5 * (X[E[:, 0]] + X[E[:, 1]])])
    return fine, out_mus, sets, x


def walk_refinement(mesh: Mesh, material, muscles: Sequence, strokes, *, levels: int = 3, feet=None,
                    feet_groups: Mapping | None = None, start=None, progress=None, **kwargs) -> list:
    """:func:`~mdsr_opt.synthesis.walk.walk` of the same strokes on ``mesh`` and on ``levels - 1`` nested
    refinements of it (:func:`refine_walker`): ``[(mesh, WalkResult), ...]``, coarsest first. ``feet`` and
    ``feet_groups`` (node indices of ``mesh``) and ``start`` ((n, 2), the body in the cycle's first frame) are
    carried to every level; ``kwargs`` go to :func:`~mdsr_opt.synthesis.walk.walk` (``mu``, ``cycles``,
    ``touching``, ``weight``, ``anchor_radius``, ``units``...). ``progress(level, mesh, result)``, if given,
    is called after each level."""
    levels = positive_int(levels, "levels")
    sets = {("group", k): v for k, v in dict(feet_groups or {}).items()}
    if feet is not None:
        sets[("feet",)] = feet
    out = []
    m, mus, x = mesh, list(muscles), None if start is None else np.asarray(start, dtype=float)
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
                          feet: str = "region", from_rest: bool = False, progress=None, **kwargs) -> tuple:
    """A scene's gait (the schedule of ``layout`` on the scene's mesh, solved once by
    :func:`~mdsr_opt.synthesis.gait.gait_schedule`) walked on the scene's mesh and its nested refinements
    (:func:`walk_refinement`): ``(schedule, [(mesh, WalkResult), ...])``. ``feet`` as in
    :func:`~mdsr_opt.synthesis.walk.walk_scene`; the walk starts from the schedule's first frame (solved on the
    scene's mesh, settled on each level), or with ``from_rest`` from the rest shape (as when ``anchor_radius``,
    passed on to :func:`~mdsr_opt.synthesis.walk.walk`, is not the layout's); ``kwargs`` go to
    :func:`~mdsr_opt.synthesis.walk.walk`."""
    sch, region = scene_schedule(scene, layout, sequence=sequence, frames_per_step=frames_per_step, feet=feet)
    S = np.asarray(sch.strokes, dtype=float)
    if len(S) > 1 and np.allclose(S[0], S[-1]):
        S = S[:-1]
    start = sch.states[0] if bool(sch.success[0]) and not from_rest else None
    kwargs.setdefault("units", sch.units)
    kwargs.setdefault("anchor_radius", layout.anchor_radius)
    groups = foot_groups(scene.mesh, region) if region is not None else None
    runs = walk_refinement(scene.mesh, scene.material, layout.muscles, S, levels=levels,
                           feet=region if feet == "region" else None, feet_groups=groups, start=start,
                           progress=progress, **kwargs)
    return sch, runs
