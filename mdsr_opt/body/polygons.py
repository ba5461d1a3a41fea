"""Planar polygons and segment sets: signed area, validation of simple polygons, exact contact tests.

These are the geometric tests behind :meth:`mdsr_opt.Mesh.from_polygon` (outline and holes) and
:meth:`mdsr_opt.Mesh.boundary_crosses` (a body overlapping itself). Contacts between segments are found in
O(B log B) with a bounding-box tree and decided with GEOS's exact-sign predicates (through shapely), so a
crossing through a vertex, a touching vertex and collinear overlapping edges are all found.

Example
-------
>>> from mdsr_opt.body.polygons import check_polygon, polygon_area
>>> polygon_area(check_polygon([[0, 0], [0, 1], [2, 1], [2, 0]]))  # clockwise in, counter-clockwise out
2.0
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..core.checks import as_float_array

__all__ = ["polygon_area", "segment_contacts", "ring_segments", "check_polygon", "corner_angles",
           "point_inside", "triangle_angles"]


def polygon_area(poly: np.ndarray) -> float:
    """Signed area of a closed polygon (positive when counter-clockwise).

    The vertices are taken relative to their mean first, so a small polygon far from the origin keeps its
    area to full precision (the shoelace sum of raw coordinates cancels catastrophically there).
    """
    p = np.asarray(poly, dtype=float)
    p = p - p.mean(axis=0)
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def segment_contacts(points: ArrayLike, segments: ArrayLike) -> np.ndarray:
    """Pairs of segments of a segment soup that meet where they should not, in O(B log B).

    Parameters
    ----------
    points : (n, 2) coordinates.
    segments : (B, 2) node indices of each segment (a polyline or the loops of a boundary).

    Returns
    -------
    numpy.ndarray of int, shape (k, 2)
        Rows ``(i, j)`` with ``i < j``: segments that share no node but have a point in common (a proper
        crossing, a crossing through a vertex, a vertex touching a segment, two vertices at the same
        place, or collinear segments overlapping), and segments that share a node but overlap along a
        length (an edge folded back onto its neighbour). Empty when the segments form simple curves that
        meet only at their shared nodes.

    Notes
    -----
    Candidate pairs come from a bounding-box tree (GEOS STRtree through shapely) and are tested with
    GEOS's robust (exact-sign) orientation predicates, so touching and collinear cases are decided
    exactly for the floating-point input, not within a tolerance.
    """
    import shapely

    P = np.asarray(points, dtype=float)
    E = np.asarray(segments, dtype=np.int64)
    if len(E) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    segs = shapely.linestrings(np.stack([P[E[:, 0]], P[E[:, 1]]], axis=1))
    i, j = shapely.STRtree(segs).query(segs, predicate="intersects")
    keep = i < j
    i, j = i[keep], j[keep]
    Ei, Ej = E[i], E[j]
    share = (Ei[:, 0] == Ej[:, 0]) | (Ei[:, 0] == Ej[:, 1]) | (Ei[:, 1] == Ej[:, 0]) | (Ei[:, 1] == Ej[:, 1])
    bad = ~share
    # neighbours meet at their shared node; they are bad only if their interiors overlap, which needs the
    # three points to be collinear: a floating-point orientation beyond Shewchuk's error bound rules that
    # out, and the few pairs left are decided exactly by GEOS
    s = np.flatnonzero(share)
    a0, a1, b0, b1 = P[Ei[s, 0]], P[Ei[s, 1]], P[Ej[s, 0]], P[Ej[s, 1]]
    far = np.where(((Ej[s, 0] == Ei[s, 0]) | (Ej[s, 0] == Ei[s, 1]))[:, None], b1, b0)
    left = (a1[:, 0] - a0[:, 0]) * (far[:, 1] - a0[:, 1])
    right = (a1[:, 1] - a0[:, 1]) * (far[:, 0] - a0[:, 0])
    s = s[np.abs(left - right) <= 4e-16 * (np.abs(left) + np.abs(right))]
    if len(s):
        bad[s] = shapely.relate_pattern(segs[i[s]], segs[j[s]], "1********")
    out = np.column_stack([i[bad], j[bad]]).astype(np.int64)
    return out[np.lexsort((out[:, 1], out[:, 0]))]


def ring_segments(sizes: list[int]) -> np.ndarray:
    """Segments (node pairs) of closed rings stored one after another with the given vertex counts."""
    segs, offset = [], 0
    for k in sizes:
        idx = np.arange(k) + offset
        segs.append(np.column_stack([idx, np.roll(idx, -1)]))
        offset += k
    return np.vstack(segs)


def check_polygon(poly: ArrayLike, name: str = "outline") -> np.ndarray:
    """Validate a simple polygon (k, 2); return it counter-clockwise without a repeated closing point.

    Raises ``ValueError`` for fewer than 3 vertices, repeated vertices, zero area or self-intersection
    (a crossing, a vertex touching another edge, or collinear edges overlapping), decided exactly in
    O(k log k) by :func:`segment_contacts`.
    """
    p = as_float_array(poly, name, shape=(None, 2))
    if len(p) >= 3 and np.abs(p[0] - p[-1]).max() <= 1e-12 * float(np.ptp(p, axis=0).max()):
        p = p[:-1]  # a repeated closing point (to rounding)
    if len(p) < 3:
        raise ValueError(f"{name} needs at least 3 distinct vertices, got {len(p)}")
    scale = float(np.ptp(p, axis=0).max())
    if scale == 0.0:
        raise ValueError(f"{name} is degenerate: all vertices coincide")
    seg = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
    if np.any(seg <= 1e-12 * scale):
        i = int(np.argmin(seg))
        raise ValueError(f"{name} is degenerate: vertices {i} and {(i + 1) % len(p)} coincide")
    d = p - p[0]
    if np.linalg.matrix_rank(d, tol=1e-12 * scale) < 2:
        raise ValueError(f"{name} is degenerate: zero area (all vertices lie on one line)")
    hit = segment_contacts(p, ring_segments([len(p)]))
    if len(hit):
        i, j = (int(v) for v in hit[0])
        raise ValueError(f"{name} is self-intersecting: edge {i} (vertices {i}-{(i + 1) % len(p)}) meets "
                         f"edge {j} (vertices {j}-{(j + 1) % len(p)})")
    area = polygon_area(p)
    if abs(area) <= 1e-12 * scale * scale:
        raise ValueError(f"{name} is degenerate: zero area")
    return p if area > 0 else p[::-1].copy()


def corner_angles(poly: np.ndarray) -> np.ndarray:
    """Interior angle (degrees, in (0, 360)) at each vertex of a counter-clockwise polygon (k, 2)."""
    p = np.asarray(poly, dtype=float)
    to_prev, to_next = np.roll(p, 1, axis=0) - p, np.roll(p, -1, axis=0) - p
    cross = to_next[:, 0] * to_prev[:, 1] - to_next[:, 1] * to_prev[:, 0]
    return np.degrees(np.arctan2(cross, np.einsum("ij,ij->i", to_next, to_prev))) % 360.0


def point_inside(poly: np.ndarray) -> np.ndarray:
    """A point strictly inside a simple polygon (centroid of its largest ear triangle)."""
    import triangle as tr

    k = len(poly)
    seg = np.column_stack([np.arange(k), (np.arange(k) + 1) % k])
    t = tr.triangulate({"vertices": poly, "segments": seg}, "pQ")
    tri = t["triangles"]
    v = t["vertices"]
    d1, d2 = v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]]
    areas = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    return v[tri[int(np.argmax(areas))]].mean(axis=0)


def triangle_angles(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The interior angles of each triangle, in degrees, (m, 3): the one at each of its corners."""
    X = vertices[triangles]
    out = np.empty((len(triangles), 3))
    for k in range(3):
        a = X[:, (k + 1) % 3] - X[:, k]
        b = X[:, (k + 2) % 3] - X[:, k]
        cos = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        out[:, k] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return out
