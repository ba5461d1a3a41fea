"""Muscle routing: the contraction graph of a target shape and the best-first muscle search.

Given the rest mesh and a target configuration (typically the result of external driving), every mesh edge
gets a weight, its relative contraction ``w = (l0 - l) / l0`` (positive: the edge shortens, negative: it
stretches). :func:`contraction_graph` returns these as a networkx graph. :func:`route_muscles` lays
muscle units along strongly and uniformly contracted, smooth chains of edges:

1. **Seeds.** The ``n_seeds`` most contracted edges whose weight exceeds ``min_contraction``.
2. **First units.** Each connected component of the seed edges is cut into simple paths (the straightest
   continuation first); each path is a muscle unit.
3. **Growth and splicing.** Units grow from their endpoints by a best-first (A*-like) search. A step adds
   a contracted edge ``e`` at an endpoint ``N`` and costs

   ``g = K_a * Var(w over the grown unit) / w_max**2 + K_b * (1 - cos(theta))``,

   the unit's nonuniformity after the step (relative to the largest contraction ``w_max``) plus the
   tortuosity of the turn ``theta`` between ``e`` and the unit's end direction. A step is allowed only
   if ``g <= 1``. Of all allowed steps, the one with the smallest ``f = g + K_h * h`` is taken, where
   ``h`` is the shortest-path length along mesh edges (rest lengths, in mean edge lengths) from the new
   endpoint to the nearest endpoint of another unit. A step that reaches another unit's endpoint joins
   the two units into one (splicing: fewer, longer muscles). Growth ends when no step is allowed.
4. **Selection.** Units shorter than ``min_length`` are dropped; the rest are ranked by the contraction
   they capture (``sum w * l0`` over their edges) and the first ``max_muscles`` are returned.

A cable cannot push: an edge with ``w <= min_contraction`` (every elongated or unchanged edge) is never
part of a muscle, neither as a seed nor by growth. A target that only stretches the body, contracts
nothing by more than ``min_contraction``, or equals the rest shape (every edge length within a relative
``1e-8``, up to a rigid motion) gives no muscles and a :class:`RoutingWarning` saying which.

Deviations from the paper (and from the project's design notes), on purpose:

* ``g_a`` is the unit's variance *after* the step over ``w_max**2``, not the *rise* in the variance.
  The rise can be negative (an edge near the unit's mean lowers the variance), which would reward a
  step, and gating each step's rise lets the variance creep up without bound over many small steps.
  The variance after the step, gated by ``g <= 1``, caps every muscle's relative variance at ``1/K_a``,
  and dividing by ``w_max**2`` makes ``K_a`` independent of how strongly the target contracts.
* ``h`` is the shortest-path length along mesh edges, not the Manhattan distance. The paper takes the
  Manhattan distance because a muscle follows the lattice edges, so its length is closer to that than
  to the straight-line distance. On a triangle mesh the length along mesh edges is exactly that path
  length, and unlike a Manhattan distance (which depends on the x and y axes) it does not change when
  the body is rotated: rotating mesh and target together gives the same muscles.

Determinism: ties are broken by rest geometry (edge midpoints, node coordinates), never by node index,
and weights are compared on a grid of ``1e-9``, so the ~1e-16 round-off of a rigid motion of the target
changes the order of two weights only if they straddle a grid boundary (in practice never; the tests
check several motions). Relabelling the nodes or moving the target rigidly gives the same muscles.

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh
>>> from mdsr_opt.routing import route_muscles
>>> mesh = Mesh.rectangle(4.0, 1.0, nx=16, ny=4)
>>> target = mesh.points * [0.8, 1.0]          # shorten along x by 20 %
>>> result = route_muscles(mesh, target)
>>> len(result) > 0 and all(s.turning_angle == 0.0 for s in result.stats)
True
"""

from __future__ import annotations

import math
import numbers
import warnings
from collections import deque
from dataclasses import asdict, dataclass, field

