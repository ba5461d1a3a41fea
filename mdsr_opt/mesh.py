"""The immutable triangle mesh of a planar soft body, meshing of polygons, and quality checks.

A :class:`Mesh` holds rest nodes ``points`` (n, 2) and counter-clockwise ``triangles`` (m, 3).
Everything else (edges, boundary, element matrices, quality) is derived on first use and cached.
Construction validates the mesh: every problem is a ``ValueError``/``TypeError`` naming it.

Example
-------
>>> from mdsr_opt import Mesh
>>> mesh = Mesh.rectangle(4.0, 1.0, nx=8, ny=2)
>>> mesh.n_nodes, mesh.n_triangles
(27, 32)
"""

from __future__ import annotations

from functools import cached_property, wraps

import numpy as np
from numpy.typing import ArrayLike

from ._checks import as_float_array, as_index_array, positive_float

__all__ = ["Mesh", "polygon_area", "check_polygon"]


def _frozen(value):
    """Make cached arrays (or lists of them) read-only so callers cannot corrupt a mesh's derived data."""
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
    elif isinstance(value, list):
        for v in value:
            _frozen(v)
    return value


def _cached(fn):
    """``cached_property`` whose array result is read-only."""
    @wraps(fn)
    def compute(self):
        return _frozen(fn(self))

    return cached_property(compute)


