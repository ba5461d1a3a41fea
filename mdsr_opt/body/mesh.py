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
import warnings

import numpy as np
from numpy.typing import ArrayLike

from ..core.checks import as_float_array, as_index_array, positive_float, positive_int
from .polygons import (check_polygon, corner_angles, point_inside, polygon_area, ring_segments,
                       segment_contacts, triangle_angles)

__all__ = ["Mesh", "MAX_TRIANGLES", "MAX_RESOLUTION"]

#: Default limit of :meth:`Mesh.from_polygon` on the number of triangles (raise it with ``max_triangles=``).
MAX_TRIANGLES = 2_000_000
#: The largest node count a resolution may ask for (scenes, studies, the command line): the memory of a solve
#: grows about in proportion to the nodes (about 15 kB a node in an IPOPT solve), so 200k
#: nodes need about 3 GB, and a mistyped resolution is refused at once instead of exhausting the memory.
MAX_RESOLUTION = 200_000


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
        duplicate triangles, nodes used by no triangle, or overlapping rest geometry (a boundary that
        crosses or touches itself, or triangles winding more than once around a node).
    """

    __slots__ = ("_points", "_triangles", "_boundary", "__dict__")

    def __init__(self, points: ArrayLike, triangles: ArrayLike):
        p = as_float_array(points, "points", shape=(None, 2))
        t = as_index_array(triangles, "triangles", n=len(p), shape=(None, 3))
        if len(t) == 0:
            raise ValueError("triangles is empty: a mesh needs at least one triangle")
        self._boundary = _validate_topology(p, t)
        self._boundary.setflags(write=False)
        reason = _overlap(p, t, self._boundary, rest=True)
        if reason:
            raise ValueError(f"the rest geometry overlaps itself: {reason}")
        p.setflags(write=False)
        t.setflags(write=False)
        self._points = p
        self._triangles = t

    # ------------------------------------------------------------------ pickling
    def __getstate__(self):
        """What a pickle keeps: the mesh and its derived arrays, without the solvers' caches (``*_cache``:
        CasADi models and sparse factorisations, which neither pickle nor belong to the mesh's data; a copy
        builds them again on first use)."""
        d = {k: v for k, v in self.__dict__.items() if not k.endswith("_cache")}
        return d, {name: getattr(self, name) for name in ("_points", "_triangles", "_boundary")}

    def __setstate__(self, state) -> None:
        d, slots = state
        for name, value in slots.items():
            value.setflags(write=False)  # an unpickled array is writeable again; a mesh's data is not
            object.__setattr__(self, name, value)
        for value in d.values():
            _frozen(value)
        self.__dict__.update(d)

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
        n, key = max(len(self._points), 1), self._edge_keys
        e = np.stack([key // n, key % n], axis=1).astype(self._triangles.dtype)
        e.setflags(write=False)
        return e

    @cached_property
    def _edge_keys(self) -> np.ndarray:
        """One integer per undirected edge, ``i n + j`` with ``i < j``, sorted (so sorts like ``(i, j)``)."""
        t = self._triangles.astype(np.int64)
        a = np.concatenate([t[:, 0], t[:, 1], t[:, 2]])
        b = np.concatenate([t[:, 1], t[:, 2], t[:, 0]])
        return np.unique(np.minimum(a, b) * max(len(self._points), 1) + np.maximum(a, b))

    @cached_property
    def edge_index(self) -> dict[tuple[int, int], int]:
        """Map ``(i, j)`` with ``i < j`` to the row of :attr:`edges` (for many single lookups in Python; see
        :meth:`edge_rows` for arrays)."""
        e = self.edges
        return dict(zip(zip(e[:, 0].tolist(), e[:, 1].tolist()), range(len(e))))

    def edge_rows(self, i: ArrayLike, j: ArrayLike) -> np.ndarray:
        """The rows of :attr:`edges` joining nodes ``i[k]`` and ``j[k]`` (either order), -1 where the two
        are not joined by an edge (or a node is out of range): one binary search per pair, no Python loop."""
        i, j = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
        n, keys = max(len(self._points), 1), self._edge_keys  # a mesh has at least one triangle: keys
        lo, hi = np.minimum(i, j), np.maximum(i, j)
        key = lo * n + hi
        pos = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
        return np.where((lo >= 0) & (hi < n) & (keys[pos] == key), pos, -1)

    def has_edge(self, i: int, j: int) -> bool:
        return bool(self.edge_rows(i, j) >= 0)

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
        return directed[self._boundary]

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
        """Does the body overlap itself in configuration ``x``?

        Elements can all stay upright (``J > 0``) while the body folds through itself; contact is not
        modelled, so such a state is not physical. True when two boundary edges that share no node have a
        point in common (a crossing, also one through a vertex, a vertex touching an edge, or collinear
        edges overlapping), when neighbouring boundary edges fold back onto each other, or when the
        triangles around a boundary node cover more than a full turn. Exact for the floating-point input
        and O(B log B) in the number B of boundary edges (see :func:`segment_contacts`).
        """
        return self.boundary_crossing(x) is not None

    def boundary_crossing(self, x: ArrayLike) -> str | None:
        """Where the body overlaps itself in configuration ``x`` (the nodes or boundary edges, and a point), as
        a sentence; None when it does not (the test of :meth:`boundary_crosses`)."""
        return _overlap(self._check_state(x), self._triangles, self._boundary)

    def _check_state(self, x: ArrayLike, name: str = "x") -> np.ndarray:
        return as_float_array(x, name, shape=(self.n_nodes, 2))

    # ------------------------------------------------------------------ quality
    @_cached
    def angles(self) -> np.ndarray:
        """Interior angles of each triangle in degrees, (m, 3)."""
        return triangle_angles(self._points, self._triangles)

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
                     holes: list[ArrayLike] | None = None, min_angle: float = 30.0, *,
                     max_triangles: int = MAX_TRIANGLES) -> "Mesh":
        """Quality-mesh a simple polygon (with optional polygonal holes) with Shewchuk's Triangle.

        Parameters
        ----------
        outline : array_like, shape (k, 2)
            Vertices of the outer boundary, either orientation.
        max_area : float, optional
            Largest triangle area, in the outline's units squared; default: the polygon's area / 200.
            Honoured at any scale: the polygon is centred and scaled to unit size before meshing, so a
            1 cm body given in metres or a body far from the origin meshes as finely as asked.
        holes : list of array_like, optional
            Polygons strictly inside the outline, neither touching it nor each other, and not nested
            inside one another (a hole inside a hole would be a separate island of material).
        min_angle : float
            Smallest interior angle in degrees, at most 34 (Triangle may not terminate above). Every
            triangle meets it: Triangle leaves a few narrower ones next to input corners narrower than 60
            degrees, and a refinement pass splits them. Every corner of the outline (and every corner of
            the body at a hole) must be at least this wide, since Triangle cannot split an input corner.
        max_triangles : int
            Refuse, before meshing, a request expected to make more triangles than this. The expectation
            adds ``1.6 x area / max_area`` (what Triangle makes where the area bound governs), the
            triangles that thin parts need (a part ``w`` wide needs triangles about ``w`` across: a strip
            of length ``L`` takes about ``2 L / w``, whatever ``max_area``) and a few at each edge shorter
            than ``sqrt(max_area)`` (see :func:`mdsr_opt.body.triangulate.expected_triangles`). Triangle
            is also stopped after adding this many points, so no request can exhaust memory. The default,
            :data:`MAX_TRIANGLES` (2 million), bounds the time (seconds) and memory (about a GB) of
            meshing and validation; pass a larger value to go beyond it.

        Raises
        ------
        ValueError
            A bad outline or hole (see :func:`check_polygon`), holes crossing, touching, outside the
            outline or nested in one another, a corner narrower than ``min_angle``, ``min_angle`` above 34,
            a non-positive ``max_area``, or a request over ``max_triangles`` (the message names the thin
            part that drives the count, its width and place, and the width the limit allows).

        Warns
        -----
        UserWarning
            An angle below ``min_angle`` remains after the repair passes (not seen on fuzzed outlines);
            the message gives the smallest angle and where it is.

        Notes
        -----
        Scale-free: the polygon is centred, scaled to unit size and rounded to 2**-40 of its size before
        Triangle sees it, so a polygon scaled by any factor (with ``max_area`` scaled by its square) meshes
        into the same triangles. The outline's and holes' vertices come back exactly as given.

        Example
        -------
        >>> m = Mesh.from_polygon([[0, 0], [2, 0], [2, 1], [0, 1]], max_area=0.05)
        >>> m.quality()["min_angle_deg"] >= 30.0 - 1e-9
        True
        """
        import shapely

        from .triangulate import (TRIANGLES_PER_AREA, expected_triangles, quality_triangulation,
                                  to_given_coordinates, too_many_triangles, triangle_min_angles)

        outer = check_polygon(outline, "outline")
        hole_polys = [check_polygon(h, f"holes[{i}]") for i, h in enumerate(holes or [])]
        min_angle = positive_float(min_angle, "min_angle")
        if min_angle > 34.0:
            raise ValueError(f"min_angle must be <= 34 degrees for Triangle to terminate, got {min_angle}")
        max_triangles = positive_int(max_triangles, "max_triangles")
        names = ["outline"] + [f"holes[{i}]" for i in range(len(hole_polys))]
        polys = [outer] + hole_polys
        # scale-free coordinates: centred, scaled to unit size and rounded to a grid of 2**-40, so the same
        # polygon at any scale or place gives Triangle the same numbers (and the same mesh)
        lo, hi = outer.min(axis=0), outer.max(axis=0)
        s = float(np.max(hi - lo))
        centre = 0.5 * (lo + hi)
        unit = [np.round((p - centre) / s * 2.0 ** 40) * 2.0 ** -40 for p in polys]
        area = polygon_area(unit[0]) - sum(polygon_area(h) for h in unit[1:])
        if area <= 0.0:
            raise ValueError("the holes cover the whole outline: no material is left to mesh")
        if max_area is None:
            unit_area = float(f"{area / 200.0:.12g}")
            max_area = unit_area * s * s
        else:
            max_area = positive_float(max_area, "max_area")
            unit_area = float(f"{max_area / (s * s):.12g}")  # the same digits at every scale
        expected = max(TRIANGLES_PER_AREA * area / unit_area, float(sum(len(p) for p in polys)))
        if expected > max_triangles:
            raise ValueError(
                f"max_area={max_area:.6g} would make about {expected:.3g} triangles (1.6 x area "
                f"{area * s * s:.6g} / max_area), more than the limit max_triangles={int(max_triangles)}; "
                f"pass a larger max_area, or raise the limit with max_triangles= (Mesh.from_polygon)")
        # the rings may not meet: one segment soup of all of them, tested at once (a ring meeting itself
        # here came within 2**-41 of the outline's size of itself, closer than the grid above resolves)
        ring_of = np.repeat(np.arange(len(unit)), [len(u) for u in unit])
        segs = ring_segments([len(u) for u in unit])
        hit = segment_contacts(np.vstack(unit), segs)
        for i, j in hit:
            a, b = int(ring_of[segs[i, 0]]), int(ring_of[segs[j, 0]])
            if a == b:
                raise ValueError(f"{names[a]} comes within {2.0 ** -41 * s:.3g} (a 2e12th of the outline's "
                                 "size) of itself: too close to mesh; widen the gap")
            if a == 0:
                raise ValueError(f"{names[b]} is not inside the outline: they intersect or touch")
            raise ValueError(f"{names[a]} and {names[b]} intersect or touch")
        if hole_polys:
            rings = [shapely.Polygon(u) for u in unit]
            for i, u in enumerate(unit[1:]):
                if not shapely.contains_xy(rings[0], u[0, 0], u[0, 1]):
                    raise ValueError(f"holes[{i}] is not inside the outline")
            tree = shapely.STRtree(rings[1:])
            first = shapely.points(np.array([u[0] for u in unit[1:]]))
            inner, container = tree.query(first, predicate="within")
            for k in np.flatnonzero(inner != container):
                raise ValueError(
                    f"holes[{int(inner[k])}] lies inside holes[{int(container[k])}]: holes nested in holes "
                    "are not supported (the material between them would be an island not joined to the "
                    "body); mesh that island as a body of its own")
        for r, (name, u) in enumerate(zip(names, unit)):
            ang = corner_angles(u)
            if r > 0:  # the body's angle at a hole corner is the outside of the hole's corner
                ang = 360.0 - ang
            k = int(np.argmin(ang))
            if ang[k] < min_angle - 1e-9:
                v = polys[r][k]
                raise ValueError(
                    f"{name} has a corner of {ang[k]:.4g} degrees at vertex {k} ({v[0]:.6g}, {v[1]:.6g}), "
                    f"narrower than min_angle={min_angle:g}: Triangle cannot split an input corner, so that "
                    f"angle cannot be met; pass min_angle <= {np.floor(ang[k] * 100) / 100:g} or widen the "
                    "corner")
        expected, thin = expected_triangles(unit, unit_area, limit=max_triangles)
        if expected > max_triangles:
            raise ValueError(too_many_triangles(expected, thin, names, s, centre, max_area, max_triangles))
        hole_points = np.array([point_inside(h) for h in unit[1:]]) if hole_polys else None
        v, tri, on_segment, capped = quality_triangulation(np.vstack(unit), segs, hole_points, min_angle, unit_area,
                                               max_steiner=max_triangles)
        if capped or len(tri) > max_triangles:
            made = "stopped at the limit after adding" if capped else "made"
            raise ValueError(f"meshing {made} {len(tri)} triangles, more than the limit "
                             f"max_triangles={int(max_triangles)} (small features or narrow gaps refine the "
                             "mesh beyond the area bound); pass a larger max_area, or raise the limit with "
                             "max_triangles= (Mesh.from_polygon)")
        ang = triangle_min_angles(v, tri)
        if ang.min() < min_angle - 1e-6:
            c = v[tri[int(np.argmin(ang))]].mean(axis=0) * s + centre
            warnings.warn(f"the mesh's smallest angle is {ang.min():.4g} degrees, in the triangle centred at "
                          f"({c[0]:.6g}, {c[1]:.6g}), below min_angle={min_angle:g}", UserWarning, stacklevel=2)
        return cls(*to_given_coordinates(v, tri, on_segment, segs, np.vstack(polys), s, centre))

    @classmethod
    def rectangle(cls, width: float, height: float, nx: int, ny: int,
                  origin: tuple[float, float] = (0.0, 0.0), pattern: str = "alternating") -> "Mesh":
        """A structured mesh of a rectangle with ``nx`` x ``ny`` cells, each split into two triangles.

        ``pattern`` is ``"right"`` (all diagonals alike) or ``"alternating"`` (diagonals alternate, which
        avoids a preferred direction).
        """
        width = positive_float(width, "width")
        height = positive_float(height, "height")
        nx, ny = positive_int(nx, "nx"), positive_int(ny, "ny")
        if pattern not in ("right", "alternating"):
            raise ValueError(f"pattern must be 'right' or 'alternating', got {pattern!r}")
        xs = origin[0] + np.linspace(0.0, width, nx + 1)
        ys = origin[1] + np.linspace(0.0, height, ny + 1)
        X, Y = np.meshgrid(xs, ys)
        pts = np.column_stack([X.ravel(), Y.ravel()])
        i, j = np.meshgrid(np.arange(nx), np.arange(ny))
        i, j = i.ravel(), j.ravel()
        a = j * (nx + 1) + i
        b, c, d = a + 1, a + nx + 2, a + nx + 1
        right = np.ones_like(a, dtype=bool) if pattern == "right" else (i + j) % 2 == 0
        first = np.where(right[:, None], np.column_stack([a, b, c]), np.column_stack([a, b, d]))
        second = np.where(right[:, None], np.column_stack([a, c, d]), np.column_stack([b, c, d]))
        tris = np.stack([first, second], axis=1).reshape(-1, 3)
        return cls(pts, tris.astype(np.int64))


def _validate_topology(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Validate a mesh's triangles; return the boundary mask of :func:`_edge_structure`."""
    n = len(p)
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
    return _edge_structure(t, n)


