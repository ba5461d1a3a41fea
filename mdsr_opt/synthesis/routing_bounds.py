"""Proofs that a shortest path on the rest mesh is longer than a length, for the routing search's heuristic.

The heuristic of :class:`~mdsr_opt.synthesis.routing_search.Router` asks, for a growth step, whether the shortest
path along mesh edges (rest lengths) from another unit's end ``s`` to the step's new node ``u`` is at most a length
``need``. Mostly ``need`` lies within a few percent of the straight line ``|x_u - x_s|`` and the answer is no, and
Dijkstra's search proves that only by settling every node within ``need`` of ``s``: on a fine mesh most of the body.

Subtracting a linear potential from the lengths proves it on a thin region instead. With a unit vector ``n``, an
edge ``a -> b`` of rest length ``l`` costs ``l - <x_b - x_a, n>``, which is not negative because the rest length is
the straight distance; so Dijkstra's search still applies, and a path from ``s`` to ``x`` of rest length ``L`` costs
``L - <x - x_s, n>`` (the sum telescopes). With ``n`` near the direction from ``s`` to ``u``, the nodes whose reduced
length stays within ``need - <x_u - x_s, n>`` lie in a thin region about the segment from ``s`` to ``u`` (an A*
search with the potential as its estimate). After such a search stopped at a reduced length ``limit``, every node
``x`` has ``rest path length >= min(reduced length, limit) + <x - x_s, n>``; when that bound exceeds ``need`` (by a
margin for round-off), the path is longer than ``need``. Otherwise nothing is known and the caller searches as
before, so the lengths the routing compares are still those of Dijkstra's search on the rest lengths and every
choice it makes is the same.

The directions are :data:`N_DIRECTIONS` fixed unit vectors, each with its reduced graph built on first use; the
searches are kept per source node and direction (their settled nodes only), so one search answers the later
steps near the same unit end. Inside :func:`~mdsr_opt.synthesis.routing_memo.shared_work` the routings of one body
share them (the graphs and bounds depend on the mesh alone).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from .routing_memo import rest_graph

__all__ = ["LowerBounds", "N_DIRECTIONS", "BOUND_REACH", "BOUND_FLOATS", "GRAPH_FLOATS"]

#: the fixed directions of the linear potentials (a query uses the nearest to its own direction)
N_DIRECTIONS = 32
#: a search goes this many mean edge lengths (in reduced length) beyond what its own query needs, so that it also
#: answers the next steps near the same unit end
BOUND_REACH = 0.25
#: the most settled lengths kept (nodes with their reduced lengths), the oldest searches dropped first
BOUND_FLOATS = 1 << 21
#: the most reduced lengths (one per directed edge and direction) kept, the least recently used direction dropped
GRAPH_FLOATS = 1 << 23


class LowerBounds:
    """Lower bounds of the rest-length shortest paths of ``mesh`` (every edge, both ways) from its nodes.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    >>> b = LowerBounds(mesh)
    >>> b.farther(0, 16, 3.9), b.farther(0, 16, 4.0 + 1e-6)   # node 16 is the corner (4, 0): a path of length 4
    (True, False)
    >>> b.farther(0, 84, 4.2), b.farther(0, 84, 4.5)   # to the corner (4, 1): 4 + sqrt(2) - 1 along the edges
    (True, False)
    """

    def __init__(self, mesh):
        self.mesh = mesh
        self.graph = None  # the arrays below are made on the first query

    def _build(self) -> None:
        mesh = self.mesh
        self.graph = rest_graph(mesh)[0]
        G, X = self.graph, mesh.points
        rows = np.repeat(np.arange(G.shape[0]), np.diff(G.indptr))
        self.dx, self.dy = X[G.indices, 0] - X[rows, 0], X[G.indices, 1] - X[rows, 1]
        self.X = X
        self.ell = float(mesh.edge_lengths.mean()) if G.nnz else 0.0
        # reduced lengths are kept at least ``floor`` (never 0), and a bound gives way by the most that and the
        # round-off of the reduced lengths can add along a path (at most n_nodes edges)
        self.floor = 1e-12 * (float(G.data.max()) if G.nnz else 0.0)
        self.slack = 2.0 * mesh.n_nodes * self.floor
        self.unit = [(math.cos(2.0 * math.pi * k / N_DIRECTIONS), math.sin(2.0 * math.pi * k / N_DIRECTIONS))
                     for k in range(N_DIRECTIONS)]
        self._graphs: dict[int, csr_matrix] = {}
        self._searched: dict[tuple[int, int], tuple] = {}  # (node, direction) -> (nodes, reduced lengths, limit)
        self._floats = 0

    def _reduced(self, k: int) -> csr_matrix:
        H = self._graphs.pop(k, None)
        if H is None:
            c, s = self.unit[k]
            G = self.graph
            data = np.maximum(G.data - (self.dx * c + self.dy * s), self.floor)
            H = csr_matrix((data, G.indices, G.indptr), shape=G.shape)
            while self._graphs and (len(self._graphs) + 1) * G.nnz > GRAPH_FLOATS:
                self._graphs.pop(next(iter(self._graphs)))
        self._graphs[k] = H  # the most recently used last
        return H

    def farther(self, s: int, u: int, need: float) -> bool:
        """True when the shortest path from node ``s`` to node ``u`` (rest lengths) is proven longer than ``need``;
        False when it is not known (it may still be)."""
        if not math.isfinite(need):
            raise ValueError(f"need must be a finite length, got {need!r}")
        if self.graph is None:
            self._build()
        vx, vy = float(self.X[u, 0] - self.X[s, 0]), float(self.X[u, 1] - self.X[s, 1])
        k = int(round(math.atan2(vy, vx) / (2.0 * math.pi) * N_DIRECTIONS)) % N_DIRECTIONS
        c, sn = self.unit[k]
        proj = vx * c + vy * sn
        margin = 1e-9 * abs(need) + self.slack
        # a reduced length above this proves it (the path's length then exceeds need + margin)
        want = need + margin - proj
        if want < 0.0:  # reduced lengths are not negative: farther than the projection alone
            return True
        got = self._searched.get((s, k))
        if got is not None:
            if self._bound(got, u) > want:
                return True
            if got[2] > want:  # u settled within the bound: a new search finds the same reduced length
                return False
        limit = want + BOUND_REACH * self.ell
        g = dijkstra(self._reduced(k), directed=True, indices=s, limit=limit)
        nodes = np.flatnonzero(np.isfinite(g))
        got = (nodes, g[nodes], limit)
        self._keep((s, k), got)
        return self._bound(got, u) > want

    @staticmethod
    def _bound(got, u: int) -> float:
        """The reduced length to ``u`` (the limit when the search did not settle it)."""
        nodes, lengths, limit = got
        i = int(np.searchsorted(nodes, u))
        return float(lengths[i]) if i < len(nodes) and nodes[i] == u else limit

    def _keep(self, key, got) -> None:
        old = self._searched.pop(key, None)
        self._floats += len(got[0]) - (0 if old is None else len(old[0]))
        self._searched[key] = got
        while self._floats > BOUND_FLOATS and len(self._searched) > 1:
            self._floats -= len(self._searched.pop(next(iter(self._searched)))[0])