import networkx as nx
import numpy as np
from numpy.typing import ArrayLike
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from ._checks import as_float_array, check_mesh, positive_float
from .mesh import Mesh
from .muscles import Muscle
from .results import format_value, to_jsonable

__all__ = [
    "contraction_graph",
    "edge_weights",
    "route_muscles",
    "RoutingResult",
    "MuscleStats",
    "RoutingWarning",
]

#: Weights are compared as integers on this grid (rigid-motion round-off is ~1e-16).
_QUANTUM = 1e-9
#: A target whose every edge length matches its rest length within this relative tolerance
#: (``|l - l0| <= _REST_RTOL * l0``, i.e. ``|w| <= _REST_RTOL``) counts as the rest shape.
_REST_RTOL = 1e-8


class RoutingWarning(UserWarning):
    """Routing found nothing to do (rest-shape or elongation-only target) or dropped every unit."""


# ---------------------------------------------------------------------------------------------- input
def _check_target(mesh: Mesh, target: ArrayLike) -> np.ndarray:
    """The target as a finite (n, 2) float array without inverted triangles."""
    x = as_float_array(target, "target", shape=(mesh.n_nodes, 2))
    J = mesh.jacobians(x)
    bad = J <= 0.0
    if bad.all():
        raise ValueError(f"target inverts every triangle (det F <= 0 in all {mesh.n_triangles}); "
                         "is it a mirror image of the body?")
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(f"target has {int(bad.sum())} inverted triangle(s) (det F <= 0), first: triangle "
                         f"{k} {mesh.triangles[k].tolist()} with det F = {J[k]:.3g}; "
                         "a physical target keeps every element positively oriented")
    return x


