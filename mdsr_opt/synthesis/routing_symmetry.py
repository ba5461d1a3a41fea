"""Mirror symmetry of a mesh and of a contraction field, for symmetric muscle routing.

:func:`find_reflection` looks for a reflection that maps the rest mesh onto itself (node for node, edge
for edge). :func:`~mdsr_opt.routing.route_muscles` uses it: when the body is mirror-symmetric and the
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
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ..body.checks import check_mesh
from ..body.mesh import Mesh

__all__ = ["Reflection", "find_reflection", "find_reflections", "weights_are_symmetric"]

if TYPE_CHECKING:  # pragma: no cover
    from scipy.spatial import cKDTree


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


def _try_axis(mesh: Mesh, tree: cKDTree, c: np.ndarray, d: np.ndarray, tol: float) -> Reflection | None:
    X = mesh.points
    R = 2.0 * np.outer(d, d) - np.eye(2)
    Y = (X - c) @ R.T + c
    dist, idx = tree.query(Y)
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
    # imported here: scipy.spatial takes 0.25 s to import, and unpickling a routing result (a figure job
    # does, in a jobs' server that has not routed) should not need it
    from scipy.spatial import cKDTree

    tree = cKDTree(X)
    tol = rtol * mesh.size
    out = []
    for d in dirs:
        r = _try_axis(mesh, tree, c, d / np.linalg.norm(d), tol)
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
