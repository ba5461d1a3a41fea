"""The best-first muscle search behind :func:`mdsr_opt.synthesis.routing.route_muscles` (see its module docstring).

:class:`Router` holds one routing run: the quantised contraction weights, the units (simple paths with exact
integer sums of their weights), the contracted regions and their seed units, the growth steps with their
cost ``g = K_a * g_a + K_b * (1 - cos theta)`` and heuristic, the mirror-image steps of symmetric routing,
and the fragment rule. Every ordering uses rest geometry, never node indices. The module is internal to
the routing; :func:`mdsr_opt.synthesis.routing.route_muscles` is the public entry.
"""

from __future__ import annotations

import math
from collections import deque

import networkx as nx
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from ..body.mesh import Mesh
from .routing_bounds import LowerBounds
from .routing_memo import FieldStore, memoised, node_adjacency, rest_graph, rest_lists
from .routing_spacing import apart_from_stronger

__all__ = ["Router", "mismatch", "turn_cost"]


# ---------------------------------------------------------------------------------------------- search
class _Unit:
    """A muscle unit during the search: a simple path and exact integer sums of its quantised weights."""

    __slots__ = ("uid", "path", "n", "s1", "alive")

    def __init__(self, uid: int, path: list[int], wq: list[int]):
        self.uid = uid
        self.path = deque(path)
        self.n = len(wq)
        self.s1 = sum(wq)
        self.alive = True


def turn_cost(d, e) -> float:
    """``1 - cos`` of the angle between direction vectors ``d`` and ``e``."""
    c = (d[0] * e[0] + d[1] * e[1]) / math.sqrt((d[0] * d[0] + d[1] * d[1]) * (e[0] * e[0] + e[1] * e[1]))
    return 1.0 - max(-1.0, min(1.0, c))


def mismatch(parts) -> float:
    """``g_a`` of joining ``parts`` ((edge count, sum of quantised weights) each) into one unit: the largest
    squared relative deviation of a part's mean contraction from the joined unit's mean."""
    N = sum(n for n, _ in parts)
    S = sum(s for _, s in parts)
    return max(((s * N - S * n) / (S * n)) ** 2 for n, s in parts)