def edge_weights(mesh: Mesh, target: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rest lengths, target lengths and relative contractions of ``mesh.edges``.

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    target : array_like, shape (n, 2)
        Target node positions; must be finite and must not invert any triangle.

    Returns
    -------
    l0, l, w : ndarray, shape (k,)
        Rest length, target length and ``w = (l0 - l) / l0`` of each row of ``mesh.edges``. ``l0`` is
        the mesh's cached ``edge_lengths`` and read-only (copy it to modify); ``l`` and ``w`` are new
        arrays, so changing them affects nothing else.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(1.0, 1.0, 1, 1, pattern="right")
    >>> l0, l, w = edge_weights(mesh, mesh.points * [0.5, 1.0])
    >>> float(w.max())
    0.5
    """
    mesh = check_mesh(mesh)
    return _weights(mesh, _check_target(mesh, target))


def _weights(mesh: Mesh, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    e = mesh.edges
    l0 = mesh.edge_lengths
    l = np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1)
    return l0, l, (l0 - l) / l0


def contraction_graph(mesh: Mesh, target: ArrayLike) -> nx.Graph:
    """The contraction graph of ``target`` over the rest ``mesh``.

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    target : array_like, shape (n, 2)
        Target node positions (e.g. an external-driving equilibrium). Finite, no inverted triangle.

    Returns
    -------
    networkx.Graph
        One node per mesh node (attributes ``rest`` and ``target``: coordinate tuples) and one edge per
        mesh edge with attributes ``rest_length``, ``target_length`` and ``weight`` =
        ``(rest_length - target_length) / rest_length`` (positive: contraction, negative: elongation).
        ``graph.graph`` holds ``w_max`` and ``w_min``. Note that weights can be negative, so the graph is
        not meant for networkx shortest-path routines.

    Raises
    ------
    TypeError
        ``mesh`` is not a :class:`~mdsr_opt.Mesh` or ``target`` is not numeric.
    ValueError
        ``target`` has the wrong shape, contains NaN/inf, or inverts a triangle.

    Example
    -------
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(2.0, 1.0, 2, 1)
    >>> G = contraction_graph(mesh, mesh.points * [0.9, 1.0])
    >>> round(G.edges[0, 1]["weight"], 6)
    0.1
    """
    mesh = check_mesh(mesh)
    x = _check_target(mesh, target)
    return _graph(mesh, x, *_weights(mesh, x))


def _graph(mesh: Mesh, x: np.ndarray, l0: np.ndarray, l: np.ndarray, w: np.ndarray) -> nx.Graph:
    G = nx.Graph(w_max=float(w.max()), w_min=float(w.min()))
    G.add_nodes_from((i, {"rest": tuple(p), "target": tuple(q)})
                     for i, (p, q) in enumerate(zip(mesh.points.tolist(), x.tolist())))
    G.add_edges_from((a, b, {"rest_length": r, "target_length": t, "weight": c})
                     for (a, b), r, t, c in zip(mesh.edges.tolist(), l0.tolist(), l.tolist(), w.tolist()))
    return G


# ---------------------------------------------------------------------------------------------- results
@dataclass(frozen=True)
class MuscleStats:
    """Figures of one routed muscle.

    Attributes
    ----------
    name : str
        The muscle's name.
    n_edges : int
        Number of mesh edges along the path.
    rest_length, target_length : float
        Path length at rest and in the target.
    contraction : float
        ``1 - target_length / rest_length``: the contraction that would make the whole cable match the
        target (a first guess for the design stage).
    mean_weight : float
        Mean relative contraction ``w`` of the path's edges.
    nonuniformity : float
        Variance of those weights (the paper's nonuniformity coefficient; 0 = perfectly uniform).
    turning_angle : float
        Total absolute turning of the path at rest, radians (0 = straight).
    turning_angle_target : float
        The same in the target configuration.
    """

    name: str
    n_edges: int
    rest_length: float
    target_length: float
    contraction: float
    mean_weight: float
    nonuniformity: float
    turning_angle: float
    turning_angle_target: float

    def to_dict(self) -> dict:
        """The figures as a JSON-ready dict."""
        return to_jsonable(asdict(self))


@dataclass(frozen=True, eq=False)
class RoutingResult:
    """Muscles routed for a target, with their figures.

    Iterating, ``len`` and indexing act on :attr:`muscles`, so ``for m in route_muscles(...)`` works.
    Two results compare equal only if they are the same object (``eq=False``: the graph and the dict
    have no meaningful ``==``); compare ``[m.nodes for m in result]`` instead.

    Attributes
    ----------
    muscles : tuple of Muscle
        The routed muscles, strongest first (by ``sum w * l0`` over their edges). Each path starts at the
        end whose rest coordinates are lexicographically smaller.
    stats : tuple of MuscleStats
        One entry per muscle, same order.
    graph : networkx.Graph
        The contraction graph (see :func:`contraction_graph`).
    seeds : tuple of (int, int)
        The seed edges, most contracted first.
    n_units : int
        Units left when growth stopped, before ``min_length``/``max_muscles`` selection.
    params : dict
        The knobs used (``K_a``, ``K_b``, ``K_h``, ``n_seeds``, ``max_muscles``, ``min_length``,
        ``min_contraction``).
    """

    muscles: tuple[Muscle, ...]
    stats: tuple[MuscleStats, ...]
    graph: nx.Graph
    seeds: tuple[tuple[int, int], ...] = ()
    n_units: int = 0
    params: dict = field(default_factory=dict)

    def __iter__(self):
        return iter(self.muscles)

    def __len__(self) -> int:
        return len(self.muscles)

    def __getitem__(self, i):
        return self.muscles[i]

    def __repr__(self) -> str:
        names = [m.name for m in self.muscles]
        return (f"RoutingResult({len(self.muscles)} muscle(s) {format_value(names)}, edges "
                f"{format_value([s.n_edges for s in self.stats])}, contractions "
                f"{format_value([round(s.contraction, 4) for s in self.stats])}, n_units={self.n_units}, "
                f"seeds={len(self.seeds)}, graph={self.graph.number_of_nodes()} nodes)")

    def to_dict(self) -> dict:
        """Muscles, their figures, seeds, unit count and knobs as a JSON-ready dict (the graph is left out:
        :func:`contraction_graph` rebuilds it from the mesh and the target)."""
        return to_jsonable({"muscles": list(self.muscles), "stats": [s.to_dict() for s in self.stats],
                            "seeds": list(self.seeds), "n_units": self.n_units, "params": dict(self.params)})

    def table(self) -> str:
        """The stats as a plain-text table (one row per muscle)."""
        head = (f"{'muscle':<10} {'edges':>5} {'L0':>9} {'L':>9} {'contr.':>7} {'mean w':>8} "
                f"{'var w':>9} {'turn':>7}")
        rows = [head, "-" * len(head)]
        for s in self.stats:
            rows.append(f"{s.name:<10} {s.n_edges:>5d} {s.rest_length:>9.4g} {s.target_length:>9.4g} "
                        f"{s.contraction:>7.3f} {s.mean_weight:>8.4f} {s.nonuniformity:>9.2e} "
                        f"{s.turning_angle:>7.3f}")
        return "\n".join(rows)


# ---------------------------------------------------------------------------------------------- search
class _Unit:
    """A muscle unit during the search: a simple path and exact integer sums of its quantised weights."""

    __slots__ = ("uid", "path", "n", "s1", "s2", "alive")

    def __init__(self, uid: int, path: list[int], wq: list[int]):
        self.uid = uid
        self.path = deque(path)
        self.n = len(wq)
        self.s1 = sum(wq)
        self.s2 = sum(q * q for q in wq)
        self.alive = True


def _turn_cost(d, e) -> float:
    """``1 - cos`` of the angle between direction vectors ``d`` and ``e``."""
    c = (d[0] * e[0] + d[1] * e[1]) / math.sqrt((d[0] * d[0] + d[1] * d[1]) * (e[0] * e[0] + e[1] * e[1]))
    return 1.0 - max(-1.0, min(1.0, c))


def _int_param(value, name: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


class _Router:
    """One routing run; all orderings use rest geometry, never node indices."""

    def __init__(self, mesh: Mesh, w: np.ndarray, K_a: float, K_b: float, K_h: float, floor_q: int,
                 ell: float):
        self.mesh = mesh
        self.X = mesh.points
        self.XL = mesh.points.tolist()
        self.K_a, self.K_b, self.K_h = K_a, K_b, K_h
        self.wq = np.rint(w / _QUANTUM).astype(np.int64)
        self.wql = self.wq.tolist()
        self.feasible = self.wq > floor_q
        E = mesh.edges
        mid = 0.5 * (self.X[E[:, 0]] + self.X[E[:, 1]])
        self.midl = mid.tolist()
        self.wref2 = float(int(self.wq.max()) ** 2)
        self.l0 = mesh.edge_lengths
        self.ell = ell
        # adjacency over feasible (contracted) edges only: a cable cannot push
        adj: list[list[tuple[int, int]]] = [[] for _ in range(mesh.n_nodes)]
        feasible = np.flatnonzero(self.feasible)
        for k, (a, b) in zip(feasible.tolist(), E[feasible].tolist()):
            adj[a].append((b, k))
            adj[b].append((a, k))
        self.adj = adj
        self.owner = [-1] * mesh.n_nodes
        self.units: list[_Unit] = []
        # the whole mesh with rest edge lengths, for the heuristic's shortest paths (built on first use)
        self.csgraph = None
        self.component = None
        self.fields: dict[int, np.ndarray] = {}

    # -------------------------------------------------------------- helpers
    def _nu(self, n: int, s1: int, s2: int) -> float:
        """Variance of the quantised weights over ``w_max**2`` (exact integer sums, one division)."""
        return (n * s2 - s1 * s1) / (n * n * self.wref2)

    def _dir(self, a: int, b: int) -> tuple[float, float]:
        pa, pb = self.XL[a], self.XL[b]
        return (pb[0] - pa[0], pb[1] - pa[1])

    def _edge_key(self, k: int) -> tuple[float, float]:
        return (self.midl[k][0], self.midl[k][1])

    # -------------------------------------------------------------- seeds and first units
    def seeds(self, n_seeds: int) -> list[int]:
        idx = np.flatnonzero(self.feasible)
        mid = np.asarray(self.midl)[idx]
        order = np.lexsort((mid[:, 1], mid[:, 0], -self.wq[idx]))
        return idx[order[:n_seeds]].tolist()

    def first_units(self, seeds: list[int]) -> None:
        """Connected components of the seed edges, cut into simple paths (straightest continuation first)."""
        E = self.mesh.edges
        sg = nx.Graph()
        sg.add_edges_from((int(E[k, 0]), int(E[k, 1]), {"k": k}) for k in seeds)
        rank = {k: r for r, k in enumerate(seeds)}
        comps = [sorted((d["k"] for _, _, d in sg.subgraph(c).edges(data=True)), key=rank.__getitem__)
                 for c in nx.connected_components(sg)]
        comps.sort(key=lambda ks: rank[ks[0]])  # strongest component first
        for ks in comps:
            remaining = list(ks)  # in seed order
            while remaining:
                path = self._extract_path(remaining[0], set(remaining))
                used = {self._eid(a, b) for a, b in zip(path[:-1], path[1:])}
                self._new_unit(path)
                # units never share a node: drop seed edges that touch the new path (branches)
                owner = self.owner
                remaining = [k for k in remaining if k not in used
                             and owner[E[k, 0]] == -1 and owner[E[k, 1]] == -1]

    def _eid(self, a: int, b: int) -> int:
        return self.mesh.edge_index[(a, b) if a < b else (b, a)]

    def _extract_path(self, k0: int, pool: set[int]) -> list[int]:
        a, b = (int(v) for v in self.mesh.edges[k0])
        if tuple(self.XL[b]) < tuple(self.XL[a]):
            a, b = b, a
        path = [a, b]
        on = {a, b}
        for _ in range(2):  # extend the tail, then (after reversing) the other end
            while True:
                t, p = path[-1], path[-2]
                d = self._dir(p, t)
                best = None
                for u, k in self.adj[t]:
                    if k in pool and u not in on and self.owner[u] == -1:
                        key = (_turn_cost(d, self._dir(t, u)),) + self._edge_key(k)
                        if best is None or key < best[0]:
                            best = (key, u)
                if best is None:
                    break
                path.append(best[1])
                on.add(best[1])
            path.reverse()
        return path

    def _new_unit(self, path: list[int]) -> None:
        wq = [self.wql[self._eid(a, b)] for a, b in zip(path[:-1], path[1:])]
        u = _Unit(len(self.units), path, wq)
        self.units.append(u)
        for v in path:
            self.owner[v] = u.uid

    # -------------------------------------------------------------- candidate steps
    def _candidates(self):
        """Every allowed step: (g, edge key, end coords, unit, at_tail, node, edge id, partner)."""
        out = []
        owner, units, XL, wql = self.owner, self.units, self.XL, self.wql
        K_a, K_b = self.K_a, self.K_b
        for U in units:
            if not U.alive:
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
                    if o == -1:
                        a = self._nu(U.n + 1, U.s1 + q, U.s2 + q * q)
                        g = K_a * a + K_b * _turn_cost(d, self._dir(N, u))
                        partner = None
                    elif o != U.uid:
                        V = units[o]
                        if u == V.path[0]:
                            nxt = V.path[1]
                        elif u == V.path[-1]:
                            nxt = V.path[-2]
                        else:
                            continue  # cannot join a unit in its middle
                        a = self._nu(U.n + 1 + V.n, U.s1 + q + V.s1, U.s2 + q * q + V.s2)
                        e = self._dir(N, u)
                        g = K_a * a + K_b * max(_turn_cost(d, e), _turn_cost(e, self._dir(u, nxt)))
                        partner = V
                    else:
                        continue  # own path: a muscle is a simple path
                    if g <= 1.0:
                        out.append((g, self._edge_key(k), tuple(XL[N]), U, at_tail, u, k, partner))
        return out

    # -------------------------------------------------------------- heuristic
    def _ends(self) -> list[tuple[int, int]]:
        """(unit id, node) of both endpoints of every alive unit; drops the fields of stale endpoints."""
        ends = [(U.uid, U.path[i]) for U in self.units if U.alive for i in (0, -1)]
        current = {node for _, node in ends}
        for node in [node for node in self.fields if node not in current]:
            del self.fields[node]  # an old endpoint is inside its unit now and never an endpoint again
        return ends

    def _field(self, node: int) -> np.ndarray:
        """Shortest-path lengths (rest lengths, all mesh edges) from ``node`` to every node; cached."""
        f = self.fields.get(node)
        if f is None:
            if self.csgraph is None:
                E, n = self.mesh.edges, self.mesh.n_nodes
                rows, cols = np.concatenate([E[:, 0], E[:, 1]]), np.concatenate([E[:, 1], E[:, 0]])
                self.csgraph = csr_matrix((np.concatenate([self.l0, self.l0]), (rows, cols)), shape=(n, n))
                self.component = connected_components(self.csgraph, directed=False)[1]
            f = self.fields[node] = dijkstra(self.csgraph, directed=True, indices=node)
        return f

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
        straight-line distance, so a Dijkstra field is computed only for endpoints that could be the
        nearest. Most steps then need no new field at all.
        """
        K_h = self.K_h
        ends = self._ends() if K_h > 0 else []
        if len(ends) < 4:  # fewer than two units: h = 0 everywhere
            return min(range(len(cands)), key=lambda i: (cands[i][0], cands[i][1], cands[i][2]))
        self._field(ends[0][1])  # builds the graph and its components on first use
        comp = self.component
        P = np.array([self.XL[c[5]] for c in cands])
        Q = np.array([self.XL[node] for _, node in ends])
        # straight-line lower bounds, shrunk by 1e-9 so round-off cannot lift them above the path length
        lb = np.sqrt(((P[:, None, :] - Q[None, :, :]) ** 2).sum(axis=2)) * ((1.0 - 1e-9) / self.ell)
        ids = np.array([uid for uid, _ in ends])
        cid = np.array([c[3].uid for c in cands])
        cn = np.array([c[5] for c in cands])
        en = np.array([node for _, node in ends])
        lb[(ids[None, :] == cid[:, None]) | (comp[cn][:, None] != comp[en][None, :])] = np.inf
        lb_h = lb.min(axis=1)
        lb_h[~np.isfinite(lb_h)] = 0.0  # no other unit reachable: h = 0
        g = np.array([c[0] for c in cands])
        bound = g + K_h * lb_h
        best_key, best = None, -1
        for i in np.argsort(bound, kind="stable").tolist():
            if best_key is not None and bound[i] > best_key[0]:
                break
            u, row = cands[i][5], lb[i]
            h = math.inf
            for j in np.argsort(row, kind="stable").tolist():
                if row[j] * self.ell >= h:  # also ends the loop at the masked (inf) entries
                    break
                h = min(h, float(self._field(ends[j][1])[u]))
            h = h / self.ell if math.isfinite(h) else 0.0
            key = (cands[i][0] + K_h * h, cands[i][1], cands[i][2])
            if best_key is None or key < best_key:
                best_key, best = key, i
        return best

    # -------------------------------------------------------------- growth
    def grow(self) -> None:
        while True:
            cands = self._candidates()
            if not cands:
                return
            self._apply(cands[self._choose(cands)])

    def _apply(self, cand) -> None:
        """Take one step (grow a unit by an edge, or splice it with another unit)."""
        _, _, _, U, at_tail, u, k, V = cand
        q = self.wql[k]
        if not at_tail:  # always grow at the tail
            U.path.reverse()
        if V is None:
            U.path.append(u)
            self.owner[u] = U.uid
            U.n += 1
            U.s1 += q
            U.s2 += q * q
        else:
            vp = list(V.path)
            if vp[0] != u:
                vp.reverse()
            U.path.extend(vp)
            for v in vp:
                self.owner[v] = U.uid
            U.n += 1 + V.n
            U.s1 += q + V.s1
            U.s2 += q * q + V.s2
            V.alive = False


def route_muscles(mesh: Mesh, target: ArrayLike, *, K_a: float = 10.0, K_b: float = 4.0, K_h: float = 0.1,
                  n_seeds: int = 8, max_muscles: int | None = None, min_length: float | None = None,
                  min_contraction: float = 1e-3) -> RoutingResult:
    """Route muscle units along contracted, uniform, smooth chains of mesh edges.

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    target : array_like, shape (n, 2)
        Target node positions (e.g. an external-driving equilibrium); finite, no inverted triangle.
    K_a : float, default 10
        Weight of nonuniformity: a growth step is allowed only if
        ``K_a * Var(w)/w_max**2 + K_b * (1 - cos(theta)) <= 1``, so ``1/K_a`` caps the relative variance
        a growing muscle may reach. Raise it for more, shorter, more uniform muscles; lower it for fewer,
        longer ones.
    K_b : float, default 4
        Weight of tortuosity: ``1/K_b`` caps ``1 - cos`` of each turn (4 allows about 41 degrees at zero
        nonuniformity). Raise it for straighter muscles.
    K_h : float, default 0.1
        Weight of the heuristic (shortest-path length along mesh edges to the nearest other unit's
        endpoint, in mean edge lengths) in the best-first order; it steers growth toward other units so
        they join.
    n_seeds : int, default 8
        Number of most-contracted edges that seed the search (the paper uses 5 to 10).
    max_muscles : int, optional
        Keep at most this many muscles (the strongest by ``sum w * l0``); default: all.
    min_length : float, optional
        Drop muscles whose rest length is below this; default: twice the mean rest edge length
        (so a lone seed edge that could not grow is dropped).
    min_contraction : float, default 1e-3
        The floor: only edges with ``w > min_contraction`` are used (a cable cannot push, so elongated
        and unchanged edges never carry a muscle).

    Returns
    -------
    RoutingResult
        Iterable of :class:`~mdsr_opt.Muscle`; ``.stats`` holds length, mean and variance of the weights
        (nonuniformity) and total turning angle per muscle, ``.graph`` the contraction graph.

    Raises
    ------
    TypeError
        ``mesh`` is not a Mesh, a knob has the wrong type, or ``target`` is not numeric.
    ValueError
        ``target`` has the wrong shape, contains NaN/inf or inverts a triangle; a knob is out of range.

    Warns
    -----
    RoutingWarning
        The target equals the rest shape (every edge length within a relative ``1e-8``, up to a rigid
        motion), only stretches the body, contracts no edge by more than ``min_contraction``, or every
        unit is shorter than ``min_length``. The message says which; the result is then empty.

    Example
    -------
    >>> import numpy as np
    >>> from mdsr_opt import Mesh
    >>> mesh = Mesh.rectangle(4.0, 1.0, nx=16, ny=4)
    >>> X = mesh.points
    >>> R, phi = 3.0, (X[:, 0] - 2.0) / 3.0            # bend the strip about the centre line y = 0.5
    >>> r = R - (X[:, 1] - 0.5)                          # the top side (y = 1) is on the inside
    >>> target = np.column_stack([r * np.sin(phi), R - r * np.cos(phi)])
    >>> result = route_muscles(mesh, target)
    >>> bool(np.all(X[list(result[0].nodes), 1] > 0.5))  # the muscle runs on the concave side
    True
    """
    mesh = check_mesh(mesh)
    K_a = positive_float(K_a, "K_a", allow_zero=True)
    K_b = positive_float(K_b, "K_b", allow_zero=True)
    K_h = positive_float(K_h, "K_h", allow_zero=True)
    n_seeds = _int_param(n_seeds, "n_seeds")
    if max_muscles is not None:
        max_muscles = _int_param(max_muscles, "max_muscles")
    ell = float(mesh.edge_lengths.mean())
    if min_length is None:
        min_length = 2.0 * ell
    else:
        min_length = positive_float(min_length, "min_length", allow_zero=True)
    min_contraction = positive_float(min_contraction, "min_contraction", allow_zero=True)
    if min_contraction >= 1.0:
        raise ValueError("min_contraction must be < 1 (a fraction of the rest length), "
                         f"got {min_contraction}")
    params = dict(K_a=K_a, K_b=K_b, K_h=K_h, n_seeds=n_seeds, max_muscles=max_muscles,
                  min_length=min_length, min_contraction=min_contraction)

    x = _check_target(mesh, target)
    l0, l, w = _weights(mesh, x)
    graph = _graph(mesh, x, l0, l, w)

    def empty(msg: str) -> RoutingResult:
        warnings.warn(msg, RoutingWarning, stacklevel=3)
        return RoutingResult((), (), graph, (), 0, params)

    w_abs = float(np.abs(w).max())
    if w_abs <= _REST_RTOL:
        return empty(f"target equals the rest shape within tolerance (up to a rigid motion): no edge "
                     f"length changes by more than {_REST_RTOL:g} of its rest length (largest "
                     f"|w| = {w_abs:.3g}), so there is nothing for a muscle to do; no muscles routed")
    floor_q = int(round(min_contraction / _QUANTUM))
    router = _Router(mesh, w, K_a, K_b, K_h, floor_q, ell)
    if not router.feasible.any():
        w_top = float(w.max())
        if w_top <= _REST_RTOL:
            return empty(f"no edge contracts (largest relative stretch {-float(w.min()):.3g}): the "
                         "target only stretches the body and a cable cannot push; no muscles routed")
        return empty(f"no edge contracts by more than min_contraction={min_contraction:g} (largest "
                     f"contraction {w_top:.3g}); lower min_contraction to route such weak contractions. "
                     "Elongated edges cannot carry a muscle (a cable cannot push); no muscles routed")
    seeds = router.seeds(n_seeds)
    router.first_units(seeds)
    router.grow()

    E = mesh.edges
    units = [U for U in router.units if U.alive]
    found = []
    for U in units:
        path = list(U.path)
        if tuple(router.XL[path[-1]]) < tuple(router.XL[path[0]]):
            path.reverse()
        ks = [router._eid(a, b) for a, b in zip(path[:-1], path[1:])]
        L0 = float(sum(l0[k] for k in ks))
        if L0 < min_length:
            continue
        strength = sum(router.wql[k] * l0[k] for k in ks)
        found.append((-strength, tuple(router.XL[path[0]]), tuple(router.XL[path[-1]]), path, ks))
    found.sort(key=lambda t: t[:3])
    if max_muscles is not None:
        found = found[:max_muscles]
    seed_edges = tuple((int(E[k, 0]), int(E[k, 1])) for k in seeds)
    if not found:
        warnings.warn(f"all {len(units)} muscle unit(s) are shorter than min_length={min_length:.4g}; "
                      "no muscles routed (lower min_length, K_a or K_b)", RoutingWarning, stacklevel=2)
        return RoutingResult((), (), graph, seed_edges, len(units), params)

    muscles, stats = [], []
    for i, (_, _, _, path, ks) in enumerate(found):
        m = Muscle(path, name=f"muscle {i}")
        wk = w[ks]
        L0, L = m.length(mesh.points), m.length(x)
        muscles.append(m)
        stats.append(MuscleStats(name=m.name, n_edges=len(ks), rest_length=L0, target_length=L,
                                 contraction=1.0 - L / L0, mean_weight=float(wk.mean()),
                                 nonuniformity=float(wk.var()), turning_angle=m.turning_angle(mesh.points),
                                 turning_angle_target=m.turning_angle(x)))
    return RoutingResult(tuple(muscles), tuple(stats), graph, seed_edges, len(units), params)
