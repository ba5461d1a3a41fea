"""Work shared between the routings of one body and one target.

:func:`~mdsr_opt.synthesis.routing.route_for_design` routes the same target up to four times (at the
fabrication's clearance, deeper inside, with ``K_a = 1``, and on every contracted edge snapped into the band).
Much of that is the same work: the body's mirror symmetry, the compression-dominated edges, and the search
inside the band at an inset an earlier routing already searched (the band routing pools exactly that search
with its snapped ropes), and the searches' shortest-path lengths from unit ends (:class:`FieldStore`). Inside
:func:`shared_work`, :func:`memoised` computes each such piece once and
returns the same object afterwards; outside it, it simply computes. The results are the same either way: the
keys name every input the piece depends on, the mesh (by identity, alive for the whole scope) and the target
included.
"""

from __future__ import annotations

import contextlib
from contextvars import ContextVar
from typing import Callable, Hashable, Iterator, TypeVar

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

__all__ = ["FieldStore", "NodeAdjacency", "PointList", "SHARED_FIELD_FLOATS", "memoised", "node_adjacency",
           "rest_graph", "rest_lists", "shared_work"]

T = TypeVar("T")

_MEMO: ContextVar[dict | None] = ContextVar("mdsr_routing_memo", default=None)


@contextlib.contextmanager
def shared_work() -> Iterator[dict]:
    """A scope in which :func:`memoised` keeps what it computes (one mesh and one target only)."""
    token = _MEMO.set({})
    try:
        yield _MEMO.get()
    finally:
        _MEMO.reset(token)


def memoised(key: Hashable, make: Callable[[], T]) -> T:
    """``make()``, kept under ``key`` inside :func:`shared_work` and returned again for the same key.

    Example
    -------
    >>> calls = []
    >>> with shared_work():
    ...     a = memoised("k", lambda: calls.append(1) or [1])
    ...     b = memoised("k", lambda: calls.append(1) or [2])
    >>> a is b, len(calls)
    (True, 1)
    """
    memo = _MEMO.get()
    if memo is None:
        return make()
    if key not in memo:
        memo[key] = make()
    return memo[key]


class PointList:
    """Points of an ``(n, 2)`` array for Python loops: ``points[i]`` is the pair ``(x_i, y_i)`` of floats, made
    on access from two flat lists (a list per point made up front was 10^4-10^5 containers per routing on a
    fine mesh, whose allocations set off full passes of the cyclic garbage collector)."""

    __slots__ = ("x", "y")

    def __init__(self, A: np.ndarray):
        self.x, self.y = A[:, 0].tolist(), A[:, 1].tolist()

    def __getitem__(self, i: int) -> tuple[float, float]:
        return (self.x[i], self.y[i])

    def __len__(self) -> int:
        return len(self.x)


def rest_lists(mesh) -> tuple[PointList, PointList]:
    """The rest positions and the edge midpoints of ``mesh`` as :class:`PointList` objects (for Python loops),
    memoised."""
    def make():
        X, E = mesh.points, mesh.edges
        return PointList(X), PointList(0.5 * (X[E[:, 0]] + X[E[:, 1]]))

    return memoised(("rest lists", id(mesh)), make)


def rest_graph(mesh):
    """``(graph, components)``, memoised: every edge of ``mesh`` with its rest length both ways (CSR), and
    the connected component of each node."""
    def make():
        E, n, l0 = mesh.edges, mesh.n_nodes, mesh.edge_lengths
        rows, cols = np.concatenate([E[:, 0], E[:, 1]]), np.concatenate([E[:, 1], E[:, 0]])
        graph = csr_matrix((np.concatenate([l0, l0]), (rows, cols)), shape=(n, n))
        return graph, connected_components(graph, directed=False)[1]

    return memoised(("rest graph", id(mesh)), make)


#: the most shortest-path lengths (floats) the routings of one body keep for each other inside
#: :func:`shared_work`, besides each routing's own (:class:`FieldStore`)
SHARED_FIELD_FLOATS = 1 << 23


class FieldStore(dict):
    """One routing's shortest-path lengths per source node (``node -> (lengths, radius searched)``, the
    rest graph's: :func:`rest_graph`), shared with the other routings of the same body inside
    :func:`shared_work`: a node the routing has not searched from is looked up among theirs (the lengths
    depend on the mesh alone, and an entry is exact within its radius whoever searched), and what it searches
    is kept there too, up to :data:`SHARED_FIELD_FLOATS` (the oldest dropped first). The routing's own
    entries are the dict's: it drops them as it did alone."""

    def __init__(self, mesh):
        super().__init__()
        memo = _MEMO.get()
        # the shared entries and the floats they hold
        self.shared = None if memo is None else memo.setdefault(("path fields", id(mesh)), [{}, 0])

    def get(self, node, default=None):
        if node in self:
            return self[node]
        return default if self.shared is None else self.shared[0].get(node, default)

    def __setitem__(self, node, value) -> None:
        super().__setitem__(node, value)
        if self.shared is None:
            return
        sh, total = self.shared
        old = sh.pop(node, None)
        sh[node] = value
        total += len(value[0]) - (0 if old is None else len(old[0]))
        while total > SHARED_FIELD_FLOATS and len(sh) > 1:
            total -= len(sh.pop(next(iter(sh)))[0])
        self.shared[1] = total


class NodeAdjacency:
    """Each node's ``(neighbour, edge)`` pairs over the edges ``keep`` (a mask over ``E``, the mesh's edges),
    in increasing edge order: ``adjacency[node]`` is a list made on first access and kept. A search reads
    the nodes its units reach, a small part of a fine mesh; a list per node made up front was some 10^5
    containers per routing, whose allocations set off full passes of the cyclic garbage collector."""

    def __init__(self, E: np.ndarray, keep: np.ndarray, n_nodes: int):
        k = np.flatnonzero(keep)
        ends = np.concatenate([E[k, 0], E[k, 1]])
        order = np.lexsort((np.concatenate([k, k]), ends))
        self._nbr = np.concatenate([E[k, 1], E[k, 0]])[order].tolist()
        self._edge = np.concatenate([k, k])[order].tolist()
        self._cut = np.searchsorted(ends[order], np.arange(n_nodes + 1)).tolist()
        self._made: dict[int, list] = {}

    def __getitem__(self, node: int) -> list:
        pairs = self._made.get(node)
        if pairs is None:
            s, e = self._cut[node], self._cut[node + 1]
            pairs = self._made[node] = list(zip(self._nbr[s:e], self._edge[s:e]))
        return pairs


def node_adjacency(mesh, keep: np.ndarray) -> NodeAdjacency:
    """:class:`NodeAdjacency` of ``mesh`` over the edges ``keep``, memoised (routings on the same edges share it)."""
    return memoised(("adjacency", id(mesh), np.asarray(keep, dtype=bool).tobytes()),
                    lambda: NodeAdjacency(mesh.edges, keep, mesh.n_nodes))
