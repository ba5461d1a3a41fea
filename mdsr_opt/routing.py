"""Muscle routing: the contraction graph of a target shape and the best-first muscle search.

Given the rest mesh and a target configuration (typically the result of external driving), every mesh edge
gets a weight, its relative contraction ``w = (l0 - l) / l0`` (positive: the edge shortens, negative: it
stretches). :func:`contraction_graph` returns these as a networkx graph. :func:`route_muscles` lays
muscle units along strongly and uniformly contracted, smooth chains of edges:

1. **Regions and seeds.** The contracted regions are the connected sets of edges contracted by at least
   ``seed_threshold * w_ref`` (``w_ref``: the contraction reached by the most contracted edges of total
   rest length four mean edge lengths; a single short edge at a corner would dominate ``w_max``). Each region is seeded on its own with its ``n_seeds`` most contracted
   edges (a global top-n would put every seed in the most contracted region).
2. **First units.** Each connected component of the seed edges is cut into simple paths, straightest
   continuation first, every turn within ``max_turn``; each path is a muscle unit.
3. **Growth and splicing.** Units grow from their endpoints by a best-first (A*-like) search. A step adds
   a contracted edge ``e`` at an endpoint ``N`` (or joins another unit's endpoint through ``e``) and costs

   ``g = K_a * g_a + K_b * (1 - cos(theta))``,

   where ``g_a`` is the nonuniformity of the step: the largest squared relative deviation of a joined
   part's mean contraction from the mean of the grown unit, ``max_p ((mean_p - mean) / mean)**2`` over
   the parts (the unit, the edge, and the other unit when splicing), and ``theta`` the turn taken (for a
   splice, the larger of the two turns at the joint). A step is allowed only if ``g <= 1`` and no turn
   exceeds ``max_turn`` (the tortuosity rule, which seed paths obey too). Of all allowed steps the one
   with the smallest ``f = g + K_h * h`` is taken, ``h`` being the shortest-path length along mesh edges
   (rest lengths, in mean edge lengths) from the new endpoint to the nearest endpoint of another unit.
   Joining another unit's endpoint splices the two (fewer, longer muscles). Growth ends when no step is
   allowed.
4. **Fragments and selection.** Units shorter than ``min_length`` are spliced into a neighbouring unit
   end (within the tortuosity limit) or dropped; the result's ``dropped`` records each with the reason.
   The rest are ranked by the contraction they capture (``sum w * l0``), and at most ``max_muscles`` kept.
5. **Symmetry.** When the body is mirror-symmetric and the target contracts mirrored edges alike,
   every step is taken together with its mirror image (:mod:`mdsr_opt.routing_symmetry`), so the
   muscles are mirror pairs or their own mirror images, node for node.

A cable cannot push: an edge with ``w <= min_contraction`` (every elongated or unchanged edge) is never
part of a muscle, neither as a seed nor by growth. A target that only stretches the body, contracts
nothing by more than ``min_contraction``, or equals the rest shape (every edge length within a relative
``1e-8``, up to a rigid motion) gives no muscles and a :class:`RoutingWarning` saying which.

Why ``g_a`` is a relative mismatch (a change made for the paper's Figure 6)
-----------------------------------------------------------------------------
An earlier version took ``g_a = Var(w over the grown unit) / w_max**2``. The weights along a chain of
contracted edges vary smoothly and lie in ``(0, w_max]``, so that variance stays below about
``0.03 w_max**2`` for any unit: ``K_a * g_a`` reached the gate ``g <= 1`` only for ``K_a`` of about 30 to
100, and below that ``K_a`` changed nothing (3 of the 5 Figure-6 targets routed identically for every
``K_a`` in 0.1 .. 10). Growth runs until no step is allowed, so ``K_a`` acts only through the gate, never
through the order. The relative mismatch is dimensionless and of order one: an edge that contracts half
as much as the unit costs ``0.25 K_a``. ``K_a`` then states how alike the parts of a muscle must be
(within ``1/sqrt(K_a)`` of the mean at zero turn), and over ``K_a`` = 1 .. 30 a smaller value splices more
units into fewer, longer muscles, as the paper reports. The paper's own ``g_a`` is the rise of the
variance; a rise can be negative (an edge near the mean lowers the variance) and lets the variance creep
over many steps, so it is not used.

Deviations from the paper (and from the project's design notes), on purpose:

* ``g_a`` as above.
* ``h`` is the shortest-path length along mesh edges, not the Manhattan distance. The paper takes the
  Manhattan distance because a muscle follows the lattice edges, so its length is closer to that than
  to the straight-line distance. On a triangle mesh the length along mesh edges is exactly that path
  length, and unlike a Manhattan distance (which depends on the x and y axes) it does not change when
  the body is rotated: rotating mesh and target together gives the same muscles.
* The tortuosity is a rule (``max_turn``) besides a cost: the paper wants smooth muscles; a rope that turns
  sharply at a node rubs and cuts the silicone.

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
from dataclasses import dataclass, field

import networkx as nx
import numpy as np
from numpy.typing import ArrayLike
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from ._checks import as_float_array, check_mesh, positive_float
from .mesh import Mesh
from .muscles import Muscle
from .routing_symmetry import Reflection, find_reflections, weights_are_symmetric

__all__ = [
    "contraction_graph",
    "edge_weights",
    "route_muscles",
    "RoutingResult",
    "MuscleStats",
    "RoutingWarning",
    "DroppedUnit",
    "largest_turn",
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
    max_turn : float
        The largest turn at any single node, at rest, radians (the tortuosity rule bounds it).
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
    max_turn: float = 0.0


@dataclass(frozen=True)
class DroppedUnit:
    """A unit that is not a muscle of the result as it stood, and why.

    Attributes
    ----------
    nodes : tuple of int
        Its path when it was spliced, dropped or cut.
    rest_length : float
        Its rest length then.
    reason : str
        ``"spliced into ..."``, ``"dropped: ..."`` or ``"cut by max_muscles ..."``.
    """

    nodes: tuple
    rest_length: float
    reason: str


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
        ``min_contraction``, ``max_turn``, ``seed_threshold``, ``symmetry``).
    dropped : tuple of DroppedUnit
        Fragments shorter than ``min_length`` (spliced or dropped) and muscles cut by ``max_muscles``.
    reflection : Reflection or None
        The mirror symmetry the muscles were routed with (None: not symmetric, or switched off).
    n_regions : int
        Contracted regions that were seeded.
    """

    muscles: tuple[Muscle, ...]
    stats: tuple[MuscleStats, ...]
    graph: nx.Graph
    seeds: tuple[tuple[int, int], ...] = ()
    n_units: int = 0
    params: dict = field(default_factory=dict)
    dropped: tuple = ()
    reflection: Reflection | None = None
    n_regions: int = 0

    def __iter__(self):
        return iter(self.muscles)

    def __len__(self) -> int:
        return len(self.muscles)

    def __getitem__(self, i):
        return self.muscles[i]

    def table(self) -> str:
        """The stats as a plain-text table (one row per muscle)."""
        head = (f"{'muscle':<10} {'edges':>5} {'L0':>9} {'L':>9} {'contr.':>7} {'mean w':>8} "
                f"{'var w':>9} {'turn':>7} {'max':>5}")
        rows = [head, "-" * len(head)]
        for s in self.stats:
            rows.append(f"{s.name:<10} {s.n_edges:>5d} {s.rest_length:>9.4g} {s.target_length:>9.4g} "
                        f"{s.contraction:>7.3f} {s.mean_weight:>8.4f} {s.nonuniformity:>9.2e} "
                        f"{s.turning_angle:>7.3f} {math.degrees(s.max_turn):>5.1f}")
        return "\n".join(rows)


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


