"""Mirror symmetry of a mesh and of a contraction field, for symmetric muscle routing.

:func:`find_reflection` looks for a reflection that maps the rest mesh onto itself (node for node, edge
for edge). :func:`~mdsr_opt.synthesis.routing.route_muscles` uses it: when the body is mirror-symmetric and the
target contracts mirrored edges alike, the muscles are routed in mirrored pairs (or as single muscles
that are their own mirror image), so a symmetric target gets symmetric muscles.

The candidate axes pass through the centroid of the rest nodes along the two principal axes of the node
cloud, so the test does not depend on how the body is placed or rotated. A body whose node cloud is
isotropic (a square, a disc) has no principal axes; there the axes through the centroid and each of the
first boundary nodes are tried as well.

Example
-------
>>> from mdsr_opt import Mesh
>>> mesh = Mesh.rectangle(4.0, 1.0, nx=16, ny=4)      # alternating diagonals: mirror-symmetric
>>> r = find_reflection(mesh)
>>> r is not None and r.node_map.shape == (mesh.n_nodes,)
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..body.checks import check_mesh
from ..body.mesh import Mesh

__all__ = ["Reflection", "find_reflection", "find_reflections", "nearest_within", "weights_are_symmetric"]

@dataclass(frozen=True, eq=False)
class Reflection:
    """A reflection that maps a mesh onto itself.

    Attributes
    ----------
    point, direction : (2,) ndarrays
        A point on the mirror axis and the axis' unit direction.
    node_map : (n,) int ndarray
        ``node_map[i]`` is the node at the mirror image of node ``i`` (an involution).
    edge_map : (k,) int ndarray
        ``edge_map[e]`` is the row of ``mesh.edges`` that is the mirror image of edge ``e``.
    """

    point: np.ndarray
    direction: np.ndarray
    node_map: np.ndarray
    edge_map: np.ndarray

    def apply(self, x: ArrayLike) -> np.ndarray:
        """Mirror points ``x`` (m, 2) about the axis."""
        x = np.asarray(x, dtype=float)
        d = self.direction
        R = 2.0 * np.outer(d, d) - np.eye(2)
        return (x - self.point) @ R.T + self.point


def nearest_within(X: np.ndarray, Y: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """For each point of ``Y`` the nearest point of ``X`` among those within ``tol`` (>= 0) of it:
    ``(dist, idx)``, with ``dist = inf`` and ``idx = -1`` where none is; of equally near points, the lower
    index. ``X`` (n, 2) finite, ``Y`` (m, 2) (a query that is not finite matches nothing).

    A hash of ``X`` on a grid of square cells at least ``tol`` wide (``2 tol``, or 1e-8 of the points'
    span if larger): a point within ``tol`` of a query lies in one of the 3 x 3 cells around the query's.
    Where a query has a match this is a k-d tree's nearest neighbour, without importing ``scipy.spatial``
    on the path of every symmetric body's routing.
    """
    X, Y = np.asarray(X, dtype=float), np.asarray(Y, dtype=float)
    for name, P in (("X", X), ("Y", Y)):
        if P.ndim != 2 or P.shape[1] != 2:
            raise ValueError(f"{name} must have shape (n, 2), got {P.shape}")
    if not np.isfinite(X).all():
        raise ValueError("X must be finite")
    tol = float(tol)
    if not tol >= 0:
        raise ValueError(f"tol must be >= 0, got {tol}")
    dist, idx = np.full(len(Y), np.inf), np.full(len(Y), -1, dtype=np.int64)
    if not len(X) or not len(Y):
        return dist, idx
    # the cells of points far beyond any body are found on coordinates scaled down (so that the span stays
    # finite); the distances are always measured on the points themselves
    big = float(np.abs(X).max())
    scale = 2.0 ** -int(np.frexp(big)[1]) if big > 1e150 else 1.0
    Xs = X * scale
    lo = Xs.min(axis=0)
    cell = max(2.0 * tol * scale, 1e-8 * float(np.ptp(Xs, axis=0).max())) or 1.0
    kx = np.floor((Xs - lo) / cell).astype(np.int64)  # at most 1e8 per axis: keys fit in int64
    top = kx.max(axis=0)
    with np.errstate(over="ignore", invalid="ignore"):  # a query far off (or not finite) matches nothing
        ky = np.floor((Y * scale - lo) / cell)
    near = np.all(np.isfinite(ky) & (ky >= -1) & (ky <= top + 1), axis=1)
    ky = np.where(near[:, None], ky, -2).astype(np.int64)
    rows = int(top[1]) + 1
    keys = kx[:, 0] * rows + kx[:, 1]
    order = np.argsort(keys, kind="stable")
    skeys = keys[order]
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            cy = ky[:, 1] + dy
            q = np.where(near & (cy >= 0) & (cy < rows), (ky[:, 0] + dx) * rows + cy, -1)
            first, last = np.searchsorted(skeys, q, "left"), np.searchsorted(skeys, q, "right")
            for r in range(int((last - first).max())):  # the points sharing a cell (one, for a mesh's nodes)
                hit = first + r < last
                j = order[np.minimum(first + r, len(skeys) - 1)]
                e = Y - X[j]
                d = np.where(hit, np.hypot(e[:, 0], e[:, 1]), np.inf)
                better = (d <= tol) & ((d < dist) | ((d == dist) & (j < idx)))
                dist[better], idx[better] = d[better], j[better]
    return dist, idx


def _try_axis(mesh: Mesh, c: np.ndarray, d: np.ndarray, tol: float) -> Reflection | None:
    X = mesh.points
    R = 2.0 * np.outer(d, d) - np.eye(2)
    Y = (X - c) @ R.T + c
    # 64 nodes spread over the mesh first: on a body with no such mirror one of them mostly has no image (each
    # query's answer is its own, so this is the whole test's answer for them)
    probe = np.unique(np.linspace(0, len(X) - 1, min(len(X), 64)).astype(np.int64))
    if not np.all(nearest_within(X, Y[probe], tol)[0] <= tol):
        return None
    dist, idx = nearest_within(X, Y, tol)
    if not np.all(dist <= tol):
        return None
    if not np.array_equal(idx[idx], np.arange(len(X))):
        return None
    E = mesh.edges
    ei = mesh.edge_index
    try:
        em = np.array([ei[(a, b) if a < b else (b, a)] for a, b in zip(idx[E[:, 0]].tolist(), idx[E[:, 1]].tolist())])
    except KeyError:
        return None
    return Reflection(point=c.copy(), direction=d.copy(), node_map=idx.astype(np.int64), edge_map=em.astype(np.int64))


def find_reflections(mesh: Mesh, rtol: float = 1e-6) -> list[Reflection]:
    """Every candidate reflection that maps ``mesh`` onto itself (at most one per candidate axis).

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    rtol : float, default 1e-6
        Node positions must match their mirror images within ``rtol * mesh.size``.

    Returns
    -------
    list of Reflection
        Empty when no candidate axis maps every node onto a node and every edge onto an edge. A body with
        two mirror axes (a rectangle) gives both, the principal axis of larger variance first.
    """
    mesh = check_mesh(mesh)
    X = mesh.points
    c = X.mean(axis=0)
    C = np.cov((X - c).T)
    evals, evecs = np.linalg.eigh(C)
    dirs = [evecs[:, 1], evecs[:, 0]]
    if abs(evals[1] - evals[0]) <= 1e-9 * max(evals[1], 1e-300):
        for b in mesh.boundary_nodes[:8].tolist():
            v = X[b] - c
            nv = np.linalg.norm(v)
            if nv > 0:
                dirs.append(v / nv)
    tol = rtol * mesh.size
    out = []
    for d in dirs:
        r = _try_axis(mesh, c, d / np.linalg.norm(d), tol)
        if r is not None and not any(np.array_equal(r.node_map, o.node_map) for o in out):
            out.append(r)
    return out


def find_reflection(mesh: Mesh, rtol: float = 1e-6) -> Reflection | None:
    """The first reflection of :func:`find_reflections`, or ``None``."""
    found = find_reflections(mesh, rtol)
    return found[0] if found else None


def weights_are_symmetric(w: np.ndarray, reflection: Reflection, rtol: float = 1e-6) -> bool:
    """True when mirrored edges have the same weight within ``rtol * max|w|``."""
    w = np.asarray(w, dtype=float)
    scale = float(np.abs(w).max()) if len(w) else 0.0
    return bool(np.all(np.abs(w - w[reflection.edge_map]) <= rtol * max(scale, 1e-300)))
