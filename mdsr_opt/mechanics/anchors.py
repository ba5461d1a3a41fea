"""Anchor patches: the rigid ends of a muscle, of a physical size.

A rope that ends on one node pulls the body with a point force, under which a planar elastic body has no
finite displacement: the end segments collapse further with every refinement. Each end is therefore anchored
over a patch of physical size, the way a knot, bead or plate spreads the force: the body nodes within
``radius`` of the end node at rest (and connected to it through such nodes) move rigidly with it. The radius
defaults to :data:`ANCHOR_FRACTION` of the body's size (its diameter at rest, :func:`body_size`),
:func:`default_anchor_radius`; it is never a number of nodes. A node equally far from both ends of one
muscle, or nearer the other end, is left out of an end's patch, so the two patches of a muscle never
overlap. Patches of *different* muscles that share a node are merged into one rigid group
(:func:`rigid_groups`), which :class:`~mdsr_opt.mechanics.constraints.MuscleConstraints` keeps rigid.

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh, Muscle
>>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
>>> bottom = [i for i in np.argsort(mesh.points[:, 0]) if mesh.points[i, 1] == 0.0]
>>> (start, end), = anchor_patches(mesh, [Muscle(bottom)], radius=0.3)
>>> sorted(start.tolist()), len(end)
([0, 1, 17], 3)
"""

from __future__ import annotations

import numpy as np

from ..core.errors import LayoutError
from ..core.checks import positive_float
from ..body.muscles import Muscle, check_muscles, label_of

__all__ = ["ANCHOR_FRACTION", "MAX_ANCHOR_FRACTION", "body_size", "convex_hull", "default_anchor_radius", "check_anchor_radius",
           "anchor_radius_or_default", "point_diameter", "valid_muscles", "anchor_patches", "rigid_groups",
           "patch_groups"]

#: Default anchor radius as a fraction of the body's size (its diameter at rest, :func:`body_size`).
ANCHOR_FRACTION = 0.04


