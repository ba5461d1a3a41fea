"""End fixtures of physical size as reduced coordinates: the nodes of a fixture move rigidly with its end node.

A rope ends on a bead, knot or plate of radius ``r_f`` cast into the body; the body nodes within ``r_f`` of the
end node (the anchor patches of :func:`~mdsr_opt.mechanics.anchors.rigid_groups`, merged where two fixtures
overlap) move with it as one rigid body. A mesh too coarse for the fixtures is refined round the rope ends (:func:`fixture_mesh`), so
a fixture keeps its physical size, and :func:`free_lengths` gives each rope's length between its fixtures. Instead of constraints with multipliers, each group is given three
coordinates -- its first node's position and an angle -- and every other member follows:
``x_k = x_r + R(phi) (X_k - X_r)``. Nodes outside every group keep their own two coordinates.

:class:`RigidReduction` maps the reduced coordinates ``q`` to the node positions ``x``, and carries a gradient
and a Hessian from ``x`` to ``q`` (``P^T g`` and ``P^T H P`` plus the curvature of the rotation, ``-g_k .
(x_k - x_r)`` on each angle).

Example
-------
>>> import numpy as np
>>> red = RigidReduction(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]), [np.array([1, 2])])
>>> red.n_q  # nodes 0 and 1 free, node 2 follows node 1: 2 + 2 + 1 angle
5
>>> q = red.rest_q(); q[-1] = np.pi / 2
>>> red.x_of(q).round(12).tolist()
[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

__all__ = ["RigidReduction", "fixture_groups", "fixture_mesh", "free_lengths", "rings_held"]


def fixture_groups(mesh, muscles, radius: float, midnodes: np.ndarray | None = None) -> list[np.ndarray]:
    """The rigid fixture groups of ``muscles`` on ``mesh`` at fixture radius ``radius`` (length units):
    :func:`~mdsr_opt.mechanics.anchors.rigid_groups` (each group lists an end node first), each extended, when ``midnodes`` gives the midpoint node of every row of ``mesh.edges``, by the midpoints of the
    edges whose two ends are in the group."""
    from .anchors import rigid_groups

    groups = rigid_groups(mesh, muscles, radius)
    if midnodes is None:
        return [np.array(g, dtype=np.int64) for g in groups]
    E = mesh.edges
    out = []
    for g in groups:
        inside = np.zeros(mesh.n_nodes, dtype=bool)
        inside[g] = True
        rows = np.flatnonzero(inside[E[:, 0]] & inside[E[:, 1]])
        out.append(np.concatenate([np.asarray(g, dtype=np.int64), np.asarray(midnodes)[rows]]))
    return out


def free_lengths(points, chains, groups) -> np.ndarray:
    """Per rope (a node chain of ``points``) the rest length of its segments that do not lie within one rigid
    group of ``groups``: the rope between its fixtures, which its stroke shortens. A stroke as long as that
    would bring the fixtures together (the silicone between them folds before)."""
    X = np.asarray(points, dtype=float).reshape(-1, 2)
    gid = np.full(len(X), -1, dtype=np.int64)
    for k, g in enumerate(groups):
        gid[np.asarray(g, dtype=np.int64)] = k
    out = []
    for c in chains:
        c = np.asarray(c, dtype=np.int64)
        seg = np.linalg.norm(np.diff(X[c], axis=0), axis=1)
        a, b = gid[c[:-1]], gid[c[1:]]
        out.append(float(seg[(a < 0) | (a != b)].sum()))
    return np.asarray(out)


def rings_held(mesh, muscles, radius: float) -> np.ndarray:
    """Per muscle end (first and last node of each, in order): whether a fixture of ``radius`` about it holds
    its whole ring of elements, every mesh edge at the end node shorter than ``radius``."""
    E, L = mesh.edges, mesh.edge_lengths
    longest = np.zeros(mesh.n_nodes)
    np.maximum.at(longest, E[:, 0], L)
    np.maximum.at(longest, E[:, 1], L)
    ends = np.array([n for m in muscles for n in (m.nodes[0], m.nodes[-1])], dtype=np.int64)
    return longest[ends] < radius


#: element size at a rope end over the fixture's radius, and its growth per unit of distance from the end,
#: of :func:`fixture_mesh` (a graded mesh: a few rings of elements round each fixture, the rest unchanged)
FIXTURE_ELEMENT, FIXTURE_GRADING = 0.5, 0.3


def fixture_mesh(mesh, muscles, radius: float, rounds: int = 6):
    """The mesh on which fixtures of ``radius`` have their physical size, and the muscles laid on it.

    A fixture that holds no node besides its rope's end is a point force, under which a planar body has no
    finite displacement (quadratic elements fold at that vertex); enlarging it to the end's ring of elements
    instead changes the body: two fixtures a rope's length apart, or of two ropes ending close together, then
    meet across one element, which takes the whole stroke and folds. So the mesh is refined round the rope
    ends instead (Triangle's conforming refinement, every node kept with its index) until every fixture holds
    its end's whole ring of elements (:func:`rings_held`): elements of :data:`FIXTURE_ELEMENT` times ``radius``
    at the ends, growing by :data:`FIXTURE_GRADING` per unit of distance. A rope keeps its nodes: an edge the
    refinement split runs through the new nodes on it, one it flipped along the shortest way round.

    Returns
    -------
    (mesh, muscles)
        ``mesh`` itself and ``muscles`` unchanged when every fixture already holds its ring; otherwise the
        refined :class:`~mdsr_opt.body.mesh.Mesh` (the first ``mesh.n_nodes`` nodes are ``mesh``'s) and
        each muscle's chain on it.

    Raises
    ------
    ValueError
        ``radius`` not positive and finite, or a mesh that ``rounds`` refinements do not resolve.
    """
    import triangle as tr

    from ..body.mesh import Mesh
    from ..body.muscles import Muscle

    radius = float(radius)
    if not np.isfinite(radius) or radius <= 0.0:
        raise ValueError(f"the fixture radius must be positive and finite, got {radius}")
    muscles = list(muscles)
    if not muscles or rings_held(mesh, muscles, radius).all():
        return mesh, muscles
    P0 = np.asarray(mesh.points, dtype=float)
    ends = np.unique([n for m in muscles for n in (m.nodes[0], m.nodes[-1])])
    chains = [np.asarray(m.nodes, dtype=np.int64) for m in muscles]
    factor = np.full(len(ends), FIXTURE_ELEMENT)
    loops = [np.asarray(lp) for lp in mesh.boundary_loops]
    segs = np.vstack([np.column_stack([lp, np.roll(lp, -1)]) for lp in loops])
    cur, pieces = mesh, chains
    for _ in range(rounds):
        P, T = np.asarray(cur.points, dtype=float), np.asarray(cur.triangles)
        c = P[T].mean(axis=1)
        d = np.linalg.norm(c[:, None, :] - P0[ends][None, :, :], axis=2)
        h = (factor[None, :] * radius + FIXTURE_GRADING * d).min(axis=1)
        out = tr.triangulate({"vertices": P.copy(), "triangles": T.astype(np.int32),
                              "segments": segs.astype(np.int32),
                              "triangle_max_area": np.sqrt(3.0) / 4.0 * h ** 2}, "rpaq30Q")
        V = out["vertices"]
        if len(V) < len(P0) or not np.allclose(V[:len(P0)], P0, rtol=0.0, atol=1e-12 * (1.0 + np.abs(P0).max())):
            raise ValueError("refining the mesh round the fixtures moved its nodes")  # pragma: no cover
        V[:len(P0)] = P0
        cur = Mesh(V, out["triangles"])
        pieces = [_relay(cur, c) for c in chains]
        segs = out["segments"]
        held = rings_held(cur, [Muscle(c) for c in pieces], radius)
        ok = np.ones(len(ends), dtype=bool)
        for c, pair in zip(pieces, held.reshape(-1, 2)):
            ok[np.searchsorted(ends, [c[0], c[-1]])] &= pair
        if ok.all():
            return cur, [Muscle(c, name=m.name) for c, m in zip(pieces, muscles)]
        factor[~ok] *= 0.6
    raise ValueError(f"the mesh could not be refined so that fixtures of radius {radius:.4g} hold their rope ends' "
                     f"rings of elements in {rounds} rounds; give a larger fixture radius")


def _relay(mesh, chain: np.ndarray) -> np.ndarray:
    """``chain`` (nodes of a coarser mesh whose nodes ``mesh`` kept) on ``mesh``: each of its edges through the
    nodes that now lie on it, in order; a simple path (a way round a flipped edge that returns to a node of the
    rope is cut at that node)."""
    P = mesh.points
    out = [int(chain[0])]
    for a, b in zip(chain[:-1].tolist(), chain[1:].tolist()):
        if mesh.edge_rows([a], [b])[0] < 0:
            d = P[b] - P[a]
            L2 = float(d @ d)
            t = (P - P[a]) @ d / L2
            off = np.abs((P[:, 0] - P[a, 0]) * d[1] - (P[:, 1] - P[a, 1]) * d[0]) / np.sqrt(L2)
            on = np.flatnonzero((t > 1e-9) & (t < 1 - 1e-9) & (off < 1e-9 * np.sqrt(L2)))
            way = [a] + on[np.argsort(t[on])].tolist() + [b]
            if (mesh.edge_rows(way[:-1], way[1:]) < 0).any():  # the edge was flipped: the shortest way round
                way = _shortest(mesh, a, b)
            out += way[1:-1]
        out.append(b)
    seen: dict[int, int] = {}
    simple: list[int] = []
    for v in out:  # a way round a flipped edge that passes a node the rope already holds: cut that loop out
        if v in seen:
            for w in simple[seen[v] + 1:]:
                del seen[w]
            del simple[seen[v] + 1:]
        else:
            seen[v] = len(simple)
            simple.append(v)
    c = np.asarray(simple, dtype=np.int64)
    if (mesh.edge_rows(c[:-1], c[1:]) < 0).any():
        raise ValueError("a rope's edge was not kept when the mesh was refined round the fixtures")  # pragma: no cover
    return c


def _shortest(mesh, a: int, b: int) -> list[int]:
    """The shortest path from node ``a`` to node ``b`` along the edges of ``mesh`` (rest lengths)."""
    from scipy.sparse.csgraph import dijkstra

    E, L, n = mesh.edges, mesh.edge_lengths, mesh.n_nodes
    rows, cols = np.concatenate([E[:, 0], E[:, 1]]), np.concatenate([E[:, 1], E[:, 0]])
    G = sp.csr_matrix((np.concatenate([L, L]), (rows, cols)), shape=(n, n))
    _, pred = dijkstra(G, indices=a, return_predecessors=True)
    way = [b]
    while way[-1] != a:
        way.append(int(pred[way[-1]]))
    return way[::-1]


class RigidReduction:
    """Reduced coordinates of a body whose node ``groups`` move rigidly (see the module docstring).

    Parameters
    ----------
    points : (n, 2) rest positions.
    groups : sequence of int arrays, disjoint; the first node of each is its reference node.
    """

    def __init__(self, points, groups: Sequence[np.ndarray] = ()):
        X = np.asarray(points, dtype=float).reshape(-1, 2)
        n = len(X)
        member = np.full(n, -1, dtype=np.int64)  # group of a node that follows a reference node
        refs = []
        for k, g in enumerate(groups):
            g = np.asarray(g, dtype=np.int64).ravel()
            if len(g) < 2:
                continue
            if len(np.unique(g)) != len(g) or (member[g] >= 0).any() or np.isin(g, refs).any():
                raise ValueError(f"fixture group {k} overlaps another group or repeats a node")
            member[g[1:]] = len(refs)
            refs.append(int(g[0]))
        self.X = X
        self.n = n
        self.refs = np.array(refs, dtype=np.int64)
        self.member = member
        own = np.flatnonzero(member < 0)
        self.own = own
        self.q_index = np.full(n, -1, dtype=np.int64)  # x-coordinate of an own node in q (y follows)
        self.q_index[own] = 2 * np.arange(len(own))
        self.n_angles = len(refs)
        self.n_q = 2 * len(own) + self.n_angles
        self.followers = np.flatnonzero(member >= 0)
        self._fref = self.refs[member[self.followers]]
        self._arm0 = X[self.followers] - X[self._fref]

    def rest_q(self) -> np.ndarray:
        """The reduced coordinates of the rest shape."""
        q = np.zeros(self.n_q)
        q[:2 * len(self.own)] = self.X[self.own].ravel()
        return q

    def q_of(self, x) -> np.ndarray:
        """Reduced coordinates of a state ``x`` whose groups are rigid (each angle from the group's best-fit
        rotation)."""
        x = np.asarray(x, dtype=float).reshape(-1, 2)
        q = np.zeros(self.n_q)
        q[:2 * len(self.own)] = x[self.own].ravel()
        arm = x[self.followers] - x[self._fref]
        cross = self._arm0[:, 0] * arm[:, 1] - self._arm0[:, 1] * arm[:, 0]
        dot = (self._arm0 * arm).sum(1)
        g = self.member[self.followers]
        s, c = np.bincount(g, cross, self.n_angles), np.bincount(g, dot, self.n_angles)
        q[2 * len(self.own):] = np.arctan2(s, c)
        return q

    def _angles(self, q):
        phi = q[2 * len(self.own):][self.member[self.followers]]
        return np.cos(phi), np.sin(phi)

    def x_of(self, q) -> np.ndarray:
        """Node positions (n, 2) of the reduced coordinates ``q``."""
        q = np.asarray(q, dtype=float)
        x = np.empty((self.n, 2))
        x[self.own] = q[:2 * len(self.own)].reshape(-1, 2)
        c, s = self._angles(q)
        a = self._arm0
        x[self.followers] = x[self._fref] + np.column_stack([c * a[:, 0] - s * a[:, 1], s * a[:, 0] + c * a[:, 1]])
        return x

    def jacobian(self, q) -> sp.csr_matrix:
        """``P = dx/dq`` (2n, n_q), sparse."""
        x = self.x_of(q)
        rows, cols, vals = [], [], []
        own = self.own
        rows += [2 * own, 2 * own + 1]
        cols += [self.q_index[own], self.q_index[own] + 1]
        vals += [np.ones(len(own)), np.ones(len(own))]
        f, r = self.followers, self._fref
        rows += [2 * f, 2 * f + 1]
        cols += [self.q_index[r], self.q_index[r] + 1]
        vals += [np.ones(len(f)), np.ones(len(f))]
        arm = x[f] - x[r]
        ang = 2 * len(own) + self.member[f]
        rows += [2 * f, 2 * f + 1]
        cols += [ang, ang]
        vals += [-arm[:, 1], arm[:, 0]]
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(2 * self.n, self.n_q))

    def curvature(self, q, gx) -> sp.csr_matrix:
        """The second-derivative term of ``d^2 E / dq^2`` for a gradient ``gx`` (2n,) in ``x``: on each angle,
        ``sum_k gx_k . d^2 x_k / d phi^2 = -sum_k gx_k . (x_k - x_r)``, with the mixed angle-reference terms
        zero (the arm does not depend on ``x_r``)."""
        x = self.x_of(q)
        f, r = self.followers, self._fref
        arm = x[f] - x[r]
        g = np.asarray(gx, dtype=float).reshape(-1, 2)[f]
        d = np.bincount(self.member[f], -(g * arm).sum(1), self.n_angles)
        idx = 2 * len(self.own) + np.arange(self.n_angles)
        return sp.csr_matrix((d, (idx, idx)), shape=(self.n_q, self.n_q))
