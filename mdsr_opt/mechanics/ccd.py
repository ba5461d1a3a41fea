"""Node-segment proximity of a body's boundary: the broad phase over a step's swept boxes and continuous
collision detection (the time of impact), for the barrier contact of :mod:`~mdsr_opt.mechanics.barrier`.

A step moves every node on a straight line, ``x(t) = x0 + t (x1 - x0)``, ``t`` in ``[0, 1]``. In the plane
the boundary of an upright body first crosses itself where a boundary node meets a boundary segment that
does not end at it (two segments cannot cross without one's end passing through the other), so node-segment
pairs suffice. For such a pair ``p``, ``(a, b)`` the node lies on the segment's line where
``c(t) = (b - a) x (p - a)`` vanishes: ``c`` is a quadratic in ``t`` (its coefficients from the moves), and
a root ``t`` in ``[0, 1]`` is an impact when ``p``'s projection parameter on ``(a, b)`` there lies in
``[0, 1]``, widened by :data:`S_EPS` for rounding at the segment's ends (:func:`time_of_impact`).

The broad phase (:func:`swept_pairs`) bounds each node's path and each segment's sweep by a circle
(the segment's: about the mean of its ends' four positions, through the farthest) and keeps the pairs whose
circles, grown by a pad, overlap: a k-d tree of the items that move about as much as most (their radii at
most four times the median), the few that move more against all.

Example
-------
>>> import numpy as np
>>> x0 = np.array([[0.5, 1.0], [0.0, 0.0], [1.0, 0.0]])     # node 0 above the segment (1, 2)
>>> x1 = x0 + [[0.0, -2.0], [0.0, 0.0], [0.0, 0.0]]         # node 0 moved through it
>>> float(time_of_impact(x0, x1, np.array([[0, 1, 2]]))[0])
0.5
"""

from __future__ import annotations

import numpy as np

__all__ = ["swept_pairs", "time_of_impact", "earliest_impact", "S_EPS"]

#: a root counts as an impact when the projection parameter ``s`` there lies in ``[-S_EPS, 1 + S_EPS]``: a node
#: passing exactly through a segment's end (a shared boundary vertex) has ``s`` 0 or 1 only up to rounding
#: (measured: just outside ``[0, 1]`` for 359 of 6,645 random motions through a vertex); a node passing within
#: ``S_EPS`` of a segment's length beyond its end is reported as an impact, which only shortens a step
S_EPS = 1e-9


def _cross(u, v):
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _circles(X0, X1, nodes, segs):
    """Bounding circles ``(centre, radius)`` of the nodes' paths and of the segments' sweeps."""
    P0, P1 = X0[nodes], X1[nodes]
    nc = 0.5 * (P0 + P1)
    nr = 0.5 * np.linalg.norm(P1 - P0, axis=1)
    S = np.stack([X0[segs[:, 0]], X0[segs[:, 1]], X1[segs[:, 0]], X1[segs[:, 1]]])  # (4, s, 2)
    sc = S.mean(axis=0)
    sr = np.linalg.norm(S - sc, axis=2).max(axis=0)
    return nc, nr, sc, sr


def swept_pairs(X0, X1, nodes, segs, pad: float) -> np.ndarray:
    """Candidate node-segment pairs of the step from ``X0`` to ``X1`` (both (n, 2)).

    Parameters
    ----------
    X0, X1 : (n, 2) arrays
        Node positions at the step's start and end (the same array for one state).
    nodes : (k,) int array
        The boundary nodes.
    segs : (s, 2) int array
        The boundary segments (node pairs).
    pad : float
        The distance within which a pair counts (``dhat`` for the barrier, any small positive value for
        collision detection).

    Returns
    -------
    (N, 3) int array
        Rows ``(p, a, b)``: every pair of a node ``p`` and a segment ``(a, b)`` not ending at it that come
        within ``pad`` of each other at some point of the step (and possibly others, not farther apart than
        the sum of their bounding circles' radii plus ``pad``), each once, sorted.
    """
    from scipy.spatial import cKDTree  # here: `mdsr run`'s own process leaves scipy.spatial to its jobs

    nodes = np.asarray(nodes, dtype=np.int64)
    segs = np.asarray(segs, dtype=np.int64).reshape(-1, 2)
    if not len(nodes) or not len(segs):
        return np.zeros((0, 3), dtype=np.int64)
    nc, nr, sc, sr = _circles(np.asarray(X0, dtype=float), np.asarray(X1, dtype=float), nodes, segs)
    big_n = nr > 4.0 * np.median(nr) + 1e-300
    big_s = sr > 4.0 * np.median(sr) + 1e-300
    found_i, found_j = [], []
    sn, ss = np.flatnonzero(~big_n), np.flatnonzero(~big_s)
    if len(sn) and len(ss):
        reach = float(nr[sn].max() + sr[ss].max() + pad)
        ij = cKDTree(nc[sn]).sparse_distance_matrix(cKDTree(sc[ss]), reach, output_type="ndarray")
        found_i.append(sn[ij["i"].astype(np.int64)])
        found_j.append(ss[ij["j"].astype(np.int64)])
    for bi in np.flatnonzero(big_n):  # the few that move far: against every segment
        found_i.append(np.full(len(segs), bi))
        found_j.append(np.arange(len(segs)))
    for bj in np.flatnonzero(big_s):
        found_i.append(np.arange(len(nodes)))
        found_j.append(np.full(len(nodes), bj))
    if not found_i:
        return np.zeros((0, 3), dtype=np.int64)
    i, j = np.concatenate(found_i), np.concatenate(found_j)
    near = np.linalg.norm(nc[i] - sc[j], axis=1) <= nr[i] + sr[j] + pad
    p, a, b = nodes[i[near]], segs[j[near], 0], segs[j[near], 1]
    keep = (p != a) & (p != b)
    out = np.unique(np.stack([p[keep], a[keep], b[keep]], axis=1), axis=0)
    return out.reshape(-1, 3)


