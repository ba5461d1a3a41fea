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

__all__ = ["FieldStore", "SHARED_FIELD_FLOATS", "memoised", "rest_graph", "rest_lists", "shared_work"]

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


def rest_lists(mesh) -> tuple[list, list]:
    """The rest positions and the edge midpoints of ``mesh`` as nested lists (for Python loops), memoised."""
    def make():
        X, E = mesh.points, mesh.edges
        return X.tolist(), (0.5 * (X[E[:, 0]] + X[E[:, 1]])).tolist()

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
