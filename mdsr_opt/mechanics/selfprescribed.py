"""Door check of external driving with self-contact: prescribed nodes placed so that the prescribed part of
the body would overlap itself (:func:`check_prescribed_self`).

With ``contact=True`` the boundary may touch but never cross itself. Anchored and dragged nodes are not free
to give way, so when their prescribed positions already put two pieces of the boundary through each other,
closer than the contact gap, or a prescribed node inside a prescribed triangle, no solve can reach the
target: load stepping would only stall at the fraction where they meet. This module refuses such input
before any solve, as :func:`~mdsr_opt.mechanics.obstacles.check_prescribed` does for rigid obstacles.
"""

from __future__ import annotations

import numpy as np

__all__ = ["check_prescribed_self", "PATH_FRACTIONS"]

#: the load fractions (besides the target) at which the prescribed nodes' path is looked at
PATH_FRACTIONS = np.linspace(0.0, 1.0, 9)[1:-1]


def _groups(mesh, nodes: np.ndarray) -> np.ndarray:
    """The connected group (through mesh edges between prescribed nodes) of each of ``nodes``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    pos = np.full(mesh.n_nodes, -1)
    pos[nodes] = np.arange(len(nodes))
    e = pos[mesh.edges]
    e = e[(e >= 0).all(axis=1)]
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(nodes), len(nodes)))
    return connected_components(g, directed=False)[1]


class _Prescribed:
    """The prescribed part of the body: its boundary edges and triangles (in positions of ``nodes``) and
    which prescribed node is joined by a mesh edge to which."""

    def __init__(self, mesh, nodes: np.ndarray):
        at = np.full(mesh.n_nodes, -1)
        at[nodes] = np.arange(len(nodes))
        seg = at[mesh.boundary_edges]
        self.seg = seg[(seg >= 0).all(axis=1)]
        tri = at[mesh.triangles]
        self.tri = tri[(tri >= 0).all(axis=1)]
        self.bnd = np.unique(self.seg)
        e = at[mesh.edges]
        e = np.sort(e[(e >= 0).all(axis=1)], axis=1)
        self.k = len(nodes)
        self.keys = np.sort(e[:, 0] * self.k + e[:, 1])
        self.X0 = mesh.points[nodes]

    def joined(self, u, v) -> np.ndarray:
        """Whether the prescribed nodes ``u[i]`` and ``v[i]`` (positions) share a mesh edge."""
        q = np.minimum(u, v) * self.k + np.maximum(u, v)
        i = np.minimum(np.searchsorted(self.keys, q), max(len(self.keys) - 1, 0))
        return (self.keys[i] == q) if len(self.keys) else np.zeros(len(q), dtype=bool)


def _overlap(pr: _Prescribed, x: np.ndarray, gap: float):
    """The first overlap of the prescribed part ``pr`` at positions ``x`` (k, 2), or None: ``(kind, i, j)``
    with ``i``, ``j`` positions in the prescribed nodes."""
    import shapely

    from ..body.polygons import segment_contacts

    seg, tri, bnd = pr.seg, pr.tri, pr.bnd
    if len(seg) >= 2:
        bad = segment_contacts(x, seg)
        if len(bad):
            return "cross", int(seg[bad[0, 0], 0]), int(seg[bad[0, 1], 0])
    # a prescribed node strictly inside a prescribed triangle it is not a corner of
    moved = np.any(x != pr.X0, axis=1)  # nodes and triangles at rest cannot overlap one another
    tmoved = moved[tri].any(axis=1) if len(tri) else np.zeros(0, dtype=bool)
    if tmoved.any():
        ti = np.flatnonzero(tmoved)
        ip, it = shapely.STRtree(shapely.polygons(x[tri[ti]])).query(shapely.points(x), predicate="within")
        it = ti[it]
        if (~tmoved).any() and moved.any():  # the moved nodes against the triangles at rest
            tr = np.flatnonzero(~tmoved)
            pm = np.flatnonzero(moved)
            jp, jt = shapely.STRtree(shapely.polygons(x[tri[tr]])).query(shapely.points(x[pm]), predicate="within")
            ip, it = np.concatenate([ip, pm[jp]]), np.concatenate([it, tr[jt]])
        own = (tri[it] == ip[:, None]).any(axis=1)
        ip, it = ip[~own], it[~own]
        if len(ip):
            return "inside", int(ip[0]), int(tri[it[0], 0])
    # prescribed boundary nodes closer than the gap to a prescribed boundary edge they are not next to (and
    # closer than at rest: a fine mesh's nodes may lie that close already)
    if gap > 0 and len(bnd) and len(seg):
        lines = shapely.linestrings(np.stack([x[seg[:, 0]], x[seg[:, 1]]], axis=1))
        ip, js = shapely.STRtree(lines).query(shapely.points(x[bnd]), predicate="dwithin", distance=gap)
        p, a, b = bnd[ip], seg[js, 0], seg[js, 1]
        keep = (p != a) & (p != b)
        p, a, b, js = p[keep], a[keep], b[keep], js[keep]
        keep = ~pr.joined(p, a) & ~pr.joined(p, b)  # not a neighbour along the boundary
        p, a, b, js = p[keep], a[keep], b[keep], js[keep]
        if len(p):
            X0 = pr.X0
            d = shapely.distance(shapely.points(x[p]), lines[js])
            d0 = shapely.distance(shapely.points(X0[p]), shapely.linestrings(np.stack([X0[a], X0[b]], axis=1)))
            close = np.flatnonzero(d < np.minimum(gap, d0))
            if len(close):
                return "close", int(p[close[0]]), int(a[close[0]])
    return None


def check_prescribed_self(mesh, nodes, positions, gap: float, anchored: int = 0) -> None:
    """Refuse prescribed nodes that make the prescribed part of the body overlap itself under self-contact.

    Parameters
    ----------
    mesh : the body (:class:`~mdsr_opt.body.mesh.Mesh`).
    nodes : (k,) node numbers of the prescribed nodes: the ``anchored`` anchored ones first, then the
        dragged ones.
    positions : callable ``s -> (k, 2)``, their positions at load fraction ``s`` in [0, 1].
    gap : the contact gap (length units): prescribed boundary pieces may not come closer than it (unless
        they are that close at rest).
    anchored : how many of ``nodes`` (the first) are anchored.

    Raises
    ------
    ValueError
        Naming two of the nodes involved, how each is prescribed, their group of prescribed nodes (by its
        place at rest) and the load fraction at which they first overlap (the target first).
    """
    nodes = np.asarray(nodes, dtype=np.int64).reshape(-1)
    if len(nodes) < 2:
        return
    pr = _Prescribed(mesh, nodes)
    for s in (1.0, *PATH_FRACTIONS):
        x = np.asarray(positions(float(s)), dtype=float).reshape(-1, 2)
        found = _overlap(pr, x, float(gap))
        if found is None:
            continue
        kind, i, j = found
        groups = _groups(mesh, nodes)
        X0 = mesh.points[nodes]

        def name(k: int) -> str:
            c = X0[groups == groups[k]].mean(axis=0)
            how = "anchored" if k < anchored else f"dragged to ({x[k, 0]:.4g}, {x[k, 1]:.4g})"
            return f"node {int(nodes[k])} ({how}; of the prescribed nodes around ({c[0]:.4g}, {c[1]:.4g}) at rest)"

        what = {"cross": "the boundary edge at {a} crosses the one at {b}",
                "inside": "{a} lies inside a prescribed triangle at {b}",
                "close": f"{{a}} comes closer than the contact gap {gap:.3g} to the boundary edge at {{b}}"}[kind]
        where = "at their targets" if s == 1.0 else f"{s:.0%} of the way along the drags"
        raise ValueError(
            f"with contact, the prescribed nodes would overlap {where}: {what.format(a=name(i), b=name(j))}. "
            "The body cannot pass through itself, so no solve could reach this; move the drags' targets (or "
            "their paths) so that the prescribed parts stay apart")