def _roots01(A, B, C):
    """The real roots in ``[0, 1]`` of ``A t^2 + B t + C`` per row: ``(t1, t2)`` (NaN where none; for a
    linear or constant row the one root in ``t1``)."""
    scale = np.maximum(np.maximum(np.abs(A), np.abs(B)), np.abs(C))
    scale = np.where(scale > 0, scale, 1.0)
    quad = np.abs(A) > 1e-12 * scale
    t1 = np.full(A.shape, np.nan)
    t2 = np.full(A.shape, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = B * B - 4.0 * A * C
        sq = np.sqrt(np.maximum(disc, 0.0))
        q = -0.5 * (B + np.where(B >= 0, sq, -sq))  # the stable pair of roots: q / A and C / q
        r1 = np.where(quad & (disc >= -1e-14 * B * B), q / A, np.nan)
        r2 = np.where(quad & (disc >= -1e-14 * B * B), C / np.where(q != 0, q, np.nan), np.nan)
        lin = ~quad & (np.abs(B) > 1e-14 * scale)
        r1 = np.where(lin, -C / B, r1)
    for r, out in ((r1, t1), (r2, t2)):
        ok = (r >= 0.0) & (r <= 1.0)
        out[ok] = r[ok]
    return t1, t2


def time_of_impact(X0, X1, pairs) -> np.ndarray:
    """The earliest ``t`` in ``[0, 1]`` at which each pair's node lies on its segment along the straight step
    from ``X0`` to ``X1``; ``inf`` where it does not.

    Parameters
    ----------
    X0, X1 : (n, 2) arrays
        Node positions at the step's start and end.
    pairs : (N, 3) int array
        Rows ``(p, a, b)``.

    Returns
    -------
    (N,) float array
        The time of impact of each pair (a node moving along its segment's line through it: the first of 33
        even samples of ``t`` at which it is on the segment, rounded down).
    """
    X0, X1 = np.asarray(X0, dtype=float), np.asarray(X1, dtype=float)
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 3)
    if not len(pairs):
        return np.zeros(0)
    p, a, b = pairs.T
    e0, w0 = X0[b] - X0[a], X0[p] - X0[a]
    de, dw = (X1[b] - X1[a]) - e0, (X1[p] - X1[a]) - w0
    A = _cross(de, dw)
    B = _cross(e0, dw) + _cross(de, w0)
    C = _cross(e0, w0)
    toi = np.full(len(pairs), np.inf)
    for t in _roots01(A, B, C):
        tt = np.where(np.isfinite(t), t, 0.0)[:, None]
        e, w = e0 + tt * de, w0 + tt * dw
        s = np.einsum("ij,ij->i", w, e) / np.maximum(np.einsum("ij,ij->i", e, e), 1e-300)
        hit = np.isfinite(t) & (s >= -S_EPS) & (s <= 1.0 + S_EPS)
        toi = np.where(hit, np.minimum(toi, np.where(np.isfinite(t), t, np.inf)), toi)
    scale = np.maximum(np.abs(A) + np.abs(B) + np.abs(C), 1e-300)
    size = np.einsum("ij,ij->i", e0, e0) + np.einsum("ij,ij->i", w0, w0) + np.einsum("ij,ij->i", dw, dw)
    flat = np.flatnonzero(scale <= 1e-14 * np.maximum(size, 1e-300))  # on the segment's line throughout
    for k in flat:
        for t in np.linspace(0.0, 1.0, 33):
            e, w = e0[k] + t * de[k], w0[k] + t * dw[k]
            s = float(w @ e) / max(float(e @ e), 1e-300)
            if 0.0 <= s <= 1.0:
                toi[k] = min(toi[k], max(t - 1.0 / 32, 0.0))
                break
    return toi


def earliest_impact(X0, X1, nodes, segs) -> float:
    """The earliest time of impact of any boundary node with any boundary segment along the straight step
    from ``X0`` to ``X1`` (``inf`` when none): :func:`swept_pairs` then :func:`time_of_impact`."""
    pairs = swept_pairs(X0, X1, nodes, segs, 0.0)
    toi = time_of_impact(X0, X1, pairs)
    return float(toi.min()) if len(toi) else np.inf
