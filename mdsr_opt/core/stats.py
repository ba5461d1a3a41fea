"""Small statistics shared by studies and charts: log-log slopes and Pareto fronts."""

from __future__ import annotations

import math
from typing import Callable, Sequence
import numpy as np

__all__ = ['fit_slopes', 'pareto_front']


def fit_slopes(rows: Sequence[dict], time_of: Callable[[dict], float] | None = None) -> dict:
    """Least-squares fit ``log10(time) = a + b log10(nodes)`` per method over its successful runs.

    Returns ``{method: (slope b, intercept a, number of runs)}`` for methods whose successful runs span node
    counts at least a factor 2 apart (closer ones give no meaningful slope). ``time_of`` defaults to build
    plus solve time.
    """
    time_of = time_of or (lambda r: r["build_time"] + r["solve_time"])
    out = {}
    for m in dict.fromkeys(r["method"] for r in rows):
        pts = [(r["nodes"], time_of(r)) for r in rows if r["method"] == m and r["success"] and time_of(r) > 0]
        nodes = {p[0] for p in pts}
        if not nodes or max(nodes) < 2 * min(nodes):
            continue
        x, y = np.log10(np.array(pts, dtype=float)).T
        b, a = np.polyfit(x, y, 1)
        out[m] = (float(b), float(a), len(pts))
    return out


def pareto_front(times: Sequence[float], errors: Sequence[float]) -> np.ndarray:
    """Indices of the points not dominated in (time, error), sorted by time: each is more accurate than every
    faster point."""
    t = np.asarray(times, dtype=float)
    e = np.asarray(errors, dtype=float)
    ok = np.flatnonzero(np.isfinite(t) & np.isfinite(e))
    order = ok[np.lexsort((e[ok], t[ok]))]
    front, best = [], math.inf
    for i in order:
        if e[i] < best:
            front.append(i)
            best = e[i]
    return np.array(front, dtype=np.int64)
