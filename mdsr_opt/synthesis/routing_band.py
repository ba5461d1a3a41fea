"""Ropes routed in the continuous band and snapped to mesh edges inside it (:func:`snap_into_band`).

A rope runs in a channel with a wall, so every rope node must lie ``clearance`` inside the outline and the
holes (:meth:`~mdsr_opt.synthesis.fabrication.Fabrication.clearance`). Searching only on the mesh edges that
far inside (:func:`~mdsr_opt.synthesis.fabrication.admissible_edges`, ``band="edges"`` in
:func:`~mdsr_opt.synthesis.routing.route_muscles`) fails where the body's contraction is strongest next to the
outline -- a bent limb's concave side, a tentacle curled towards one face: the most contracted edges inside
the band then lie along the band's own edge, and on an unstructured mesh that edge is jagged. A rope grown
along it reaches a "tooth" (a band node whose every forward neighbour lies outside the band) after a few
edges, and the search stops with fragments of 4 to 6 edges that are too short for two end fixtures. Beside a
hole the band narrows to necks thinner than the mesh spacing, which no chain of mesh edges crosses at all.

``band="offset"`` routes in the continuous band instead:

1. The search runs on every contracted edge (as without fabrication), so the ropes follow the contraction
   where it is, outline or not, and are as long and smooth as the search makes them (``band="offset+long"``:
   also the ropes of a search at ``K_a = 1``, fewer and longer, which the band's gaps cut anyway; the fixture
   fit keeps the strongest of the pooled ropes).
2. Each rope's rest polyline is moved into the band (the body's polygon shrunk by the clearance, with
   shapely): each node to its nearest point of the band. Where that point is farther than the clearance
   plus one mean edge length from the node, the rope crosses a gap of the band (a neck beside a hole too thin
   for a channel with its wall): the rope is cut there, and each part is routed on its own.
3. Each part is snapped to the mesh: the cheapest chain of admissible, contracted edges (both nodes at least
   the clearance inside; a cable cannot push) from the admissible node nearest its first point to the one
   nearest its last point, each edge costing its rest length times ``1 + (d / h)**2``, with ``d`` the
   distance of the edge's midpoint from the moved polyline and ``h`` the mean edge length: a corridor
   along the moved rope. Shortest paths go round the band's teeth rather than into them. The part is covered
   by such chains from its start onwards, each reaching as far along the moved rope as the corridor allows,
   the next starting past its end where the band's mesh has a break.

Why not refine the band (add nodes along it) or offset whole routes node by node: a refined band changes the
user's mesh, and with it the target, the anchors' and drags' nodes and every figure of the design; an
offset route's nodes are no mesh nodes. Snapping keeps every rope on mesh edges of the given mesh and every
node exactly as far inside as the admissible edges guarantee. Snapped ropes may come near each other (two
outline ropes moved onto one band edge); the fixture fit that follows
(:func:`~mdsr_opt.synthesis.routing_fixtures.fit_fixtures`) keeps a channel and a wall between them, as for
any routing. A snapped chain turns by at most :data:`SNAP_TURN` at a node (or ``max_turn`` when that is
larger): it zigzags about the moved rope along the band's jagged edge.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

__all__ = ["band_polygon", "snap_into_band", "STRETCHED_COST"]

#: A snapped rope may cross an edge the target does not contract (round a tooth of the band's jagged edge) at
#: this many times the cost of a contracted one.
STRETCHED_COST = 4.0
#: The largest turn (degrees) of a snapped rope at a node when ``max_turn`` is smaller: the band's edge is
#: jagged on an unstructured mesh, and a chain along it zigzags about its smooth centre line (the moved rope,
#: which keeps ``max_turn``) by up to half an edge.
SNAP_TURN = 70.0
#: A snapped rope keeps its edges' midpoints within this many mean edge lengths of the moved rope.
CORRIDOR = 1.5


def band_polygon(mesh, clearance: float):
    """The body at rest (outline minus holes, from ``mesh.boundary_loops``) shrunk by ``clearance``: where a
    channel's centre line may run (shapely geometry, possibly empty or of several parts)."""
    from shapely.geometry import Polygon

    P = mesh.points
    loops = mesh.boundary_loops
    poly = Polygon(P[loops[0]], [P[lp] for lp in loops[1:]])
    if not poly.is_valid:
        poly = poly.buffer(0)
    return poly.buffer(-clearance, 16)


