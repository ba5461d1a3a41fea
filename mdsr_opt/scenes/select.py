"""Node selection on a mesh for problem scripts: boxes, discs, polygons, nearest nodes, edge paths."""

from __future__ import annotations

import math
import numbers

import numpy as np
from numpy.typing import ArrayLike

from ..body.mesh import Mesh
from ..body.muscles import Muscle
from ..core.checks import as_float_array, check_int, positive_float

__all__ = ['nodes_in_box', 'nodes_near', 'nearest_node', 'nodes_in_polygon', 'edge_path', 'edge_graph', 'boundary_path']


# ---------------------------------------------------------------------------------------------- node selection
def nodes_in_box(mesh: Mesh, xmin: float = -math.inf, ymin: float = -math.inf, xmax: float = math.inf,
                 ymax: float = math.inf, boundary: bool = False) -> np.ndarray:
    """Nodes with ``xmin <= x <= xmax`` and ``ymin <= y <= ymax`` (boundary nodes only with ``boundary``).

    A bound is a real number or infinite (no bound on that side); NaN, or a minimum above its maximum, is a
    ``ValueError`` naming it."""
    x0, y0, x1, y1 = (_bound(v, k) for v, k in ((xmin, "xmin"), (ymin, "ymin"), (xmax, "xmax"), (ymax, "ymax")))
    for lo, hi, a in ((x0, x1, "x"), (y0, y1, "y")):
        if lo > hi:
            raise ValueError(f"nodes_in_box: {a}min {lo:g} is above {a}max {hi:g}: the box is empty")
    P = mesh.points
    eps = 1e-9 * mesh.size
    sel = (P[:, 0] >= x0 - eps) & (P[:, 0] <= x1 + eps) & (P[:, 1] >= y0 - eps) & (P[:, 1] <= y1 + eps)
    idx = np.flatnonzero(sel)
    if boundary:
        idx = np.intersect1d(idx, mesh.boundary_nodes)
    return idx.astype(np.int64)