class Router:
    """One routing run; all orderings use rest geometry, never node indices."""

    def __init__(self, mesh: Mesh, wq: np.ndarray, K_a: float, K_b: float, K_h: float, floor_q: int,
                 ell: float, turn_limit: float, mirror=None, admissible: np.ndarray | None = None):
        self.mesh = mesh
        self.X = mesh.points
        # rest positions and edge midpoints as lists (read in the search's Python loops), shared by the
        # routings of one body (routing_memo)
        self.XL, self.midl = rest_lists(mesh)
        self.K_a, self.K_b, self.K_h = K_a, K_b, K_h
        self.turn_limit = turn_limit  # largest allowed 1 - cos(turn) at any node (+ round-off slack)
        self.wq = wq
        self.wql = self.wq.tolist()
        self.floor_q = floor_q
        self.eligible = None  # the compression-dominated edges, set by regions()
        self.ring_uids: set[int] = set()  # the ring ropes round holes (seed_units)
        # a cable cannot push; ``admissible``: the edges far enough inside the body for a channel
        self.feasible = self.wq > floor_q if admissible is None else (self.wq > floor_q) & admissible
        self.l0 = mesh.edge_lengths
        self.ell = ell
        self.mp = None if mirror is None else mirror.node_map.tolist()
        self.me = None if mirror is None else mirror.edge_map.tolist()
        # adjacency over feasible (contracted) edges only: a cable cannot push; each node's (neighbour, edge)
        # pairs in increasing edge order, made for the nodes the search reaches (routing_memo)
        self.adj = node_adjacency(mesh, self.feasible)
        self.edges_at = node_adjacency(mesh, np.ones(len(self.l0), dtype=bool))  # every edge: edge_id
        self.owner = [-1] * mesh.n_nodes
        self.units: list[_Unit] = []
        self.mirror_uid: list[int] = []
        # the whole mesh with rest edge lengths, for the heuristic's shortest paths (built on first use)
        self.csgraph = None
        self.component = None
        self.fields = FieldStore(mesh)  # per end node: lengths, radius searched (shared: routing_memo)
        self.bounds = memoised(("lower bounds", id(mesh)), lambda: LowerBounds(mesh))  # the body's, built on use

    # -------------------------------------------------------------- helpers
    def _dir(self, a: int, b: int) -> tuple[float, float]:
        pa, pb = self.XL[a], self.XL[b]
        return (pb[0] - pa[0], pb[1] - pa[1])

    def _turn_ok(self, a: int, b: int, c: int) -> bool:
        """The turn at ``b`` of the path ``a, b, c`` obeys the tortuosity limit."""
        return turn_cost(self._dir(a, b), self._dir(b, c)) <= self.turn_limit

    def _edge_key(self, k: int) -> tuple[float, float]:
        return self.midl[k]  # (x, y)

    def edge_id(self, a: int, b: int) -> int:
        """The row of ``mesh.edges`` joining nodes ``a`` and ``b`` (KeyError if none)."""
        for u, k in self.edges_at[a]:
            if u == b:
                return k
        raise KeyError((a, b))

    # -------------------------------------------------------------- seeds and first units
    def regions(self, threshold_q: int, eligible: np.ndarray, spacing: float = 0.0) -> list[list[int]]:
        """Contracted regions, each as its strongly contracted edges (``wq >= threshold_q``), strongest first.

        A node is marked when an edge contracted by at least ``threshold_q`` (quantised) ends at it; a
        region is a connected set of marked nodes, joined by contracted edges between marked nodes. (The
        strongly contracted edges alone would not do: only the edges aligned with the compression contract
        much, so they form parallel chains that never touch, one "region" per chain.) Only ``eligible``
        edges mark nodes (see :func:`route_muscles`: compression, not the Poisson response to a stretch).
        Regions are ordered by the contraction they hold (``sum w * l0`` over their strong edges), then by
        their strongest edge and rest geometry: a small island of strongly contracted edges (where a mesh's
        first ring of nodes round a hole happens to clear the ropes' inset) would otherwise be seeded first
        and, through the seed spacing, keep the ring just outside it from being seeded. Islands beside a region
        holding far more are left out (routing_spacing)."""
        E = self.mesh.edges
        self.eligible = eligible  # for the rings of seed_units
        strong = self.feasible & (self.wq >= threshold_q) & eligible
        idx = np.flatnonzero(strong)
        if len(idx) == 0:
            return []
        n = self.mesh.n_nodes
        marked = np.zeros(n, dtype=bool)
        marked[E[idx].ravel()] = True
        link = np.flatnonzero(self.feasible & marked[E[:, 0]] & marked[E[:, 1]])
        A = csr_matrix((np.ones(len(link)), (E[link, 0], E[link, 1])), shape=(n, n))
        _, lab = connected_components(A, directed=False)
        mid = 0.5 * (self.X[E[idx, 0]] + self.X[E[idx, 1]])  # the midpoints of rest_lists, as an array
        order = np.lexsort((mid[:, 1], mid[:, 0], -self.wq[idx]))
        out: dict[int, list[int]] = {}
        for j in order.tolist():
            out.setdefault(int(lab[E[idx[j], 0]]), []).append(int(idx[j]))
        regions = list(out.values())  # dicts keep insertion order: the region of the strongest edge first
        # the contraction a region holds, sum w * l0 over its strong edges, on a grid of 1e-6 of the largest
        # (mirror regions' rest lengths differ by round-off; the stable sort keeps them in the order above)
        hold = np.array([float(np.dot(self.wq[r], self.l0[r])) for r in regions])
        hold = np.rint(hold / (1e-6 * hold.max())).astype(np.int64)
        order = np.argsort(-hold, kind="stable")
        regions = [regions[i] for i in order.tolist()]
        if spacing > 0:  # an island beside a region holding far more is its fragment (routing_spacing)
            regions = [r for r, ok in zip(regions, apart_from_stronger(self.mesh, [E[r].ravel() for r in regions],
                                                                        spacing, hold[order])) if ok]
        return regions

    def seed_units(self, regions: list[list[int]], n_seeds: int, spacing: float = 0.0) -> list[int]:
        """First units: the ring ropes round squeezed holes (:meth:`rings`), then region by region: the
        region's ``n_seeds`` most contracted edges are its seeds; each
        connected component of them is cut into simple paths, straightest continuation first and every
        turn within the tortuosity limit; in symmetric mode each path comes with its mirror image. A path
        is started only from a seed edge farther than ``spacing`` (a length) from every node of the units
        made before it: on a fine mesh the most contracted edges of a region lie in several parallel rows
        a cell apart, which would otherwise each become a muscle. Returns the seed edges, region by region,
        strongest first."""
        E = self.mesh.edges
        seeds = []
        taken = np.zeros(self.mesh.n_nodes, dtype=bool)  # nodes of the units made so far
        for group in self.rings():  # a ring rope, or a mirror pair of them (no seed spacing: a ring is no row)
            for p in group:
                self._new_unit(p)
                self.ring_uids.add(len(self.units) - 1)  # complete: it neither grows nor is spliced into
            if len(group) == 2:
                self.mirror_uid[-1], self.mirror_uid[-2] = len(self.units) - 2, len(self.units) - 1
        for edges in regions:
            top = edges[:n_seeds]
            seeds += top
            rank = {k: r for r, k in enumerate(top)}
            sg = nx.Graph()
            sg.add_edges_from((int(E[k, 0]), int(E[k, 1]), {"k": k}) for k in top)
            comps = [sorted((d["k"] for _, _, d in sg.subgraph(c).edges(data=True)), key=rank.__getitem__)
                     for c in nx.connected_components(sg)]
            comps.sort(key=lambda ks: rank[ks[0]])  # strongest component first
            pool = set(top)
            for ks in comps:
                for k0 in ks:
                    a, b = (int(v) for v in E[k0])
                    if k0 not in pool or self.owner[a] != -1 or self.owner[b] != -1:
                        continue
                    if spacing > 0 and taken.any() and \
                            np.min(np.linalg.norm(self.X[taken] - self.midl[k0], axis=1)) < spacing:
                        continue
                    path = self._extract_path(k0, pool)
                    if not path:
                        continue
                    paths = [path]
                    if self.mp is not None:
                        mirror = [self.mp[v] for v in path]
                        if set(mirror) != set(path):
                            paths.append(mirror)
                    for p in paths:
                        self._new_unit(p)
                        taken[p] = True
                        pool.difference_update(self.edge_id(u, v) for u, v in zip(p[:-1], p[1:]))
                    if len(paths) == 2:
                        self.mirror_uid[-1], self.mirror_uid[-2] = len(self.units) - 2, len(self.units) - 1
        return seeds

    def rings(self) -> list[tuple[list[int], ...]]:
        """The ring ropes round the holes the target squeezes (:mod:`~mdsr_opt.synthesis.routing_rings`): per
        hole whose rim shortens all round and round which a ring of routable edges winds within the tortuosity
        limit, whose every edge passes the nonuniformity gate against the ring's mean (``K_a * g_a <= 1``) and
        whose contraction (``sum w * l0``) lies at least half on compression-dominated edges (those
        :meth:`regions` was given: at the default ``compression_ratio`` a hole drawn shut, whose hoop
        contraction comes with a radial stretch about as large, gets no ring), the ring opened into a rope
        (in symmetric mode, a ring that is its own mirror image opened on the axis; a mirror pair of rings
        is laid as a pair, the second the mirror image of the first)."""
        from .routing_rings import hole_rings, open_ring

        out, used = [], set()
        for cycle in hole_rings(self.mesh, self.feasible, self.wq, self.turn_limit, self.floor_q):
            if used & set(cycle) or (self.mp is not None and used & {self.mp[v] for v in cycle}):
                continue
            ks = [self.edge_id(a, b) for a, b in zip(cycle, cycle[1:] + cycle[:1])]
            n, s1 = len(ks), sum(self.wql[k] for k in ks)
            if any(self.K_a * mismatch(((n, s1), (1, self.wql[k]))) > 1.0 for k in ks):
                continue
            hold = self.wq[ks] * self.l0[ks]
            if self.eligible is not None and hold[self.eligible[ks]].sum() < 0.5 * hold.sum():
                continue  # mostly the sideways response of a radial stretch (see compression_ratio)
            rope = open_ring(cycle, self.wq, self.edge_id, self.XL, self.mp)
            if rope is None:
                continue
            used.update(cycle)
            if self.mp is not None and {self.mp[v] for v in cycle} != set(cycle):
                out.append((rope, [self.mp[v] for v in rope]))
            else:
                out.append((rope,))
        return out

    def _extract_path(self, k0: int, pool: set[int]) -> list[int]:
        a, b = (int(v) for v in self.mesh.edges[k0])
        if tuple(self.XL[b]) < tuple(self.XL[a]):
            a, b = b, a
        path = [a, b]
        on = {a, b}
        n, s1 = 1, self.wql[k0]  # edge count and weight sum of the path, for the nonuniformity gate
        mp = self.mp
        mode = "free"
        if mp is not None:
            if mp[a] == b:
                mode = "crossing"   # the edge crosses the axis: extend both ends as mirror images
            elif mp[a] == a and mp[b] == b:
                mode = "axis"       # the edge lies on the axis: stay on it
            elif mp[a] == a or mp[b] == b:
                return []           # one end on the axis: not a seed (growth may still reach it)
            else:
                mode = "side"       # keep to one side so the mirror path is disjoint
        for _ in range(2):  # extend the tail, then (after reversing) the other end
            while True:
                t, p = path[-1], path[-2]
                d = self._dir(p, t)
                best = None
                for u, k in self.adj[t]:
                    if k not in pool or u in on or self.owner[u] != -1:
                        continue
                    if mode == "axis" and mp[u] != u:
                        continue
                    if mode == "side" and (mp[u] == u or mp[u] in on or self.owner[mp[u]] != -1):
                        continue
                    if mode == "crossing" and (mp[u] == u or mp[u] in on or self.owner[mp[u]] != -1
                                               or not self._turn_ok(mp[p], mp[t], mp[u])):
                        continue
                    tc = turn_cost(d, self._dir(t, u))
                    if tc > self.turn_limit:
                        continue
                    q = self.wql[k]
                    parts = ((n, s1), (1, q), (1, q)) if mode == "crossing" else ((n, s1), (1, q))
                    if self.K_a * mismatch(parts) + self.K_b * tc > 1.0:
                        continue  # a seed path obeys the same gate as growth
                    key = (tc,) + self._edge_key(k)
                    if best is None or key < best[0]:
                        best = (key, u, q)
                if best is None:
                    break
                path.append(best[1])
                on.add(best[1])
                n, s1 = n + (2 if mode == "crossing" else 1), s1 + (2 if mode == "crossing" else 1) * best[2]
                if mode == "crossing":
                    path.insert(0, mp[best[1]])
                    on.add(mp[best[1]])
            if mode == "crossing":
                break
            path.reverse()
        return path

    def _new_unit(self, path: list[int]) -> None:
        wq = [self.wql[self.edge_id(a, b)] for a, b in zip(path[:-1], path[1:])]
        u = _Unit(len(self.units), path, wq)
        self.units.append(u)
        self.mirror_uid.append(u.uid)
        for v in path:
            self.owner[v] = u.uid

    # -------------------------------------------------------------- candidate steps
    def _candidates(self):
        """Every allowed step: (g, edge key, end coords, unit, at_tail, node, edge id, partner)."""
        out = []
        owner, units, XL, wql = self.owner, self.units, self.XL, self.wql
        K_a, K_b, lim, mp = self.K_a, self.K_b, self.turn_limit, self.mp
        rings = self.ring_uids
        for U in units:
            if not U.alive or U.uid in rings:
                continue
            for at_tail in (False, True):
                if at_tail:
                    N, P = U.path[-1], U.path[-2]
                else:
                    N, P = U.path[0], U.path[1]
                d = self._dir(P, N)
                for u, k in self.adj[N]:
                    o = owner[u]
                    q = wql[k]
                    e = self._dir(N, u)
                    t1 = turn_cost(d, e)
                    if t1 > lim:
                        continue
                    if o == -1:
                        a = mismatch(((U.n, U.s1), (1, q)))
                        g = K_a * a + K_b * t1
                        partner = None
                    elif o != U.uid and o not in rings:
                        V = units[o]
                        if u == V.path[0]:
                            nxt = V.path[1]
                        elif u == V.path[-1]:
                            nxt = V.path[-2]
                        else:
                            continue  # cannot join a unit in its middle
                        t2 = turn_cost(e, self._dir(u, nxt))
                        if t2 > lim:
                            continue
                        a = mismatch(((U.n, U.s1), (1, q), (V.n, V.s1)))
                        g = K_a * a + K_b * max(t1, t2)
                        partner = V
                    else:
                        continue  # own path: a muscle is a simple path
                    if g > 1.0:
                        continue
                    if mp is not None and not self._orbit_ok(U, N, u, k, partner):
                        continue
                    out.append((g, self._edge_key(k), tuple(XL[N]), U, at_tail, u, k, partner))
        return out

    def _orbit_ok(self, U, N: int, u: int, k: int, V) -> bool:
        """Symmetric mode: the step and its mirror image can both be taken and keep every path simple."""
        mp = self.mp
        Um = self.mirror_uid[U.uid]
        if Um == U.uid:  # a unit that is its own mirror image grows at both ends at once
            if mp[u] == u:
                return False
            return V is None or self.mirror_uid[V.uid] != V.uid
        if V is not None and V.uid == Um:  # joining its own mirror image: one edge, or a cycle
            return mp[N] == u
        if V is None and mp[u] == u:  # both reach the same axis node: they meet there
            return self._turn_ok(N, u, mp[N])
        return True

    def _apply_orbit(self, cand) -> None:
        """Take a step; in symmetric mode then its mirror image, and refresh the mirror pairing."""
        _, _, _, U, at_tail, u, k, V = cand
        N = U.path[-1] if at_tail else U.path[0]
        self._apply(U, at_tail, u, k, V)
        if self.mp is None:
            return
        mN, mu = self.mp[N], self.mp[u]
        W = self.units[self.owner[mN]]
        if self.owner[mu] != W.uid:  # the mirror step is not done yet
            if W.path[-1] == mN:
                tail = True
            elif W.path[0] == mN:
                tail = False
            else:  # pragma: no cover - _orbit_ok rules this out
                raise AssertionError("mirror step from the middle of a unit")
            o = self.owner[mu]
            self._apply(W, tail, mu, self.me[k], None if o == -1 else self.units[o])
        for Z in self.units:
            if Z.alive:
                self.mirror_uid[Z.uid] = self.owner[self.mp[Z.path[0]]]

    # -------------------------------------------------------------- heuristic
    def _ends(self) -> list[tuple[int, int]]:
        """(unit id, node) of both endpoints of every alive unit; drops the fields of stale endpoints."""
        ends = [(U.uid, U.path[i]) for U in self.units if U.alive for i in (0, -1)]
        current = {node for _, node in ends}
        for node in [node for node in self.fields if node not in current]:
            del self.fields[node]  # an old endpoint is inside its unit now and never an endpoint again
        return ends

    def _graph(self) -> None:
        """The whole mesh with rest edge lengths and its connected components, built on first use."""
        if self.csgraph is None:
            self.csgraph, self.component = rest_graph(self.mesh)

    def _field(self, node: int) -> np.ndarray:
        """Shortest-path lengths (rest lengths, all mesh edges) from ``node`` to every node; cached."""
        f, reach = self.fields.get(node, (None, -1.0))
        if reach < math.inf:
            self._graph()
            f = dijkstra(self.csgraph, directed=True, indices=node)
            self.fields[node] = (f, math.inf)
        return f

    def _distance(self, node: int, u: int, need: float, straight: float) -> float:
        """The shortest-path length from ``node`` to ``u`` (in the same component) when it is at most
        ``need``, else ``inf``; ``straight`` is a lower bound of it (the straight line).

        Dijkstra's search from ``node`` stops at a radius (``limit``): at least ``need``, and when ``need``
        is unbounded 1.1 times the straight line plus two edges, doubled until ``u`` lies inside. The lengths
        inside the radius are those of the whole search (the same nodes settled in the same order), so the
        choice of :meth:`_choose` is that of the full fields, and on a fine mesh each search settles only the
        nodes near the unit's end instead of the whole body. The search is kept per end node with its radius;
        a search on a thin region first proves most "farther than ``need``" (routing_bounds)."""
        f, reach = self.fields.get(node, (None, -1.0))
        while True:
            if f is not None:
                d = float(f[u])
                if d <= reach:  # settled inside the radius: exact
                    return d if d <= need else math.inf
                if reach >= need:  # farther than the radius, which covers what is asked
                    return math.inf
            if math.isfinite(need) and self.bounds.farther(node, u, need):
                return math.inf
            reach = max(need if math.isfinite(need) else 1.1 * straight + 2.0 * self.ell, 2.0 * reach)
            f = dijkstra(self.csgraph, directed=True, indices=node, limit=reach)
            self.fields[node] = (f, reach)

    def _heuristic(self, cands) -> np.ndarray:
        """``h`` of every candidate: the shortest-path length along mesh edges (rest lengths, in mean edge
        lengths) from its new endpoint to the nearest endpoint of another unit; 0 when no other unit is
        reachable (a separate part of the body) or there is no other unit. The reference for
        :meth:`_choose`, which computes ``h`` only where it can change the choice."""
        ends = self._ends()
        if len(ends) < 4:
            return np.zeros(len(cands))
        pts = [c[5] for c in cands]
        D = np.array([self._field(node)[pts] for _, node in ends])          # (endpoints, candidates)
        ids = np.array([uid for uid, _ in ends])
        cid = np.array([c[3].uid for c in cands])
        D[ids[:, None] == cid[None, :]] = np.inf
        h = D.min(axis=0)
        h[~np.isfinite(h)] = 0.0
        return h / self.ell

    def _choose(self, cands) -> int:
        """Index of the step with the smallest key ``(g + K_h * h, edge midpoint, end node)``.

        The same choice as taking the minimum over :meth:`_heuristic`, but cheaper: a path along mesh
        edges is never shorter than the straight line, so ``g + K_h * |u - e| / ell`` bounds each
        candidate's ``f`` from below. Candidates are visited in the order of that bound and the search
        stops once the bound exceeds the best ``f`` found; within a candidate, endpoints are visited by
        straight-line distance, so a Dijkstra search runs only from endpoints that could be the nearest,
        and only as far as a length that could still make the candidate the best (:meth:`_distance`). Most
        steps then need no new search at all.
        """
        K_h = self.K_h
        ends = self._ends() if K_h > 0 else []
        if len(ends) < 4:  # fewer than two units: h = 0 everywhere
            return min(range(len(cands)), key=lambda i: (cands[i][0], cands[i][1], cands[i][2]))
        self._graph()  # the whole mesh's graph and components, on first use
        comp = self.component
        cn = np.array([c[5] for c in cands])
        en = np.array([node for _, node in ends])
        P, Q = self.X[cn], self.X[en]  # the rest positions (XL's values)
        # straight-line lower bounds, shrunk by 1e-9 so round-off cannot lift them above the path length
        lb = np.sqrt(((P[:, None, :] - Q[None, :, :]) ** 2).sum(axis=2)) * ((1.0 - 1e-9) / self.ell)
        ids = np.array([uid for uid, _ in ends])
        cid = np.array([c[3].uid for c in cands])
        lb[(ids[None, :] == cid[:, None]) | (comp[cn][:, None] != comp[en][None, :])] = np.inf
        lb_h = lb.min(axis=1)
        reachable = np.isfinite(lb_h)  # another unit's end in the same part of the body
        lb_h[~reachable] = 0.0  # no other unit reachable: h = 0
        g = np.array([c[0] for c in cands])
        bound = g + K_h * lb_h
        best_key, best = None, -1
        for i in np.argsort(bound, kind="stable").tolist():
            if best_key is not None and bound[i] > best_key[0]:
                break
            u, row = cands[i][5], lb[i]
            # a path longer than ``cap`` makes this step's key larger than the best one (a margin for
            # round-off): such lengths need not be known
            cap = math.inf if best_key is None else \
                (best_key[0] - cands[i][0]) / K_h * self.ell * (1.0 + 1e-9) + 1e-12 * self.ell
            h = math.inf
            for j in np.argsort(row, kind="stable").tolist():
                if row[j] * self.ell >= min(h, cap):  # also ends the loop at the masked (inf) entries
                    break
                h = min(h, self._distance(ends[j][1], u, min(h, cap), row[j] * self.ell))
            if math.isinf(h) and reachable[i]:
                continue  # another unit is reachable, but farther than cap: this step cannot be chosen
            h = h / self.ell if math.isfinite(h) else 0.0
            key = (cands[i][0] + K_h * h, cands[i][1], cands[i][2])
            if best_key is None or key < best_key:
                best_key, best = key, i
        return best

    # -------------------------------------------------------------- the whole search
    def search(self, *, seed_threshold: float, compressed: np.ndarray, n_seeds: int, spacing: float,
               min_length: float):
        """Regions, seeds, growth and fragments on the feasible edges: (regions, seed edges, dropped units as
        (path, rest length, why))."""
        # the reference contraction: the largest w reached by edges of total rest length 4 mean edge lengths
        # (not w_max, which a single short edge at a corner can dominate)
        feas = np.flatnonzero(self.feasible)
        order = feas[np.argsort(-self.wq[feas], kind="stable")]
        reach = np.searchsorted(np.cumsum(self.l0[order]), 4.0 * self.ell)
        w_ref_q = int(self.wq[order[min(reach, len(order) - 1)]])
        threshold_q = max(self.floor_q + 1, int(math.ceil(seed_threshold * w_ref_q)))
        self.threshold_q = threshold_q  # the seed threshold reached (quantised), for a message when nothing seeds
        regions = self.regions(threshold_q, compressed, spacing)
        seeds = self.seed_units(regions, n_seeds, spacing)
        self.grow()
        return regions, seeds, self.settle_fragments(min_length)

    # -------------------------------------------------------------- growth
    def grow(self) -> None:
        while True:
            cands = self._candidates()
            if not cands:
                return
            self._apply_orbit(cands[self._choose(cands)])

    def _apply(self, U, at_tail: bool, u: int, k: int, V) -> None:
        """Grow unit ``U`` by the edge ``k`` to node ``u`` (at its tail or head), splicing in unit ``V``
        when ``u`` is one of ``V``'s ends."""
        q = self.wql[k]
        if not at_tail:  # always grow at the tail
            U.path.reverse()
        if V is None:
            U.path.append(u)
            self.owner[u] = U.uid
            U.n += 1
            U.s1 += q
        else:
            vp = list(V.path)
            if vp[0] != u:
                vp.reverse()
            U.path.extend(vp)
            for v in vp:
                self.owner[v] = U.uid
            U.n += 1 + V.n
            U.s1 += q + V.s1
            V.alive = False

    # -------------------------------------------------------------- fragments
    def settle_fragments(self, min_length: float) -> list[tuple[tuple[int, ...], float, str]]:
        """Splice or drop the units shorter than ``min_length``; returns (path, rest length, what happened).

        A short unit (a fragment) is spliced into another unit when one of its ends is joined to one of that
        unit's ends by a contracted edge, every turn at the joint obeys the tortuosity limit, and the
        nonuniformity gate holds with the mismatch weighted by the fragment's share of the joined edges
        (``K_a * share * g_a <= 1``: a short fragment may differ more than a growth step). Otherwise it is
        dropped. Fragments are
        handled shortest first; in symmetric mode a fragment and its mirror image share their fate.
        """
        notes = []
        l0 = self.l0

        def length(U):
            p = list(U.path)
            return float(sum(l0[self.edge_id(a, b)] for a, b in zip(p[:-1], p[1:])))

        while True:
            short = [U for U in self.units if U.alive and length(U) < min_length]
            if not short:
                return notes
            short.sort(key=lambda U: (length(U), tuple(self.XL[min(U.path, key=lambda v: self.XL[v])])))
            F = short[0]
            L = length(F)
            join = None
            for at_tail in (False, True):
                N = F.path[-1] if at_tail else F.path[0]
                P = (F.path[-2] if at_tail else F.path[1]) if len(F.path) > 1 else None
                for u, k in sorted(self.adj[N], key=lambda uk: self._edge_key(uk[1])):
                    o = self.owner[u]
                    if o == -1 or o == F.uid or o in self.ring_uids:
                        continue
                    V = self.units[o]
                    if u not in (V.path[0], V.path[-1]):
                        continue
                    nxt = V.path[1] if u == V.path[0] else V.path[-2]
                    if (P is not None and not self._turn_ok(P, N, u)) or not self._turn_ok(N, u, nxt):
                        continue
                    q = self.wql[k]
                    share = (F.n + 1) / (F.n + 1 + V.n)
                    if self.K_a * share * mismatch(((F.n, F.s1), (1, q), (V.n, V.s1))) > 1.0:
                        continue  # the fragment contracts too differently for its share of the muscle
                    if self.mp is not None and not self._orbit_ok(F, N, u, k, V):
                        continue
                    join = (at_tail, u, k, V)
                    break
                if join is not None:
                    break
            path = tuple(F.path)
            if join is not None:
                V = join[3]
                notes.append((path, L, f"spliced into the unit through node {join[1]}: shorter than "
                                       f"min_length={min_length:.4g} (rest length {L:.4g})"))
                self._apply_orbit((0.0, None, None, F, join[0], join[1], join[2], V))
            else:
                group = [F]
                if self.mp is not None:
                    M = self.units[self.mirror_uid[F.uid]]
                    if M is not F:
                        group.append(M)
                for G in group:
                    notes.append((tuple(G.path), length(G),
                                  f"dropped: rest length {length(G):.4g} < min_length={min_length:.4g} and no "
                                  "unit end to splice into within the tortuosity limit and the nonuniformity gate"))
                    G.alive = False
                    for v in G.path:
                        self.owner[v] = -1