def _turn_cost(d, e) -> float:
    """``1 - cos`` of the angle between direction vectors ``d`` and ``e``."""
    c = (d[0] * e[0] + d[1] * e[1]) / math.sqrt((d[0] * d[0] + d[1] * d[1]) * (e[0] * e[0] + e[1] * e[1]))
    return 1.0 - max(-1.0, min(1.0, c))


def _mismatch(parts) -> float:
    """``g_a`` of joining ``parts`` ((edge count, sum of quantised weights) each) into one unit: the largest
    squared relative deviation of a part's mean contraction from the joined unit's mean."""
    N = sum(n for n, _ in parts)
    S = sum(s for _, s in parts)
    return max(((s * N - S * n) / (S * n)) ** 2 for n, s in parts)


def _int_param(value, name: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


class _Router:
    """One routing run; all orderings use rest geometry, never node indices."""

    def __init__(self, mesh: Mesh, wq: np.ndarray, K_a: float, K_b: float, K_h: float, floor_q: int,
                 ell: float, turn_limit: float, mirror=None):
        self.mesh = mesh
        self.X = mesh.points
        self.XL = mesh.points.tolist()
        self.K_a, self.K_b, self.K_h = K_a, K_b, K_h
        self.turn_limit = turn_limit  # largest allowed 1 - cos(turn) at any node (+ round-off slack)
        self.wq = wq
        self.wql = self.wq.tolist()
        self.feasible = self.wq > floor_q
        E = mesh.edges
        mid = 0.5 * (self.X[E[:, 0]] + self.X[E[:, 1]])
        self.midl = mid.tolist()
        self.l0 = mesh.edge_lengths
        self.ell = ell
        self.mp = None if mirror is None else mirror.node_map.tolist()
        self.me = None if mirror is None else mirror.edge_map.tolist()
        # adjacency over feasible (contracted) edges only: a cable cannot push
        adj: list[list[tuple[int, int]]] = [[] for _ in range(mesh.n_nodes)]
        feasible = np.flatnonzero(self.feasible)
        for k, (a, b) in zip(feasible.tolist(), E[feasible].tolist()):
            adj[a].append((b, k))
            adj[b].append((a, k))
        self.adj = adj
        self.owner = [-1] * mesh.n_nodes
        self.units: list[_Unit] = []
        self.mirror_uid: list[int] = []
        # the whole mesh with rest edge lengths, for the heuristic's shortest paths (built on first use)
        self.csgraph = None
        self.component = None
        self.fields: dict[int, np.ndarray] = {}

    # -------------------------------------------------------------- helpers
    def _dir(self, a: int, b: int) -> tuple[float, float]:
        pa, pb = self.XL[a], self.XL[b]
        return (pb[0] - pa[0], pb[1] - pa[1])

    def _turn_ok(self, a: int, b: int, c: int) -> bool:
        """The turn at ``b`` of the path ``a, b, c`` obeys the tortuosity limit."""
        return _turn_cost(self._dir(a, b), self._dir(b, c)) <= self.turn_limit

    def _edge_key(self, k: int) -> tuple[float, float]:
        return (self.midl[k][0], self.midl[k][1])

    def _eid(self, a: int, b: int) -> int:
        return self.mesh.edge_index[(a, b) if a < b else (b, a)]

    # -------------------------------------------------------------- seeds and first units
    def regions(self, threshold_q: int, eligible: np.ndarray) -> list[list[int]]:
        """Contracted regions, each as its strongly contracted edges (``wq >= threshold_q``), strongest first.

        A node is marked when an edge contracted by at least ``threshold_q`` (quantised) ends at it; a
        region is a connected set of marked nodes, joined by contracted edges between marked nodes. (The
        strongly contracted edges alone would not do: only the edges aligned with the compression contract
        much, so they form parallel chains that never touch, one "region" per chain.) Only ``eligible``
        edges mark nodes (see :func:`route_muscles`: compression, not the Poisson response to a stretch).
        Regions are ordered by
        their strongest edge, then by rest geometry.
        """
        E = self.mesh.edges
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
        mid = np.asarray(self.midl)[idx]
        order = np.lexsort((mid[:, 1], mid[:, 0], -self.wq[idx]))
        out: dict[int, list[int]] = {}
        for j in order.tolist():
            out.setdefault(int(lab[E[idx[j], 0]]), []).append(int(idx[j]))
        return list(out.values())  # dicts keep insertion order: the region of the strongest edge first

    def seed_units(self, regions: list[list[int]], n_seeds: int) -> list[int]:
        """First units, region by region: the region's ``n_seeds`` most contracted edges are its seeds; each
        connected component of them is cut into simple paths, straightest continuation first and every
        turn within the tortuosity limit; in symmetric mode each path comes with its mirror image.
        Returns the seed edges, region by region, strongest first."""
        E = self.mesh.edges
        seeds = []
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
                        pool.difference_update(self._eid(u, v) for u, v in zip(p[:-1], p[1:]))
                    if len(paths) == 2:
                        self.mirror_uid[-1], self.mirror_uid[-2] = len(self.units) - 2, len(self.units) - 1
        return seeds

    def _extract_path(self, k0: int, pool: set[int]) -> list[int]:
        a, b = (int(v) for v in self.mesh.edges[k0])
        if tuple(self.XL[b]) < tuple(self.XL[a]):
            a, b = b, a
        path = [a, b]
        on = {a, b}
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
                    tc = _turn_cost(d, self._dir(t, u))
                    if tc > self.turn_limit:
                        continue
                    key = (tc,) + self._edge_key(k)
                    if best is None or key < best[0]:
                        best = (key, u)
                if best is None:
                    break
                path.append(best[1])
                on.add(best[1])
                if mode == "crossing":
                    path.insert(0, mp[best[1]])
                    on.add(mp[best[1]])
            if mode == "crossing":
                break
            path.reverse()
        return path

    def _new_unit(self, path: list[int]) -> None:
        wq = [self.wql[self._eid(a, b)] for a, b in zip(path[:-1], path[1:])]
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
                    e = self._dir(N, u)
                    t1 = _turn_cost(d, e)
                    if t1 > lim:
                        continue
                    if o == -1:
                        a = _mismatch(((U.n, U.s1), (1, q)))
                        g = K_a * a + K_b * t1
                        partner = None
                    elif o != U.uid:
                        V = units[o]
                        if u == V.path[0]:
                            nxt = V.path[1]
                        elif u == V.path[-1]:
                            nxt = V.path[-2]
                        else:
                            continue  # cannot join a unit in its middle
                        t2 = _turn_cost(e, self._dir(u, nxt))
                        if t2 > lim:
                            continue
                        a = _mismatch(((U.n, U.s1), (1, q), (V.n, V.s1)))
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
        unit's ends by a contracted edge and every turn at the joint obeys the tortuosity limit (the
        nonuniformity gate is waived: the fragment is short). Otherwise it is dropped. Fragments are
        handled shortest first; in symmetric mode a fragment and its mirror image share their fate.
        """
        notes = []
        l0 = self.l0

        def length(U):
            p = list(U.path)
            return float(sum(l0[self._eid(a, b)] for a, b in zip(p[:-1], p[1:])))

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
                    if o == -1 or o == F.uid:
                        continue
                    V = self.units[o]
                    if u not in (V.path[0], V.path[-1]):
                        continue
                    nxt = V.path[1] if u == V.path[0] else V.path[-2]
                    if (P is not None and not self._turn_ok(P, N, u)) or not self._turn_ok(N, u, nxt):
                        continue
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
                                  "unit end to splice into within the tortuosity limit"))
                    G.alive = False
                    for v in G.path:
                        self.owner[v] = -1


def route_muscles(mesh: Mesh, target: ArrayLike, *, K_a: float = 4.0, K_b: float = 4.0, K_h: float = 0.1,
                  n_seeds: int = 8, max_muscles: int | None = None, min_length: float | None = None,
                  min_contraction: float = 1e-3, max_turn: float = 45.0, seed_threshold: float = 0.6,
                  symmetry: str | bool = "auto") -> RoutingResult:
    """Route muscle units along contracted, uniform, smooth chains of mesh edges.

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    target : array_like, shape (n, 2)
        Target node positions (e.g. an external-driving equilibrium); finite, no inverted triangle.
    K_a : float, default 4
        Weight of nonuniformity ``g_a``, the largest squared relative deviation of a joined part's mean
        contraction from the grown unit's mean (see the module docstring). A step is allowed only if
        ``K_a * g_a + K_b * (1 - cos(theta)) <= 1``; at zero turn an edge may join a unit whose mean
        contraction it matches within ``1/sqrt(K_a)``. Smaller: fewer, longer muscles (more splicing);
        larger: more, shorter, more uniform ones.
    K_b : float, default 4
        Weight of tortuosity ``1 - cos(theta)`` of the turn taken.
    K_h : float, default 0.1
        Weight of the heuristic (shortest-path length along mesh edges to the nearest other unit's
        endpoint, in mean edge lengths) in the best-first order.
    n_seeds : int, default 8
        Seed edges per contracted region: the region's ``n_seeds`` most contracted edges.
    max_muscles : int, optional
        Keep at most this many muscles (the strongest by ``sum w * l0``; mirror pairs are kept or cut
        together); default: all. Cut muscles are listed in ``result.dropped``.
    min_length : float, optional
        Fragments with a smaller rest length are spliced into a neighbouring unit or dropped (the reason
        is in ``result.dropped``); default: twice the mean rest edge length.
    min_contraction : float, default 1e-3
        Only edges with ``w > min_contraction`` are used (a cable cannot push).
    max_turn : float, default 45
        Tortuosity rule, degrees: no muscle turns by more than this at any node (seed paths, growth steps
        and splice joints alike).
    seed_threshold : float, default 0.6
        Contracted regions are the connected sets of edges with ``w >= seed_threshold * w_ref``; each
        region gets its own seeds. ``w_ref`` is the largest contraction reached by edges of total rest
        length four mean edge lengths (so one short edge at a corner cannot set it).
    symmetry : {"auto", True, False}, default "auto"
        Route mirrored pairs of muscles when the body is mirror-symmetric (``find_reflections``) and
        mirrored edges contract alike (within ``1e-6 * max|w|``). ``True`` requires that and raises
        otherwise; ``False`` never does it.

    Returns
    -------
    RoutingResult
        Iterable of :class:`~mdsr_opt.Muscle`; ``.stats`` per muscle, ``.dropped`` the fragments and cut
        muscles with the reason, ``.graph`` the contraction graph, ``.reflection`` the symmetry used.

    Raises
    ------
    TypeError
        ``mesh`` is not a Mesh, a knob has the wrong type, or ``target`` is not numeric.
    ValueError
        ``target`` has the wrong shape, contains NaN/inf or inverts a triangle; a knob is out of range;
        ``symmetry=True`` for a body or target that is not mirror-symmetric.

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
    max_turn = positive_float(max_turn, "max_turn", allow_zero=True)
    if max_turn > 180.0:
        raise ValueError(f"max_turn must be <= 180 degrees, got {max_turn}")
    seed_threshold = positive_float(seed_threshold, "seed_threshold")
    if seed_threshold > 1.0:
        raise ValueError(f"seed_threshold must be in (0, 1] (a fraction of the largest contraction), "
                         f"got {seed_threshold}")
    if symmetry not in ("auto", True, False):
        raise ValueError(f"symmetry must be 'auto', True or False, got {symmetry!r}")
    params = dict(K_a=K_a, K_b=K_b, K_h=K_h, n_seeds=n_seeds, max_muscles=max_muscles,
                  min_length=min_length, min_contraction=min_contraction, max_turn=max_turn,
                  seed_threshold=seed_threshold, symmetry=symmetry)

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
    reflection = None
    if symmetry is not False:
        reflection = next((m for m in find_reflections(mesh) if weights_are_symmetric(w, m)), None)
        if symmetry is True and reflection is None:
            raise ValueError("symmetry=True but the body is not mirror-symmetric or the target does not "
                             "contract mirrored edges alike")
    wq = np.rint(w / _QUANTUM).astype(np.int64)
    if reflection is not None:  # exact symmetry of the quantised weights (floor of the pair's mean)
        wq = (wq + wq[reflection.edge_map]) // 2
    floor_q = int(round(min_contraction / _QUANTUM))
    turn_limit = (1.0 - math.cos(math.radians(max_turn))) + 1e-12
    router = _Router(mesh, wq, K_a, K_b, K_h, floor_q, ell, turn_limit, reflection)
    if not router.feasible.any():
        w_top = float(w.max())
        if w_top <= _REST_RTOL:
            return empty(f"no edge contracts (largest relative stretch {-float(w.min()):.3g}): the "
                         "target only stretches the body and a cable cannot push; no muscles routed")
        return empty(f"no edge contracts by more than min_contraction={min_contraction:g} (largest "
                     f"contraction {w_top:.3g}); lower min_contraction to route such weak contractions. "
                     "Elongated edges cannot carry a muscle (a cable cannot push); no muscles routed")
    # the reference contraction: the largest w reached by edges of total rest length 4 mean edge lengths
    # (not w_max, which a single short edge at a corner can dominate)
    feas = np.flatnonzero(router.feasible)
    order = feas[np.argsort(-wq[feas], kind="stable")]
    reach = np.searchsorted(np.cumsum(l0[order]), 4.0 * ell)
    w_ref_q = int(wq[order[min(reach, len(order) - 1)]])
    threshold_q = max(floor_q + 1, int(math.ceil(seed_threshold * w_ref_q)))
    regions = router.regions(threshold_q, _compression_dominated(mesh, x, w))
    seeds = router.seed_units(regions, n_seeds)
    router.grow()
    dropped = [DroppedUnit(p, L, why) for p, L, why in router.settle_fragments(min_length)]

    E = mesh.edges
    units = [U for U in router.units if U.alive]
    found = []
    for U in units:
        path = list(U.path)
        if tuple(router.XL[path[-1]]) < tuple(router.XL[path[0]]):
            path.reverse()
        ks = [router._eid(a, b) for a, b in zip(path[:-1], path[1:])]
        strength = sum(router.wql[k] * l0[k] for k in ks)
        found.append([-strength, tuple(router.XL[path[0]]), tuple(router.XL[path[-1]]), path, ks, U.uid])
    found.sort(key=lambda t: t[:3])
    if max_muscles is not None:
        kept, taken = [], set()
        for f in found:
            if f[5] in taken:
                continue
            orbit = [f] + [g for g in found if reflection is not None and g[5] != f[5]
                           and g[5] == router.mirror_uid[f[5]]]
            if len(kept) + len(orbit) <= max_muscles:
                kept += orbit
            else:
                for g in orbit:
                    L = float(sum(l0[k] for k in g[4]))
                    dropped.append(DroppedUnit(tuple(g[3]), L, f"cut by max_muscles={max_muscles} (weaker "
                                                                  "than the muscles kept; mirror pairs kept whole)"))
            taken.update(g[5] for g in orbit)
        found = sorted(kept, key=lambda t: t[:3])
    seed_edges = tuple((int(E[k, 0]), int(E[k, 1])) for k in seeds)
    if not found:
        warnings.warn(f"all {len(units) + len(dropped)} muscle unit(s) are shorter than min_length="
                      f"{min_length:.4g}; no muscles routed (lower min_length, K_a or K_b)", RoutingWarning,
                      stacklevel=2)
        return RoutingResult((), (), graph, seed_edges, len(units), params, tuple(dropped), reflection,
                             len(regions))

    muscles, stats = [], []
    for i, (_, _, _, path, ks, _) in enumerate(found):
        m = Muscle(path, name=f"muscle {i}")
        wk = w[ks]
        L0, L = m.length(mesh.points), m.length(x)
        muscles.append(m)
        stats.append(MuscleStats(name=m.name, n_edges=len(ks), rest_length=L0, target_length=L,
                                 contraction=1.0 - L / L0, mean_weight=float(wk.mean()),
                                 nonuniformity=float(wk.var()), turning_angle=m.turning_angle(mesh.points),
                                 turning_angle_target=m.turning_angle(x),
                                 max_turn=largest_turn(mesh.points, path)))
    return RoutingResult(tuple(muscles), tuple(stats), graph, seed_edges, len(units), params, tuple(dropped),
                         reflection, len(regions))