def _moved(P, path, band, jump: float) -> list[np.ndarray]:
    """The rest polyline of ``path`` moved into ``band``, as pieces split where a node is farther than ``jump``
    from the band (a gap of the band)."""
    import shapely
    from shapely.ops import nearest_points

    Q = P[list(path)]
    pts = shapely.points(Q)
    inside = shapely.contains_xy(band, Q[:, 0], Q[:, 1])
    d = shapely.distance(pts, band)
    pieces, cur = [], []
    for i, q in enumerate(Q):
        if inside[i]:
            cur.append(q)
            continue
        if d[i] > jump:
            if len(cur) >= 2:
                pieces.append(np.asarray(cur))
            cur = []
            continue
        near = nearest_points(band, pts[i])[0]
        cur.append(np.array([near.x, near.y]))
    if len(cur) >= 2:
        pieces.append(np.asarray(cur))
    return pieces


def _turn_moves(P, E, ks, turn_limit: float, used=None):
    """The line graph of the edges ``ks`` for shortest paths that never turn by more than ``turn_limit`` (as
    ``1 - cos``): one state per directed edge (``j < m``: row ``ks[j]`` forward, ``j >= m``: backward), and a
    move from ``u -> v`` to ``v -> w`` (``w != u``) where the turn at ``v`` is within the limit. Returns the
    directed edges' start and end nodes and the moves as two index arrays. ``used`` (a mask over ``ks``): only
    the moves between those edges, in the same order as among all moves (the rest would be barred anyway)."""
    m = len(ks)
    s = np.concatenate([E[ks, 0], E[ks, 1]])
    t = np.concatenate([E[ks, 1], E[ks, 0]])
    on = np.ones(2 * m, dtype=bool) if used is None else np.concatenate([used, used])
    order = np.argsort(s, kind="stable")
    order = order[on[order]]  # the directed edges used, by start node (stable: by state within a node)
    ptr = np.searchsorted(s[order], np.arange(len(P) + 1))
    src = np.flatnonzero(on)
    deg = ptr[t[src] + 1] - ptr[t[src]]              # moves out of each used directed edge's end node
    j1 = np.repeat(src, deg)
    j2 = order[np.repeat(ptr[t[src]], deg) + (np.arange(len(j1)) - np.repeat(np.cumsum(deg) - deg, deg))]
    vec = P[t] - P[s]  # each directed edge's vector and length, gathered per move below
    norm = np.linalg.norm(vec, axis=1)
    cos = (vec[j1] * vec[j2]).sum(axis=1) / (norm[j1] * norm[j2])
    ok = (t[j2] != s[j1]) & (1.0 - cos <= turn_limit)
    return s, t, j1[ok], j2[ok]


def _cheapest_from(s, t, j1, j2, cost, source: int):
    """Shortest paths over the moves from node ``source`` (each directed edge costs ``cost`` of its row;
    an infinite cost bars it): distances and predecessors per directed edge; the source is state ``len(s)``."""
    M = len(s)
    c = np.concatenate([cost, cost])
    keep = np.isfinite(c[j1]) & np.isfinite(c[j2])
    j1, j2 = j1[keep], j2[keep]
    src = np.flatnonzero((s == source) & np.isfinite(c))
    A = csr_matrix((np.concatenate([c[j2], c[src]]), (np.concatenate([j1, np.full(len(src), M)]),
                                                      np.concatenate([j2, src]))), shape=(M + 1, M + 1))
    dist, pred = dijkstra(A, directed=True, indices=M, return_predecessors=True)
    return dist[:M], pred