def _edge_structure(t: np.ndarray, n: int) -> np.ndarray:
    """Check how triangles share edges; return which directed edges ``[t01; t12; t20]`` lie on the boundary.

    One sort of the undirected edge keys finds every problem: an edge in more than two triangles, two
    triangles crossing an edge in the same direction (overlap or duplicate), and boundary nodes where
    separate fans meet (bow-tie).
    """
    directed = np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]).astype(np.int64)
    lo, hi = np.minimum(directed[:, 0], directed[:, 1]), np.maximum(directed[:, 0], directed[:, 1])
    key = lo * n + hi
    order = np.argsort(key, kind="stable")
    k = key[order]
    same = k[1:] == k[:-1]
    if (same[1:] & same[:-1]).any():
        _refuse_duplicates(t)
        e = int(k[1:-1][same[1:] & same[:-1]][0])
        raise ValueError(f"non-manifold mesh: edge {[e // n, e % n]} is shared by more than two triangles")
    twin = np.flatnonzero(same)  # order[twin] and order[twin + 1] are the two sides of an interior edge
    start = directed[:, 0]
    if (start[order[twin]] == start[order[twin + 1]]).any():
        _refuse_duplicates(t)
        raise ValueError("triangles overlap: two triangles traverse an edge in the same direction "
                         "(the mesh folds over)")
    shared = np.zeros(len(key), dtype=bool)
    shared[order[twin]] = True
    shared[order[twin + 1]] = True
    boundary = ~shared
    # boundary vertices must be manifold: at most one outgoing boundary edge each
    out_count = np.bincount(start[boundary], minlength=n)
    if (out_count > 1).any():
        raise ValueError(f"non-manifold mesh: node {int(np.argmax(out_count > 1))} joins separate fans "
                         "of triangles (bow-tie)")
    return boundary


