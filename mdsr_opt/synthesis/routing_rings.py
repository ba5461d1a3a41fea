"""Ring muscles round a squeezed hole (an eye drawn shut, lips pursed), for the muscle routing.

A hole whose surroundings contract in hoop all the way round is closed by a ring of rope (orbicularis oculi,
oris), not by the arcs growth lays: growth extends a unit one edge at a time within the tortuosity limit, so
at the sharp ends of an elongated hole it stops where the mesh's node chain turns more than the limit at one
node, and the ring falls apart into arcs whose ropes, anchored at their ends, straighten instead of closing
the hole. Which arcs meet depends on where the mesh's nodes happen to lie, so the result changes with the
resolution.

:func:`hole_rings` searches the whole ring at once: the cheapest closed chain of routable edges (contracted and,
with fabrication, deep enough inside the body) that winds once round the hole with every turn, at every node
including the closing one, within the limit. The search runs over directed edges (a state is the edge just
taken, so the turn to the next edge is known) by Dijkstra from every edge crossing a ray from the hole's
centre back to that edge, the other crossing edges barred (the chain then winds exactly once). An edge costs
its rest length over its contraction, ``l0 / w``: the ring that is short and strongly contracted, i.e. the one
nearest the hole that the rope may take (a ring within twice the rim's size of the hole's
centre: round the hole, not round the body or another hole). :func:`open_ring` opens it at its least
contracted edge, where the rope's two ends sit with their fixtures.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

__all__ = ["hole_rings", "open_ring"]


def _turn_cost(d, e) -> float:
    c = (d[0] * e[0] + d[1] * e[1]) / math.sqrt((d[0] ** 2 + d[1] ** 2) * (e[0] ** 2 + e[1] ** 2))
    return 1.0 - max(-1.0, min(1.0, c))


def hole_rings(mesh, feasible: np.ndarray, wq: np.ndarray, turn_limit: float, floor_q: int = 0) -> list[list[int]]:
    """Per hole of ``mesh`` that the target squeezes (every edge of its rim contracts, ``wq > floor_q``) and round
    which a ring of ``feasible`` edges exists within the tortuosity limit: the
    ring's nodes in order, closing back to the first (see the module docstring; :func:`open_ring` makes it a
    rope), holes in the order of ``mesh.boundary_loops``.

    Parameters
    ----------
    mesh : Mesh
    feasible : (n_edges,) bool
        The edges a muscle may use (contracted; with fabrication, deep enough inside).
    wq : (n_edges,) int
        Quantised contractions (positive on feasible edges).
    turn_limit : float
        The largest allowed ``1 - cos(turn)`` at a node.
    floor_q : int
        The quantised contraction a rim edge must exceed (a hole whose rim stretches anywhere, e.g. lips
        pursed at the corners but opened in height, is shaped by other muscles than a ring).
    """
    loops = mesh.boundary_loops[1:]
    if not loops or not feasible.any():
        return []
    X = mesh.points
    E = mesh.edges
    l0 = mesh.edge_lengths
    idx = np.flatnonzero(feasible)
    out = []
    for loop in loops:
        loop = np.asarray(loop)
        rim = mesh.edge_rows(loop, np.roll(loop, -1))
        if (rim < 0).any() or (wq[rim] <= floor_q).any():
            continue
        ring = _ring_round(X, E, l0, wq, idx, np.asarray(loop), turn_limit)
        if ring is not None:
            out.append(ring)
    return out


def _ring_round(X, E, l0, wq, idx, loop, turn_limit):
    P = X[loop]
    # the hole's centroid (shoelace), the centre of the winding
    x, y = P[:, 0], P[:, 1]
    xs, ys = np.roll(x, -1), np.roll(y, -1)
    cr = x * ys - xs * y
    A = cr.sum() / 2.0
    if abs(A) < 1e-300:
        return None
    c = np.array([((x + xs) * cr).sum(), ((y + ys) * cr).sum()]) / (6.0 * A)
    ang = np.arctan2(X[:, 1] - c[1], X[:, 0] - c[0])
    # a ring round this hole, not round the body: nodes within twice the rim's largest distance from its centre
    near = np.linalg.norm(X - c, axis=1) <= 2.0 * float(np.linalg.norm(P - c, axis=1).max())
    idx = idx[near[E[idx, 0]] & near[E[idx, 1]]]
    # directed edges: (tail, head, edge id); winding counter-clockwise is positive
    tails = np.concatenate([E[idx, 0], E[idx, 1]])
    heads = np.concatenate([E[idx, 1], E[idx, 0]])
    ks = np.concatenate([idx, idx])
    d_ang = (ang[heads] - ang[tails] + np.pi) % (2.0 * np.pi) - np.pi
    # an edge crossing the ray at angle pi (the branch cut of arctan2) counter-clockwise: from above to below
    crossing = (ang[tails] > np.pi / 2) & (ang[heads] < -np.pi / 2) & (d_ang > 0)
    # an edge must not straddle the hole (its segment would pass over it): |d_ang| < pi / 2 keeps to the band
    ok = np.abs(d_ang) < np.pi / 2
    out_of: dict[int, list[int]] = {}
    for s in np.flatnonzero(ok).tolist():
        out_of.setdefault(int(tails[s]), []).append(s)
    cost = l0[ks] / np.maximum(wq[ks], 1).astype(float)
    XL = X.tolist()

    def direction(s):
        a, b = XL[tails[s]], XL[heads[s]]
        return (b[0] - a[0], b[1] - a[1])

    best = None
    for s0 in np.flatnonzero(crossing & ok).tolist():
        # Dijkstra over directed edges from s0 back to a state entering tail(s0) that turns onto s0 within limit
        start, goal = int(tails[s0]), int(heads[s0])
        dist = {s0: cost[s0]}
        prev = {s0: -1}
        heap = [(cost[s0], s0)]
        found = None
        while heap:
            d, s = heapq.heappop(heap)
            if d > dist.get(s, math.inf) or (best is not None and d >= best[0]):
                continue
            h = int(heads[s])
            if h == start and s != s0:
                if _turn_cost(direction(s), direction(s0)) <= turn_limit:
                    found = (d, s)
                    break
                continue
            ds = direction(s)
            for t in out_of.get(h, ()):
                if crossing[t] or int(heads[t]) == int(tails[s]):
                    continue
                if _turn_cost(ds, direction(t)) > turn_limit:
                    continue
                nd = d + cost[t]
                if nd < dist.get(t, math.inf):
                    dist[t], prev[t] = nd, s
                    heapq.heappush(heap, (nd, t))
        if found is None:
            continue
        chain, s = [], found[1]
        while s != -1:
            chain.append(s)
            s = prev[s]
        chain.reverse()
        nodes = [int(tails[t]) for t in chain]
        wind = float(d_ang[chain].sum())
        if len(set(nodes)) != len(nodes) or abs(wind - 2.0 * np.pi) > 1e-6 or goal != nodes[1 % len(nodes)]:
            continue  # not a simple ring round this hole once
        if best is None or found[0] < best[0]:
            best = (found[0], nodes, [int(ks[t]) for t in chain])
    if best is None:
        return None
    return best[1]


def open_ring(cycle: list[int], wq: np.ndarray, edge_id, X: np.ndarray, mirror=None) -> list[int] | None:
    """The rope of a closed ring ``cycle`` (its nodes in order, closing back to the first): opened at its least
    contracted edge (ties by the edge midpoint's rest position), the two ends of the rope then lie there with
    their fixtures. With ``mirror`` (a node map of the body's reflection) a ring that is its own mirror image is
    opened where it crosses the axis (at an edge joining mirror images, or by leaving out a node on the axis),
    so the rope is its own mirror image too; None when it does not cross the axis that way."""
    n = len(cycle)
    edges = [edge_id(cycle[i], cycle[(i + 1) % n]) for i in range(n)]

    def key(i):
        k = edges[i]
        a, b = X[cycle[i]], X[cycle[(i + 1) % n]]
        return (int(wq[k]), 0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]))

    if mirror is not None and {mirror[v] for v in cycle} == set(cycle):
        cut = [i for i in range(n) if mirror[cycle[i]] == cycle[(i + 1) % n]]
        if cut:
            j = min(cut, key=key)
            return [cycle[(j + 1 + i) % n] for i in range(n)]
        axis = [i for i in range(n) if mirror[cycle[i]] == cycle[i]]
        if not axis:
            return None
        j = min(axis, key=lambda i: (min(int(wq[edges[i - 1]]), int(wq[edges[i]])), X[cycle[i]][0], X[cycle[i]][1]))
        return [cycle[(j + 1 + i) % n] for i in range(n - 1)]
    j = min(range(n), key=key)
    # edge j joins cycle[j] and cycle[j + 1]: the rope runs from cycle[j + 1] round to cycle[j]
    return [cycle[(j + 1 + i) % n] for i in range(n)]
