"""Work shared between the routings of one body and one target.

:func:`~mdsr_opt.synthesis.routing.route_for_design` routes the same target up to four times (at the
fabrication's clearance, deeper inside, with ``K_a = 1``, and on every contracted edge snapped into the band).
Much of that is the same work: the body's mirror symmetry, the compression-dominated edges, and the search
inside the band at an inset an earlier routing already searched (the band routing pools exactly that search
with its snapped ropes). Inside :func:`shared_work`, :func:`memoised` computes each such piece once and
returns the same object afterwards; outside it, it simply computes. The results are the same either way: the
keys name every input the piece depends on, the mesh (by identity, alive for the whole scope) and the target
included.
"""

from __future__ import annotations

import contextlib
from contextvars import ContextVar
from typing import Callable, Hashable, Iterator, TypeVar

__all__ = ["memoised", "shared_work"]

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