def _compression_dominated(mesh: Mesh, x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Edges whose contraction exceeds the largest principal stretch (``sigma_1 - 1``) of the triangles
    beside them: compression, not the sideways (Poisson) response of a stretched region."""
    sv = np.linalg.svd(mesh.deformation_gradients(x), compute_uv=False)
    stretch = sv[:, 0] - 1.0
    T = mesh.triangles
    ei = mesh.edge_index
    s_edge = np.full(len(mesh.edges), -np.inf)
    for j in range(3):
        a, b = T[:, j], T[:, (j + 1) % 3]
        k = np.array([ei[(p, q) if p < q else (q, p)] for p, q in zip(a.tolist(), b.tolist())])
        np.maximum.at(s_edge, k, stretch)
    return w > s_edge


def largest_turn(x: ArrayLike, path) -> float:
    """The largest turning angle (radians) at any interior node of ``path`` in configuration ``x``.

    Example
    -------
    >>> round(math.degrees(largest_turn([[0, 0], [1, 0], [2, 1]], [0, 1, 2])), 6)
    45.0
    """
    x = np.asarray(x, dtype=float)
    d = np.diff(x[list(path)], axis=0)
    if len(d) < 2:
        return 0.0
    a, b = d[:-1], d[1:]
    c = (a * b).sum(axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return float(np.arccos(np.clip(c, -1.0, 1.0)).max())