def _refuse_duplicates(t: np.ndarray) -> None:
    """Raise if the same three nodes form more than one triangle (checked on the error path only)."""
    _, counts = np.unique(np.sort(t, axis=1), axis=0, return_counts=True)
    if (counts > 1).any():
        raise ValueError("duplicate triangles: the same three nodes appear in more than one triangle")


def _overlap(x: np.ndarray, t: np.ndarray, boundary: np.ndarray, rest: bool = False) -> str | None:
    """Why the triangles ``t`` at positions ``x`` overlap each other, or None.

    ``boundary`` marks the boundary among the directed edges ``[t01; t12; t20]``. Tested: the triangles
    around a boundary node turning through more than 360 degrees, (at ``rest``) around an interior node
    through a multiple of 360 other than one, and the boundary edges meeting anywhere but at shared nodes.
    """
    n = len(x)
    directed = np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    on_bnd = np.zeros(n, dtype=bool)
    on_bnd[directed[boundary, 0]] = True
    # signed corner angles; their sum around a node is how far its fan of triangles turns. Only the boundary
    # nodes' sums are tested unless at rest: then only the triangles with a boundary node are needed (a
    # tenth of them at 3k nodes)
    tt = t if rest else t[on_bnd[t].any(axis=1)]
    X = x[tt]
    turn = np.zeros(n)
    for k in range(3):
        u, v = X[:, (k + 1) % 3] - X[:, k], X[:, (k + 2) % 3] - X[:, k]
        ang = np.arctan2(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0], np.einsum("ij,ij->i", u, v))
        turn += np.bincount(tt[:, k], weights=ang, minlength=n)
    over = on_bnd & (turn > 2 * np.pi * (1 + 1e-12))
    if rest:
        over |= ~on_bnd & (np.abs(turn - 2 * np.pi) > 0.5)
    if over.any():
        v = int(np.argmax(over))
        return (f"the triangles around node {v} at ({x[v, 0]:.6g}, {x[v, 1]:.6g}) turn through "
                f"{np.degrees(turn[v]):.1f} degrees, more than a full turn")
    E = directed[boundary]
    hit = segment_contacts(x, E)
    if len(hit):
        i, j = (int(v) for v in hit[0])
        return (f"boundary edges {E[i].tolist()} and {E[j].tolist()} meet near ({x[E[i, 0], 0]:.6g}, "
                f"{x[E[i, 0], 1]:.6g}) where they share no node (the boundary crosses or touches itself)")
    return None