def polygon_area(poly: np.ndarray) -> float:
    """Signed area of a closed polygon (positive when counter-clockwise)."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _segments_intersect(a0, a1, b0, b1) -> np.ndarray:
    """Vectorised proper-or-touching intersection test of segment sets a (k,2) and b (l,2)."""
    def orient(p, q, r):
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

    A0, A1 = a0[:, None, :], a1[:, None, :]
    B0, B1 = b0[None, :, :], b1[None, :, :]
    d1 = orient(B0, B1, A0)
    d2 = orient(B0, B1, A1)
    d3 = orient(A0, A1, B0)
    d4 = orient(A0, A1, B1)
    scale = max(np.ptp(np.vstack([a0, a1, b0, b1]), axis=0).max(), 1e-300)
    eps = 1e-12 * scale * scale
    proper = (((d1 > eps) & (d2 < -eps)) | ((d1 < -eps) & (d2 > eps))) & \
             (((d3 > eps) & (d4 < -eps)) | ((d3 < -eps) & (d4 > eps)))

    def on_seg(p, q, r, d):  # r collinear with p-q and within its box
        return (np.abs(d) <= eps) & (np.minimum(p[..., 0], q[..., 0]) - 1e-12 * scale <= r[..., 0]) & \
            (r[..., 0] <= np.maximum(p[..., 0], q[..., 0]) + 1e-12 * scale) & \
            (np.minimum(p[..., 1], q[..., 1]) - 1e-12 * scale <= r[..., 1]) & \
            (r[..., 1] <= np.maximum(p[..., 1], q[..., 1]) + 1e-12 * scale)

    touch = on_seg(B0, B1, A0, d1) | on_seg(B0, B1, A1, d2) | on_seg(A0, A1, B0, d3) | on_seg(A0, A1, B1, d4)
    return proper | touch


def check_polygon(poly: ArrayLike, name: str = "outline") -> np.ndarray:
    """Validate a simple polygon (k, 2); return it counter-clockwise without a repeated closing point.

    Raises ``ValueError`` for fewer than 3 vertices, repeated vertices, zero area or self-intersection.
    """
    p = as_float_array(poly, name, shape=(None, 2))
    if len(p) >= 2 and np.allclose(p[0], p[-1]):
        p = p[:-1]
    if len(p) < 3:
        raise ValueError(f"{name} needs at least 3 distinct vertices, got {len(p)}")
    scale = float(np.ptp(p, axis=0).max())
    if scale == 0.0:
        raise ValueError(f"{name} is degenerate: all vertices coincide")
    seg = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
    if np.any(seg <= 1e-12 * scale):
        i = int(np.argmin(seg))
        raise ValueError(f"{name} is degenerate: vertices {i} and {(i + 1) % len(p)} coincide")
    k = len(p)
    a0, a1 = p, np.roll(p, -1, axis=0)
    hit = _segments_intersect(a0, a1, a0, a1)
    idx = np.arange(k)
    adjacent = (np.abs(idx[:, None] - idx[None, :]) <= 1) | (np.abs(idx[:, None] - idx[None, :]) == k - 1)
    hit &= ~adjacent
    if k == 3:
        hit[:] = False
    if hit.any():
        i, j = np.argwhere(hit)[0]
        raise ValueError(f"{name} is self-intersecting: edge {i} crosses edge {j}")
    area = polygon_area(p)
    if abs(area) <= 1e-12 * scale * scale:
        raise ValueError(f"{name} is degenerate: zero area")
    return p if area > 0 else p[::-1].copy()


def _point_inside(poly: np.ndarray) -> np.ndarray:
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


def _point_in_polygon(pt: np.ndarray, poly: np.ndarray) -> bool:
    x, y = pt
    inside = False
    j = len(poly) - 1
    for i in range(len(poly)):
        xi, yi = poly[i]
        xj, yj = poly[j]
        if (yi > y) != (yj > y) and x < (xj - xi) * (y - yi) / (yj - yi) + xi:
            inside = not inside
        j = i
    return inside


class Mesh:
    """An immutable planar triangle mesh.

    Parameters
    ----------
    points : array_like, shape (n, 2)
        Rest coordinates of the nodes.
    triangles : array_like of int, shape (m, 3)
        Node indices of each triangle, counter-clockwise.

    Raises
    ------
    TypeError
        Non-numeric points or non-integer triangles.
    ValueError
        NaN/inf, indices out of range, repeated nodes in a triangle, zero-area or inverted
        (clockwise) triangles, mixed orientation (fold-over), non-manifold edges or vertices,
        duplicate triangles, or nodes used by no triangle.
    """

    __slots__ = ("_points", "_triangles", "__dict__")

    def __init__(self, points: ArrayLike, triangles: ArrayLike):
        p = as_float_array(points, "points", shape=(None, 2))
        t = as_index_array(triangles, "triangles", n=len(p), shape=(None, 3))
        if len(t) == 0:
            raise ValueError("triangles is empty: a mesh needs at least one triangle")
        _validate_topology(p, t)
        p.setflags(write=False)
        t.setflags(write=False)
        self._points = p
        self._triangles = t

    # ------------------------------------------------------------------ basic data
    @property
    def points(self) -> np.ndarray:
        """Rest node coordinates, (n, 2), read-only."""
        return self._points

    @property
    def triangles(self) -> np.ndarray:
        """Counter-clockwise triangles, (m, 3), read-only."""
        return self._triangles

    @property
    def n_nodes(self) -> int:
        return len(self._points)

    @property
    def n_triangles(self) -> int:
        return len(self._triangles)

    def __repr__(self) -> str:
        return f"Mesh(n_nodes={self.n_nodes}, n_triangles={self.n_triangles})"

    @property
    def size(self) -> float:
        """Characteristic size: the diagonal of the rest bounding box."""
        return float(np.linalg.norm(np.ptp(self._points, axis=0)))

    # ------------------------------------------------------------------ derived topology
    @cached_property
    def edges(self) -> np.ndarray:
        """Unique undirected edges (k, 2) with ``i < j``, sorted lexicographically."""
        t = self._triangles
        e = np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
        e = np.sort(e, axis=1)
        e = np.unique(e, axis=0)
        e.setflags(write=False)
        return e

    @cached_property
    def edge_index(self) -> dict[tuple[int, int], int]:
        """Map ``(i, j)`` with ``i < j`` to the row of :attr:`edges`."""
        return {(int(a), int(b)): k for k, (a, b) in enumerate(self.edges)}

    def has_edge(self, i: int, j: int) -> bool:
        return (min(i, j), max(i, j)) in self.edge_index

    @_cached
    def edge_lengths(self) -> np.ndarray:
        """Rest lengths of :attr:`edges`."""
        e = self.edges
        return np.linalg.norm(self._points[e[:, 1]] - self._points[e[:, 0]], axis=1)

    @_cached
    def boundary_edges(self) -> np.ndarray:
        """Directed boundary edges (b, 2), oriented with the body on their left."""
        t = self._triangles
        directed = np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
        keys = set(map(tuple, directed.tolist()))
        mask = np.array([(b, a) not in keys for a, b in directed.tolist()])
        return directed[mask]

    @_cached
    def boundary_nodes(self) -> np.ndarray:
        """Sorted indices of the nodes on the boundary."""
        return np.unique(self.boundary_edges)

    @_cached
    def boundary_loops(self) -> list[np.ndarray]:
        """Ordered boundary loops; the first is the outer one (counter-clockwise), then holes (clockwise)."""
        nxt = {int(a): int(b) for a, b in self.boundary_edges}
        loops, seen = [], set()
        for start in sorted(nxt):
            if start in seen:
                continue
            loop, v = [], start
            while v not in seen:
                seen.add(v)
                loop.append(v)
                v = nxt[v]
            loops.append(np.array(loop, dtype=np.int64))
        loops.sort(key=lambda lp: -abs(polygon_area(self._points[lp])))
        return loops

    @_cached
    def neighbors(self) -> list[np.ndarray]:
        """Sorted neighbour node indices of each node along mesh edges."""
        nb: list[list[int]] = [[] for _ in range(self.n_nodes)]
        for a, b in self.edges.tolist():
            nb[a].append(b)
            nb[b].append(a)
        return [np.array(sorted(x), dtype=np.int64) for x in nb]

    # ------------------------------------------------------------------ element geometry
    @_cached
    def Dm(self) -> np.ndarray:
        """Rest edge matrices ``[X1-X0, X2-X0]`` as columns, (m, 2, 2)."""
        X = self._points[self._triangles]
        return np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]], axis=2)

    @_cached
    def Dm_inv(self) -> np.ndarray:
        """Inverse rest edge matrices, (m, 2, 2)."""
        return np.linalg.inv(self.Dm)

    @_cached
    def areas(self) -> np.ndarray:
        """Rest triangle areas, (m,)."""
        return 0.5 * np.linalg.det(self.Dm)

    @property
    def area(self) -> float:
        return float(self.areas.sum())

    def deformation_gradients(self, x: ArrayLike) -> np.ndarray:
        """Deformation gradient ``F = Ds Dm^-1`` of each triangle for deformed nodes ``x`` (n, 2)."""
        x = self._check_state(x)
        Y = x[self._triangles]
        Ds = np.stack([Y[:, 1] - Y[:, 0], Y[:, 2] - Y[:, 0]], axis=2)
        return Ds @ self.Dm_inv

    def jacobians(self, x: ArrayLike) -> np.ndarray:
        """``J = det F`` of each triangle; ``J <= 0`` marks an inverted element."""
        return np.linalg.det(self.deformation_gradients(x))

    def boundary_crosses(self, x: ArrayLike) -> bool:
        """Does the boundary cross itself in configuration ``x`` (the body overlapping itself)?

        Elements can all stay upright (``J > 0``) while the body folds through itself; contact is not
        modelled, so such a state is not physical. Every pair of boundary edges sharing no node is tested.
        """
        x = self._check_state(x)
        E = np.vstack([np.column_stack([lp, np.roll(lp, -1)]) for lp in self.boundary_loops])
        a, b = x[E[:, 0]], x[E[:, 1]]

        def orient(p, q, r):
            return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

        for i0 in range(0, len(E), 512):
            sl = slice(i0, i0 + 512)
            A0, A1 = a[sl, None, :], b[sl, None, :]
            B0, B1 = a[None, :, :], b[None, :, :]
            cross = (orient(B0, B1, A0) * orient(B0, B1, A1) < 0) & (orient(A0, A1, B0) * orient(A0, A1, B1) < 0)
            shared = (E[sl, None, 0] == E[None, :, 0]) | (E[sl, None, 0] == E[None, :, 1]) | \
                (E[sl, None, 1] == E[None, :, 0]) | (E[sl, None, 1] == E[None, :, 1])
            if np.any(cross & ~shared):
                return True
        return False

    def _check_state(self, x: ArrayLike, name: str = "x") -> np.ndarray:
        return as_float_array(x, name, shape=(self.n_nodes, 2))

    # ------------------------------------------------------------------ quality
    @_cached
    def angles(self) -> np.ndarray:
        """Interior angles of each triangle in degrees, (m, 3)."""
        X = self._points[self._triangles]
        out = np.empty((self.n_triangles, 3))
        for k in range(3):
            a = X[:, (k + 1) % 3] - X[:, k]
            b = X[:, (k + 2) % 3] - X[:, k]
            cos = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
            out[:, k] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        return out

    def quality(self) -> dict[str, float]:
        """Quality figures: min/max angle (deg), max aspect ratio (longest edge / shortest altitude),
        min and max area, mean edge length."""
        X = self._points[self._triangles]
        L = np.stack([np.linalg.norm(X[:, (k + 1) % 3] - X[:, k], axis=1) for k in range(3)], axis=1)
        alt = 2 * self.areas / L.max(axis=1)
        return {
            "n_nodes": self.n_nodes,
            "n_triangles": self.n_triangles,
            "min_angle_deg": float(self.angles.min()),
            "max_angle_deg": float(self.angles.max()),
            "max_aspect_ratio": float((L.max(axis=1) / alt).max()),
            "min_area": float(self.areas.min()),
            "max_area": float(self.areas.max()),
            "mean_edge_length": float(self.edge_lengths.mean()),
        }

    # ------------------------------------------------------------------ copies
    def with_points(self, points: ArrayLike) -> "Mesh":
        """A new mesh with the same triangles and new rest points (validated again)."""
        return Mesh(points, self._triangles)

    def relabel(self, perm: ArrayLike) -> "Mesh":
        """The same mesh with node ``i`` renamed ``perm[i]`` (``perm`` a permutation of range(n))."""
        perm = as_index_array(perm, "perm", n=self.n_nodes, shape=(self.n_nodes,))
        if len(np.unique(perm)) != self.n_nodes:
            raise ValueError("perm is not a permutation of the node indices")
        pts = np.empty_like(self._points)
        pts[perm] = self._points
        return Mesh(pts, perm[self._triangles])

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_polygon(cls, outline: ArrayLike, max_area: float | None = None,
                     holes: list[ArrayLike] | None = None, min_angle: float = 30.0) -> "Mesh":
        """Quality-mesh a simple polygon (with optional polygonal holes) with Shewchuk's Triangle.

        Parameters
        ----------
        outline : (k, 2) vertices of the outer boundary, either orientation.
        max_area : largest triangle area; default: the polygon's area / 200.
        holes : list of (k_i, 2) polygons strictly inside the outline, not touching each other.
        min_angle : smallest interior angle in degrees (Triangle guarantees up to about 33).

        Example
        -------
        >>> m = Mesh.from_polygon([[0, 0], [2, 0], [2, 1], [0, 1]], max_area=0.05)
        >>> m.quality()["min_angle_deg"] >= 30.0 - 1e-9
        True
        """
        import triangle as tr

        outer = check_polygon(outline, "outline")
        hole_polys = [check_polygon(h, f"holes[{i}]") for i, h in enumerate(holes or [])]
        area = polygon_area(outer)
        if max_area is None:
            max_area = area / 200.0
        max_area = positive_float(max_area, "max_area")
        min_angle = positive_float(min_angle, "min_angle")
        if min_angle > 34.0:
            raise ValueError(f"min_angle must be <= 34 degrees for Triangle to terminate, got {min_angle}")
        polys = [outer] + hole_polys
        for i, h in enumerate(hole_polys):
            if not all(_point_in_polygon(v, outer) for v in h):
                raise ValueError(f"holes[{i}] is not inside the outline")
        for i in range(len(polys)):
            for j in range(i + 1, len(polys)):
                a, b = polys[i], polys[j]
                if _segments_intersect(a, np.roll(a, -1, 0), b, np.roll(b, -1, 0)).any():
                    what = "outline" if i == 0 else f"holes[{i - 1}]"
                    raise ValueError(f"{what} and holes[{j - 1}] intersect")
        verts, segs, offset = [], [], 0
        for poly in polys:
            k = len(poly)
            verts.append(poly)
            segs.append(np.column_stack([np.arange(k), (np.arange(k) + 1) % k]) + offset)
            offset += k
        data = {"vertices": np.vstack(verts), "segments": np.vstack(segs)}
        if hole_polys:
            data["holes"] = np.array([_point_inside(h) for h in hole_polys])
        out = tr.triangulate(data, f"pq{min_angle:.6g}a{max_area:.17g}Q")
        pts = np.asarray(out["vertices"], dtype=float)
        tri = np.asarray(out["triangles"], dtype=np.int64)
        used = np.unique(tri)
        if len(used) != len(pts):  # drop vertices left outside (never expected with 'p')
            remap = -np.ones(len(pts), dtype=np.int64)
            remap[used] = np.arange(len(used))
            pts, tri = pts[used], remap[tri]
        d1, d2 = pts[tri[:, 1]] - pts[tri[:, 0]], pts[tri[:, 2]] - pts[tri[:, 0]]
        cw = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0] < 0
        tri[cw] = tri[cw][:, ::-1]
        return cls(pts, tri)

    @classmethod
    def rectangle(cls, width: float, height: float, nx: int, ny: int,
                  origin: tuple[float, float] = (0.0, 0.0), pattern: str = "alternating") -> "Mesh":
        """A structured mesh of a rectangle with ``nx`` x ``ny`` cells, each split into two triangles.

        ``pattern`` is ``"right"`` (all diagonals alike) or ``"alternating"`` (diagonals alternate, which
        avoids a preferred direction).
        """
        width = positive_float(width, "width")
        height = positive_float(height, "height")
        for v, nm in ((nx, "nx"), (ny, "ny")):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{nm} must be a positive integer, got {v!r}")
        if pattern not in ("right", "alternating"):
            raise ValueError(f"pattern must be 'right' or 'alternating', got {pattern!r}")
        xs = origin[0] + np.linspace(0.0, width, nx + 1)
        ys = origin[1] + np.linspace(0.0, height, ny + 1)
        X, Y = np.meshgrid(xs, ys)
        pts = np.column_stack([X.ravel(), Y.ravel()])
        tris = []
        for j in range(ny):
            for i in range(nx):
                a = j * (nx + 1) + i
                b, c, d = a + 1, a + nx + 2, a + nx + 1
                if pattern == "right" or (i + j) % 2 == 0:
                    tris += [(a, b, c), (a, c, d)]
                else:
                    tris += [(a, b, d), (b, c, d)]
        return cls(pts, np.array(tris, dtype=np.int64))


def _validate_topology(p: np.ndarray, t: np.ndarray) -> None:
    n, m = len(p), len(t)
    rep = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2])
    if rep.any():
        k = int(np.argmax(rep))
        raise ValueError(f"triangle {k} repeats a node: {t[k].tolist()}")
    used = np.zeros(n, dtype=bool)
    used[t.ravel()] = True
    if not used.all():
        raise ValueError(f"{int((~used).sum())} node(s) belong to no triangle (first: {int(np.argmin(used))}); "
                         "remove unused nodes")
    X = p[t]
    d1, d2 = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    lmax = np.max(np.stack([np.linalg.norm(d1, axis=1), np.linalg.norm(d2, axis=1),
                            np.linalg.norm(X[:, 2] - X[:, 1], axis=1)]), axis=0)
    degenerate = np.abs(det) <= 1e-10 * lmax ** 2
    if degenerate.any():
        k = int(np.argmax(degenerate))
        raise ValueError(f"triangle {k} {t[k].tolist()} is degenerate (zero area)")
    neg = det < 0
    if neg.all():
        raise ValueError("all triangles are clockwise (inverted); pass triangles[:, ::-1] for "
                         "counter-clockwise order")
    if neg.any():
        k = int(np.argmax(neg))
        raise ValueError(f"mixed orientation: triangle {k} {t[k].tolist()} is clockwise (inverted) while "
                         f"others are counter-clockwise; the mesh folds over")
    sorted_t = np.sort(t, axis=1)
    _, counts = np.unique(sorted_t, axis=0, return_counts=True)
    if (counts > 1).any():
        raise ValueError("duplicate triangles: the same three nodes appear in more than one triangle")
    directed = np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    _, dcount = np.unique(directed, axis=0, return_counts=True)
    undirected, ucount = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    if (ucount > 2).any():
        e = undirected[int(np.argmax(ucount > 2))]
        raise ValueError(f"non-manifold mesh: edge {e.tolist()} is shared by more than two triangles")
    if (dcount > 1).any():
        raise ValueError("triangles overlap: two triangles traverse an edge in the same direction "
                         "(the mesh folds over)")
    # boundary vertices must be manifold: at most one outgoing boundary edge each
    keys = set(map(tuple, directed.tolist()))
    bnd = np.array([a for a, b in directed.tolist() if (b, a) not in keys], dtype=np.int64)
    if len(bnd):
        _, bc = np.unique(bnd, return_counts=True)
        if (bc > 1).any():
            v = np.unique(bnd)[int(np.argmax(bc > 1))]
            raise ValueError(f"non-manifold mesh: node {int(v)} joins separate fans of triangles (bow-tie)")
