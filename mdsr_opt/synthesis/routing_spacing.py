"""Parallel twins among routed ropes: a weaker rope that runs beside a stronger one (:func:`parallel_twins`).

The search (:class:`~mdsr_opt.synthesis.routing_search.Router`) starts a unit only from a seed edge farther
than its seed spacing (a length, :data:`~mdsr_opt.synthesis.routing.SEED_SPACING` of the body's diameter)
from the units made before it. That check sees the units as seeds, a few edges long; they then grow. On a
fine mesh the most contracted edges of a bent strip lie in many parallel rows, and a seed a little more than
the spacing from a short first unit grows into a rope beside the grown one along its whole length. The band
routing (:mod:`~mdsr_opt.synthesis.routing_band`) adds more: it pools the ropes of several searches (the one
inside the band, the one on every edge snapped into it, and with ``band="offset+long"`` one at ``K_a = 1``),
which lay the same contraction twice. Each such twin is a muscle that acts where a stronger one already
does, and the fixture fit would keep it (apart by more than a channel and a wall) or its leftover beside
the stronger rope (a short muscle): a finer mesh then gets more, shorter muscles for the same target.

So the spacing holds for the grown ropes too: strongest first, a rope that lies within the spacing of the
ropes kept before it over :data:`TWIN_SHARE` of its rest length or more is a twin of them and is dropped
(said in the routing's ``dropped``). A rope and its own mirror image are never twins (a symmetric layout
keeps its pairs whole); a rope that crosses a stronger one, or meets it at an end, lies beside it over a
short part only and is kept.
"""

from __future__ import annotations

import numpy as np

__all__ = ["TWIN_SHARE", "joined_within", "parallel_twins"]

#: A rope lying within the seed spacing of stronger ropes over at least this share of its rest length is a
#: twin of them (as :func:`~mdsr_opt.synthesis.layouts.shared_layout`'s ``overlap`` for duplicates).
TWIN_SHARE = 0.5


def joined_within(P: np.ndarray, groups, spacing: float) -> np.ndarray:
    """Per group of nodes, the index of the first group it is joined to through groups whose nodes lie closer
    than ``spacing`` (a length) to one another's: the groups' clusters at that distance.

    Example
    -------
    >>> import numpy as np
    >>> P = np.array([[0.0, 0.0], [1.0, 0.0], [1.1, 0.0], [3.0, 0.0]])
    >>> joined_within(P, [[0, 1], [2], [3]], 0.5).tolist()
    [0, 0, 2]
    """
    import shapely

    root = list(range(len(groups)))

    def find(a):
        while root[a] != a:
            root[a] = root[root[a]]
            a = root[a]
        return a

    sizes = [len(g) for g in groups]
    if len(groups) > 1:
        owner = np.repeat(np.arange(len(groups)), sizes)
        pts = shapely.points(P[np.concatenate([np.asarray(g, dtype=np.int64) for g in groups])])
        ask = np.flatnonzero(owner != int(np.argmax(sizes)))  # the largest group's own pairs are never asked
        i, j = shapely.STRtree(pts).query(pts[ask], predicate="dwithin", distance=spacing)
        for a, b in {(int(owner[ask[u]]), int(owner[v])) for u, v in zip(i, j) if owner[ask[u]] != owner[v]}:
            a, b = find(a), find(b)
            root[max(a, b)] = min(a, b)
    return np.array([find(i) for i in range(len(groups))])


def parallel_twins(P: np.ndarray, paths, spacing: float, ids=None, mirror=None) -> dict:
    """The twins among ropes ranked strongest first (module docstring).

    Parameters
    ----------
    P : ndarray, shape (n, 2)
        Rest positions of the nodes.
    paths : sequence of node sequences
        The ropes, strongest first.
    spacing : float
        How near a stronger rope a rope's part lies to count as beside it (a length, > 0).
    ids : sequence of int, optional
        Per rope, its unit id in the search (negative: none).
    mirror : sequence of int, optional
        Per unit id, the id of its mirror image (symmetric routing): a rope is never its mirror image's twin.

    Returns
    -------
    dict of int to str
        Per twin, its index and why it is dropped ("dropped: ...", with the share of its rest length that lies
        beside the ropes kept before it).

    Example
    -------
    >>> import numpy as np
    >>> P = np.array([[x, y] for y in (0.0, 0.1, 1.0) for x in range(5)], float)
    >>> list(parallel_twins(P, [[0, 1, 2, 3, 4], [5, 6, 7, 8, 9], [10, 11, 12, 13, 14]], 0.2))
    [1]
    """
    from shapely.geometry import LineString, MultiLineString

    out, kept = {}, []
    for i, p in enumerate(paths):
        twin = mirror[ids[i]] if mirror and ids[i] >= 0 else None
        others = [P[list(paths[j])] for j in kept if twin is None or ids[j] != twin]
        line = LineString(P[list(p)]) if len(p) >= 2 else None
        if others and line is not None and line.length > 0:
            share = float(line.intersection(MultiLineString(others).buffer(spacing, 16)).length / line.length)
            if share >= TWIN_SHARE:
                out[i] = (f"dropped: {share:.0%} of it lies within {spacing:.4g} of stronger ropes (the seed spacing, "
                          "or a channel and a wall when more): their parallel twin")
                continue
        kept.append(i)
    return out