def snap_into_band(mesh, paths, usable: np.ndarray, contracted: np.ndarray, clearance: float,
                   turn_limit: float, band=None) -> list[tuple[int, list]]:
    """Ropes routed anywhere in the body, moved into the band and snapped to usable mesh edges (module doc).

    Parameters
    ----------
    mesh : Mesh
    paths : sequence of node sequences
        The ropes of the search on every contracted edge.
    usable : ndarray of bool, shape (n_edges,)
        The edges a rope may use: admissible (both nodes ``clearance`` inside).
    contracted : ndarray of bool, shape (n_edges,)
        The edges the target contracts; a snapped rope takes another edge only at :data:`STRETCHED_COST`
        times its cost (to get round a tooth of the band).
    clearance : float
        How far inside the outline and the holes a rope node lies.
    turn_limit : float
        The search's largest turn at a node, as ``1 - cos``; the snapped chain turns by at most the larger
        of it and :data:`SNAP_TURN` (the shortest path runs over directed edges, a move to the next edge
        allowed only within that limit).
    band : shapely geometry, optional
        :func:`band_polygon` of ``mesh`` and ``clearance`` (computed when not given).

    Returns
    -------
    list of (int, list of int)
        Per snapped part: the index of the rope it came from and its node path (two nodes or more), parts of
        one rope in order along it.
    """
    import shapely
    from shapely.geometry import LineString

    P = mesh.points
    E = mesh.edges
    h = float(mesh.edge_lengths.mean())
    if band is None:
        band = band_polygon(mesh, clearance)
    ks = np.flatnonzero(usable)
    if band.is_empty or len(ks) == 0:
        return []
    on = np.zeros(mesh.n_nodes, dtype=bool)
    on[E[ks].ravel()] = True
    nodes = np.flatnonzero(on)
    mid_xy = 0.5 * (P[E[ks, 0]] + P[E[ks, 1]])
    weight = mesh.edge_lengths[ks] * np.where(contracted[ks], 1.0, STRETCHED_COST)
    parts = [(r, Q) for r, path in enumerate(paths) for Q in _moved(P, path, band, clearance + h)]
    # the box about each moved rope its edges are measured in (a cost is finite only there): the moves
    # between edges in none of them would be barred, so they are not made
    boxes = [(Q.min(axis=0) - CORRIDOR * h, Q.max(axis=0) + CORRIDOR * h) for _, Q in parts]
    inbox = [np.flatnonzero(np.all((mid_xy >= lo) & (mid_xy <= hi), axis=1)) for lo, hi in boxes]
    used = np.zeros(len(ks), dtype=bool)
    for box in inbox:
        used[box] = True
    s, t, j1, j2 = _turn_moves(P, E, ks, max(turn_limit, 1.0 - math.cos(math.radians(SNAP_TURN))), used)
    M = len(s)
    out = []
    for (r, Q), (lo, hi), box in zip(parts, boxes, inbox):
        line = LineString(Q)
        off = np.full(len(ks), np.inf)
        off[box] = shapely.distance(shapely.points(mid_xy[box]), line) / h
        cost = np.where(off <= CORRIDOR, weight * (1.0 + off ** 2), np.inf)
        near = np.zeros(len(nodes), dtype=bool)  # nodes in the corridor along the moved rope
        along = np.full(len(nodes), -np.inf)
        nb = np.flatnonzero(np.all((P[nodes] >= lo) & (P[nodes] <= hi), axis=1))
        node_pts = shapely.points(P[nodes[nb]])
        near[nb] = shapely.distance(node_pts, line) <= h
        along[nb] = shapely.line_locate_point(line, node_pts)
        pos = -np.inf
        while True:  # cover the moved rope with the farthest-reaching chains, past each gap of the mesh
            cand = np.flatnonzero(near & (along > pos))
            if len(cand) == 0:
                break
            a = int(nodes[cand[np.argmin(along[cand])]])
            dist, pred = _cheapest_from(s, t, j1, j2, cost, a)
            reach = np.flatnonzero(np.isfinite(dist))
            ends = reach[np.isin(t[reach], nodes[near])]
            if len(ends) == 0:
                pos = along[nodes == a][0]
                continue
            far = along[np.searchsorted(nodes, t[ends])]
            best = ends[np.lexsort((dist[ends], -np.round(far / (1e-6 * h))))[0]]
            chain, j = [int(t[best])], int(best)
            while j != M:
                chain.append(int(s[j]))
                j = int(pred[j])
            chain.reverse()
            if len(set(chain)) == len(chain):
                out.append((r, chain))
            # past the chain's end, and never back to its start (which would give the same chain again)
            pos = max(float(along[np.searchsorted(nodes, chain[-1])]) + h, float(along[nodes == a][0]))
    return out