def convex_hull(P) -> np.ndarray:
    """The vertices of the convex hull of points ``P`` (m, 2), counter-clockwise from the lowest-leftmost
    (Andrew's monotone chain; points on an edge of the hull are left out). Points all on a line: its two
    ends; fewer than three distinct points: those."""
    P = np.asarray(P, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2:
        raise ValueError(f"points must have shape (m, 2), got {P.shape}")
    if not np.isfinite(P).all():
        raise ValueError("points must be finite")
    P = np.unique(P, axis=0)  # sorted by x, then y
    if len(P) < 3:
        return P
    # the turns are measured on the points moved to the origin and scaled by a power of 2 to about 1 (no
    # underflow or overflow at any scale; the hull is the same)
    Q = P - P[0]
    span = float(np.abs(Q).max())
    Q = (Q * 2.0 ** -int(np.frexp(span)[1])).tolist()

    def chain(order):
        h: list = []
        for k in order:
            p = Q[k]
            while len(h) >= 2 and ((Q[h[-1]][0] - Q[h[-2]][0]) * (p[1] - Q[h[-2]][1])
                                   - (Q[h[-1]][1] - Q[h[-2]][1]) * (p[0] - Q[h[-2]][0])) <= 0.0:
                h.pop()
            h.append(k)
        return h

    idx = range(len(P))
    return P[chain(idx)[:-1] + chain(reversed(idx))[:-1]]


def body_size(mesh) -> float:
    """The body's diameter at rest: the largest distance between two of its nodes.

    Unlike the bounding-box diagonal (``mesh.size``) it does not change when the body is rotated; for an
    axis-aligned rectangle the two agree.
    """
    cache = mesh.__dict__
    if "_diameter" not in cache:
        # the farthest pair of nodes are vertices of the convex hull, which are boundary nodes (every node
        # belongs to a triangle): the hull of those
        cache["_diameter"] = point_diameter(mesh.points[mesh.boundary_nodes])
    return cache["_diameter"]


def point_diameter(P) -> float:
    """The largest distance between two of the points ``P`` (m, 2) (0 for fewer than two): the largest
    between two vertices of their convex hull, without importing scipy.spatial on the path of every scene's
    build."""
    V = convex_hull(P)
    d = 0.0
    for i0 in range(0, len(V), 1024):
        d = max(d, float(np.sqrt(((V[i0:i0 + 1024, None, :] - V[None, :, :]) ** 2).sum(-1)).max()))
    return d


def default_anchor_radius(mesh) -> float:
    """The default anchor radius: :data:`ANCHOR_FRACTION` (0.04) times :func:`body_size`, in length units."""
    return ANCHOR_FRACTION * body_size(mesh)


def valid_muscles(mesh, muscles) -> list:
    """:func:`~mdsr_opt.body.muscles.check_muscles`, remembered per mesh for lists of :class:`Muscle`: a list of
    node chains checked on this mesh once is not walked edge by edge again (a design checks its muscles
    through a dozen functions)."""
    seq = [muscles] if isinstance(muscles, Muscle) else muscles
    if not isinstance(seq, (list, tuple)) or not seq or not all(isinstance(m, Muscle) for m in seq):
        return check_muscles(mesh, muscles)
    key = tuple((m.nodes, m.name) for m in seq)  # the names too: two muscles with one label are refused
    checked = mesh.__dict__.setdefault("_checked_muscle_chains", set())
    if key not in checked:
        out = check_muscles(mesh, seq)
        if len(checked) >= 64:
            checked.clear()
        checked.add(key)
        return out
    return list(seq)


#: An anchor radius must stay below this fraction of :func:`body_size` (a patch as wide as half the body
#: would hold most of it rigid).
MAX_ANCHOR_FRACTION = 0.5


def anchor_radius_or_default(mesh, radius) -> float:
    """``radius`` as a float, or :func:`default_anchor_radius` for None: for the functions behind the doors,
    which take the radius :func:`check_anchor_radius` checked (or any radius, see :func:`anchor_patches`)."""
    return default_anchor_radius(mesh) if radius is None else float(radius)


def _ball(mesh, centre: int, other: int, radius: float) -> list[int]:
    """Nodes within ``radius`` of ``centre`` at rest and strictly nearer to it than to ``other`` (the
    muscle's other end), connected to it through such nodes, by increasing distance.

    Only the nodes whose rest ``x`` lies within the radius of the centre's (plus a margin for round-off) are
    looked at, found by a binary search in the nodes sorted by ``x``; the distances are then the same numpy
    norms as over the whole mesh, and the breadth-first search walks the mesh's edges among them."""
    P = mesh.points
    order, xs = _nodes_by_x(mesh)
    cx = float(P[centre, 0])
    reach = radius * (1.0 + 1e-9) + 1e-12 * (abs(cx) + radius)
    lo, hi = int(np.searchsorted(xs, cx - reach, side="left")), int(np.searchsorted(xs, cx + reach, side="right"))
    cand = np.unique(np.append(order[lo:hi], centre))  # sorted, the centre among them at any radius
    dist = np.linalg.norm(P[cand] - P[centre], axis=1)
    inside = (dist <= radius) & (dist < np.linalg.norm(P[cand] - P[other], axis=1))
    inside[np.searchsorted(cand, centre)] = True
    of = dict(zip(cand[inside].tolist(), dist[inside].tolist()))
    indptr, indices = _adjacency(mesh)
    seen, queue = {centre}, [centre]
    for v in queue:
        for w in indices[indptr[v]:indptr[v + 1]]:
            if w in of and w not in seen:
                seen.add(w)
                queue.append(w)
    rest = sorted((i for i in seen if i != centre), key=lambda i: (of[i], i))
    return [centre] + rest


def _nodes_by_x(mesh) -> tuple[np.ndarray, np.ndarray]:
    """``(order, x)``: the nodes sorted by their rest ``x`` and those ``x``, cached on the mesh (not pickled:
    a ``*_cache`` key)."""
    out = mesh.__dict__.get("_nodes_by_x_cache")
    if out is None:
        order = np.argsort(mesh.points[:, 0], kind="stable")
        out = mesh.__dict__["_nodes_by_x_cache"] = (order, mesh.points[order, 0])
    return out


def _adjacency(mesh) -> tuple[list, list]:
    """``(indptr, indices)`` as lists: the neighbours of node ``v`` along mesh edges are
    ``indices[indptr[v]:indptr[v + 1]]``; cached on the mesh."""
    adj = mesh.__dict__.get("_adjacency_lists_cache")
    if adj is None:
        E, n = mesh.edges, mesh.n_nodes
        rows, cols = np.concatenate([E[:, 0], E[:, 1]]), np.concatenate([E[:, 1], E[:, 0]])
        order = np.argsort(rows, kind="stable")
        indptr = np.searchsorted(rows[order], np.arange(n + 1))
        adj = mesh.__dict__["_adjacency_lists_cache"] = (indptr.tolist(), cols[order].tolist())
    return adj


def anchor_patches(mesh, muscles, radius: float | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per muscle the node sets of its two end anchors, ``(start_patch, end_patch)``.

    Parameters
    ----------
    mesh : Mesh
    muscles : sequence of Muscle or node lists
    radius : float, optional
        Anchor radius in length units (default :func:`default_anchor_radius`); 0 anchors each end on its node.

    Returns
    -------
    list of (ndarray, ndarray)
        Each patch lists the end node first, then the body nodes within ``radius`` of it at rest, connected
        to it through such nodes and strictly nearer to it than to the muscle's other end (so a muscle's two
        patches never overlap), by increasing distance.
    """
    mus = valid_muscles(mesh, muscles)
    r = anchor_radius_or_default(mesh, radius)
    out = []
    for m in mus:
        s, e = m.nodes[0], m.nodes[-1]
        out.append((_patch(mesh, s, e, r), _patch(mesh, e, s, r)))
    return out


#: the most patches :func:`_patch` keeps per mesh (the oldest dropped first)
PATCHES_KEPT = 1024


def _patch(mesh, centre: int, other: int, radius: float) -> np.ndarray:
    """:func:`_ball` as a new int array, its nodes kept on the mesh per ``(centre, other, radius)`` (a ``*_cache``
    key, not pickled): the routing's fixture fit asks for the same ropes' patches after each rope it drops
    and at each fixture radius it tries (674 patches, 146 different, routing the starfish's pinwheel at 2.4k
    nodes)."""
    kept = mesh.__dict__.setdefault("_patches_cache", {})
    key = (int(centre), int(other), float(radius))
    nodes = kept.get(key)
    if nodes is None:
        nodes = np.array(_ball(mesh, centre, other, radius), dtype=np.int64)
        nodes.flags.writeable = False
        if len(kept) >= PATCHES_KEPT:
            kept.pop(next(iter(kept)))
        kept[key] = nodes
    return nodes.copy()


def rigid_groups(mesh, muscles, radius: float | None = None) -> list[np.ndarray]:
    """Anchor patches merged where patches of different muscles share a node: each group moves rigidly.

    Groups of one node are dropped (they constrain nothing). Raises ``ValueError`` when merging would join
    the two ends of one muscle (it could then not contract); a smaller ``radius`` avoids that. The groups
    (read-only arrays) are cached on the mesh per node chains and radius.
    """
    mus = valid_muscles(mesh, muscles)
    key = (tuple(m.nodes for m in mus), anchor_radius_or_default(mesh, radius))
    cache = mesh.__dict__.setdefault("_rigid_group_cache", {})
    if key not in cache:
        if len(cache) >= 32:
            cache.pop(next(iter(cache)))
        groups = _rigid_groups(mesh, mus, key[1])
        for g in groups:
            g.flags.writeable = False
        cache[key] = groups
    return list(cache[key])


def _rigid_groups(mesh, mus, radius: float) -> list[np.ndarray]:
    groups, joined = patch_groups(mesh, mus, radius)
    if joined:
        c = joined[0]
        raise LayoutError(f"the anchor patches of muscle {label_of(mus, c)} are joined through other muscles' "
                          "anchors, so it could not contract; give a smaller anchor_radius")
    return groups


def patch_groups(mesh, muscles, radius: float | None = None) -> tuple[list[np.ndarray], list[int]]:
    """The anchor patches merged where patches of different muscles share a node, and the muscles whose two
    ends fall into one merged group (which could then not contract); raises nothing.

    Returns
    -------
    groups : list of ndarray
        The merged groups of two nodes or more (each moves rigidly), in the order of their first patch.
    joined : list of int
        Indices of the muscles whose two end patches are in one group, in order.
    """
    mus = valid_muscles(mesh, muscles)
    patches = anchor_patches(mesh, mus, anchor_radius_or_default(mesh, radius))
    flat = [p for pair in patches for p in pair]
    parent = list(range(len(flat)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    owner: dict[int, int] = {}
    for k, p in enumerate(flat):
        for v in p.tolist():
            if v in owner:
                a, b = find(owner[v]), find(k)
                if a != b:
                    parent[max(a, b)] = min(a, b)
            else:
                owner[v] = k
    joined = [c for c in range(len(mus)) if find(2 * c) == find(2 * c + 1)]
    groups: dict[int, list[int]] = {}
    for k, p in enumerate(flat):
        g = groups.setdefault(find(k), [])
        g.extend(v for v in p.tolist() if v not in g)
    return [np.array(g, dtype=np.int64) for _, g in sorted(groups.items()) if len(g) >= 2], joined


def check_anchor_radius(mesh, radius) -> float:
    """The one check of an anchor radius: ``radius`` as a float in length units (None gives
    :func:`default_anchor_radius`); clear errors for a value that is no real number, negative, not finite,
    or :data:`MAX_ANCHOR_FRACTION` of :func:`body_size` or more.

    Called at the doors only (:func:`~mdsr_opt.solve_internal`, :func:`~mdsr_opt.design_contractions`,
    :func:`~mdsr_opt.verify_design`, :func:`~mdsr_opt.check_minimum`, :class:`~mdsr_opt.Scene`); the
    functions behind them (the design problem, the muscle constraints, :func:`anchor_patches`) take the
    radius as given.
    """
    if radius is None:
        return default_anchor_radius(mesh)
    radius = positive_float(radius, "anchor_radius", allow_zero=True)
    if radius >= MAX_ANCHOR_FRACTION * body_size(mesh):
        raise ValueError(f"anchor_radius {radius:g} is at least half the body's size ({body_size(mesh):.3g}): "
                         "a muscle's end patch would hold most of the body")
    return radius