def _bound(value, name: str) -> float:
    """A box bound: a real number, infinite allowed, not NaN (``TypeError``/``ValueError`` naming it)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"nodes_in_box: {name} must be a real number, got {type(value).__name__} {value!r}")
    if math.isnan(float(value)):
        raise ValueError(f"nodes_in_box: {name} is NaN")
    return float(value)


def nodes_near(mesh: Mesh, point: ArrayLike, radius: float, boundary: bool = False) -> np.ndarray:
    """Nodes within ``radius`` (finite, >= 0; ``ValueError`` otherwise) of ``point`` (boundary nodes only with
    ``boundary``)."""
    p = as_float_array(point, "point", shape=(2,))
    radius = positive_float(radius, "nodes_near: radius", allow_zero=True)
    idx = np.flatnonzero(np.linalg.norm(mesh.points - p, axis=1) <= radius)
    if boundary:
        idx = np.intersect1d(idx, mesh.boundary_nodes)
    return idx.astype(np.int64)


def nearest_node(mesh: Mesh, point: ArrayLike, boundary: bool = False, tol: float | None = None) -> int:
    """The node nearest to ``point``; with ``tol``, a ``ValueError`` when it lies farther than ``tol``."""
    p = as_float_array(point, "point", shape=(2,))
    tol = None if tol is None else positive_float(tol, "nearest_node: tol", allow_zero=True)
    cand = mesh.boundary_nodes if boundary else np.arange(mesh.n_nodes)
    d = np.linalg.norm(mesh.points[cand] - p, axis=1)
    k = int(np.argmin(d))
    if tol is not None and d[k] > tol:
        raise ValueError(f"no {'boundary ' if boundary else ''}node within {tol:.3g} of {p.tolist()} "
                         f"(nearest at {d[k]:.3g}): is the point on the body?")
    return int(cand[k])


def nodes_in_polygon(mesh: Mesh, polygon: ArrayLike, boundary: bool = False) -> np.ndarray:
    """Nodes inside (or on) ``polygon``: at least three vertices enclosing an area (a ``ValueError``
    otherwise: fewer vertices, or all on one line)."""
    from matplotlib.path import Path as _MplPath  # geometry only, no plotting

    poly = as_float_array(polygon, "polygon", shape=(None, 2))
    if len(poly) < 3:
        raise ValueError(f"nodes_in_polygon: polygon needs at least 3 vertices, got {len(poly)}")
    d = poly - poly[0]
    far = d[int(np.argmax(np.hypot(d[:, 0], d[:, 1])))]  # the vertex farthest from the first
    if np.abs(far[0] * d[:, 1] - far[1] * d[:, 0]).max() <= 1e-12 * float(far @ far):  # every one on its line
        raise ValueError(f"nodes_in_polygon: the polygon's {len(poly)} vertices lie on one line (or one point): "
                         "it encloses no area")
    inside = _MplPath(poly).contains_points(mesh.points, radius=1e-9 * mesh.size) | \
        _MplPath(poly).contains_points(mesh.points, radius=-1e-9 * mesh.size)
    idx = np.flatnonzero(inside)
    if boundary:
        idx = np.intersect1d(idx, mesh.boundary_nodes)
    return idx.astype(np.int64)


def _snap(mesh: Mesh, p: np.ndarray, boundary: bool, tol: float | None, what: str) -> int:
    """The node nearest ``p``; a ValueError naming ``what`` when it is farther than ``tol`` (default one mean
    edge length)."""
    tol = float(mesh.edge_lengths.mean()) if tol is None else positive_float(tol, "tol", allow_zero=True)
    k = nearest_node(mesh, p, boundary=boundary)
    d = float(np.linalg.norm(mesh.points[k] - p))
    if d > tol:
        raise ValueError(f"{what} {p.tolist()} lies {d:.3g} from the nearest {'boundary ' if boundary else ''}node, "
                         f"more than {tol:.3g} (one mean edge length): is it on the body?")
    return k


def edge_path(mesh: Mesh, waypoints: ArrayLike, name: str | None = None, boundary: bool = False,
              tol: float | None = None) -> Muscle:
    """A muscle through the nodes nearest to ``waypoints``, joined by shortest paths along mesh edges.

    The waypoints are snapped to their nearest nodes (boundary nodes with ``boundary``), each of which must
    lie within ``tol`` (default: one mean edge length) of its waypoint, else a ``ValueError`` names the
    waypoint and the distance; consecutive ones are joined by the edge path that follows the straight segment
    between them: Dijkstra on rest edge lengths, each weighted by ``1 + (d / h)**2`` with ``d`` the distance of
    the edge's midpoint from the segment and ``h`` the mean edge length. The plain shortest path would run
    along a straight outline or hole edge near the drawn line rather than through the zig-zag of interior
    edges on it (a channel on the outline cannot be moulded). Where two joins meet at a waypoint by the same
    edge (a corner waypoint), the rope turns at the node before it. The result must be a simple path.
    """
    import networkx as nx

    if not isinstance(waypoints, (str, bytes)) and np.ndim(waypoints) <= 1:  # node ids, or one point
        given = np.asarray(waypoints)
        ids = given.dtype.kind in "iu"
        raise ValueError(
            "edge_path: waypoints are points (x, y) on the body, one row each, shape (k, 2); got "
            + (f"{given.item()!r}" + (f" (and name={name!r})" if name is not None else "") if given.ndim == 0
               else f"{given.tolist()!r:.60}")
            + (": node ids? give their positions (mesh.points[[i, j]]), or Muscle([...]) for a path of node ids"
               if ids else ": give at least two points, [[x0, y0], [x1, y1]]"))
    wp = as_float_array(waypoints, "waypoints", shape=(None, 2))
    if len(wp) < 2:
        raise ValueError("a muscle path needs at least two waypoints")
    G = edge_graph(mesh)
    ids = [_snap(mesh, p, boundary, tol, f"waypoint {i}") for i, p in enumerate(wp)]
    P, h = mesh.points, float(mesh.edge_lengths.mean())
    path = [ids[0]]
    for a, b in zip(ids[:-1], ids[1:]):
        if a == b:
            continue
        for k in nx.shortest_path(G, a, b, weight=_along(P[a], P[b], P, h))[1:]:
            if len(path) >= 2 and path[-2] == k:  # out to a corner waypoint and back along the same edge: a
                path.pop()                        # rope turns at the node before it (no spike)
            else:
                path.append(k)
    return Muscle(path, name=name)


def _along(pa: np.ndarray, pb: np.ndarray, P: np.ndarray, h: float):
    """:func:`edge_path`'s edge weight between waypoints at ``pa`` and ``pb``: the rest length times ``1 + (d /
    h)**2``, ``d`` the distance of the edge's midpoint (rest positions ``P``) from the segment."""
    u = pb - pa
    uu = max(float(u @ u), 1e-300)

    def weight(i, j, data):
        m = 0.5 * (P[i] + P[j]) - pa
        t = min(max(float(m @ u) / uu, 0.0), 1.0)
        d = m - t * u
        return data["length"] * (1.0 + float(d @ d) / (h * h))

    return weight


def boundary_path(mesh: Mesh, start: ArrayLike, end: ArrayLike, via: ArrayLike | None = None,
                  name: str | None = None, inset: int = 0, tol: float | None = None) -> Muscle:
    """A muscle along a boundary loop from the boundary node nearest ``start`` to the one nearest ``end``.

    ``start`` and ``end`` must lie within ``tol`` (default: one mean edge length) of a boundary node, else a
    ``ValueError`` names the point and the distance. Of the two ways round the loop, the one passing
    nearest ``via`` is taken (default: the shorter one). ``inset`` (an integer >= 0) drops that many nodes at
    each end (a muscle that stops short of a corner); it must leave at least two.
    """
    inset = check_int(inset, "boundary_path: inset", 0)
    a = _snap(mesh, _point(start, "start"), True, tol, "start")
    b = _snap(mesh, _point(end, "end"), True, tol, "end")
    if a == b:
        raise ValueError("start and end snap to the same boundary node")
    for loop in mesh.boundary_loops:
        loop = [int(v) for v in loop]
        if a in loop and b in loop:
            break
    else:
        raise ValueError("start and end lie on different boundary loops")
    i, j = loop.index(a), loop.index(b)
    k = len(loop)
    fwd = [loop[(i + t) % k] for t in range((j - i) % k + 1)]
    bwd = [loop[(i - t) % k] for t in range((i - j) % k + 1)]
    if via is None:
        path = min(fwd, bwd, key=lambda p: Muscle(p).rest_length(mesh))
    else:
        v = _point(via, "via")
        path = min(fwd, bwd, key=lambda p: float(np.linalg.norm(mesh.points[p] - v, axis=1).min()))
    if inset:
        if len(path) - 2 * inset < 2:
            raise ValueError(f"boundary_path: inset {inset} drops every node of the {len(path)}-node path "
                             "(it must leave at least two)")
        path = path[inset:-inset]
    return Muscle(path, name=name)


def _point(value, what: str) -> np.ndarray:
    """``value`` as a point (x, y); a single integer (a node id given for a point) is refused, saying so."""
    if not isinstance(value, (bool, np.bool_)) and np.ndim(value) == 0 and np.asarray(value).dtype.kind in "iu":
        raise ValueError(f"boundary_path: {what} is a point (x, y) near the boundary, got {value!r}: a node id? give "
                         f"its position (mesh.points[{value!r}])")
    return as_float_array(value, what, shape=(2,))


def edge_graph(mesh: Mesh):
    """The rest mesh's edges as a networkx graph (edge attribute ``length``: the rest length), built once
    per mesh (kept on it) for :func:`edge_path`'s shortest paths."""
    import networkx as nx

    G = mesh.__dict__.get("_scene_edge_graph")
    if G is None:
        G = nx.Graph()
        for (i, j), l0 in zip(mesh.edges.tolist(), mesh.edge_lengths.tolist()):
            G.add_edge(i, j, length=l0)
        mesh.__dict__["_scene_edge_graph"] = G
    return G
