"""Rigid obstacles a body may touch but not enter: a ground half-plane, disks and convex polygons.

Each obstacle gives, for a body node at ``x``, the gap function the contact solve keeps non-negative
(:mod:`mdsr_opt.mechanics.contact`):

- :class:`HalfPlane` ``(point q, normal n)``: ``g = n . (x - q)`` (``n`` normalised, pointing into the free side);
- :class:`Disk` ``(center c, radius r)``: ``g = |x - c| - r``; and the disk is kept out of each boundary segment
  near it by the gap between its centre and the segment (a disk has no corners; without it a segment between two
  nodes outside the disk could cut through it);
- :class:`Obstacle` ``(polygon)``, convex: ``g = max_e n_e . (x - a_e)`` over its edges (outward normals),
  posed as the line of the edge that attains the maximum at the start of each solve (refreshed until it no
  longer changes); its corners are kept out of the body by the same gap between each corner and the body's
  boundary segments near it.

A non-convex obstacle is given as several convex ones.

Example
-------
>>> import numpy as np
>>> from mdsr_opt import HalfPlane, Disk, Obstacle
>>> ground = HalfPlane((0.0, 0.0), (0.0, 2.0))
>>> float(ground.gap(np.array([[1.0, 0.5]]))[0])
0.5
>>> float(Disk((0.0, 0.0), 1.0).gap(np.array([[3.0, 0.0]]))[0])
2.0
>>> float(Obstacle([(0, 0), (1, 0), (1, 1), (0, 1)]).gap(np.array([[2.0, 0.5]]))[0])
1.0
"""

from __future__ import annotations

import numpy as np

from ..core.checks import as_float_array

__all__ = ["HalfPlane", "Disk", "Obstacle", "check_obstacles", "check_prescribed"]


def _point(value, name) -> np.ndarray:
    return as_float_array(value, name, shape=(2,)).astype(float)


class HalfPlane:
    """The region ``n . (x - point) < 0`` is solid (e.g. the ground, ``HalfPlane((0, 0), (0, 1))``).

    Parameters
    ----------
    point : (2,) a point on the boundary line.
    normal : (2,) non-zero, pointing into the free side (normalised here).
    """

    kind = "half-plane"

    def __init__(self, point, normal):
        self.point = _point(point, "HalfPlane point")
        n = _point(normal, "HalfPlane normal")
        ln = float(np.hypot(*n))
        if ln == 0.0:
            raise ValueError("HalfPlane normal must be non-zero")
        self.normal = n / ln

    def __repr__(self) -> str:
        return f"HalfPlane(point={self.point.tolist()}, normal={self.normal.tolist()})"

    def gap(self, x) -> np.ndarray:
        """The gap of each point of ``x`` (k, 2): its signed distance from the line."""
        return (np.asarray(x, dtype=float) - self.point) @ self.normal

    def scaled(self, scale: float, shift) -> "HalfPlane":
        """The same obstacle for coordinates ``scale * (x - shift)``."""
        return HalfPlane(scale * (self.point - shift), self.normal)

    def edges(self) -> np.ndarray:
        """The supporting line as one fixed segment ``(a, b)`` with its free side on the right: (1, 2, 2)."""
        n = self.normal
        return np.array([[self.point, self.point + np.array([-n[1], n[0]])]])

    def corners(self) -> np.ndarray:
        return np.zeros((0, 2))

    def to_dict(self) -> dict:
        return {"type": "HalfPlane", "point": self.point.tolist(), "normal": self.normal.tolist()}


class Disk:
    """A solid disk ``|x - center| < radius``."""

    kind = "disk"

    def __init__(self, center, radius):
        self.center = _point(center, "Disk center")
        if isinstance(radius, bool) or not isinstance(radius, (int, float, np.integer, np.floating)) or \
                not np.isfinite(radius) or radius <= 0:
            raise ValueError(f"Disk radius must be a positive number, got {radius!r}")
        self.radius = float(radius)

    def __repr__(self) -> str:
        return f"Disk(center={self.center.tolist()}, radius={self.radius:g})"

    def gap(self, x) -> np.ndarray:
        return np.linalg.norm(np.asarray(x, dtype=float) - self.center, axis=1) - self.radius

    @property
    def inner_point(self) -> np.ndarray:
        """A point of the obstacle that must never be inside the body (its centre)."""
        return self.center

    def segment_gap(self, a, b) -> np.ndarray:
        """The gap of each segment ``(a[i], b[i])`` ((k, 2) each): its distance from the centre less the radius
        (negative where the segment cuts into the disk)."""
        a, b = np.asarray(a, dtype=float).reshape(-1, 2), np.asarray(b, dtype=float).reshape(-1, 2)
        d = b - a
        t = np.clip(((self.center - a) * d).sum(1) / np.maximum((d * d).sum(1), 1e-300), 0.0, 1.0)
        return np.linalg.norm(a + t[:, None] * d - self.center, axis=1) - self.radius

    def scaled(self, scale: float, shift) -> "Disk":
        return Disk(scale * (self.center - shift), scale * self.radius)

    def corners(self) -> np.ndarray:
        return np.zeros((0, 2))

    def to_dict(self) -> dict:
        return {"type": "Disk", "center": self.center.tolist(), "radius": self.radius}


class Obstacle:
    """A solid convex polygon (vertices in either order; stored counter-clockwise)."""

    kind = "polygon"

    def __init__(self, polygon):
        P = as_float_array(polygon, "Obstacle polygon", shape=(None, 2)).astype(float)
        if len(P) < 3:
            raise ValueError(f"Obstacle polygon needs at least 3 vertices, got {len(P)}")
        area = 0.5 * float(np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1]))
        if area == 0.0:
            raise ValueError("Obstacle polygon has zero area")
        if area < 0:
            P = P[::-1].copy()
        d = np.roll(P, -1, axis=0) - P
        cross = d[:, 0] * np.roll(d, -1, axis=0)[:, 1] - d[:, 1] * np.roll(d, -1, axis=0)[:, 0]
        if np.any(cross < -1e-12 * float(np.abs(P).max() + 1.0) ** 2) or np.any(np.hypot(*d.T) == 0):
            raise ValueError("Obstacle polygon must be convex with distinct vertices (give a non-convex obstacle "
                             "as several convex ones)")
        self.polygon = P

    def __repr__(self) -> str:
        return f"Obstacle(polygon={self.polygon.tolist()})"

    def edges(self) -> np.ndarray:
        """Edges ``(a, b)`` (m, 2, 2), counter-clockwise: the free side on the right of each."""
        return np.stack([self.polygon, np.roll(self.polygon, -1, axis=0)], axis=1)

    def gap(self, x) -> np.ndarray:
        """``max_e n_e . (x - a_e)``: the signed distance outside, a lower bound of it near the corners."""
        return self.edge_gaps(x).max(axis=1)

    def edge_gaps(self, x) -> np.ndarray:
        """``n_e . (x - a_e)`` of each point (k,) and edge (m,): (k, m)."""
        E = self.edges()
        d = E[:, 1] - E[:, 0]
        n = np.column_stack([d[:, 1], -d[:, 0]]) / np.hypot(*d.T)[:, None]
        x = np.asarray(x, dtype=float)
        return np.einsum("kmi,mi->km", x[:, None, :] - E[None, :, 0], n)

    @property
    def inner_point(self) -> np.ndarray:
        """A point of the obstacle that must never be inside the body (its vertices' mean)."""
        return self.polygon.mean(axis=0)

    def scaled(self, scale: float, shift) -> "Obstacle":
        return Obstacle(scale * (self.polygon - shift))

    def corners(self) -> np.ndarray:
        return self.polygon.copy()

    def to_dict(self) -> dict:
        return {"type": "Obstacle", "polygon": self.polygon.tolist()}


def check_obstacles(obstacles, mesh=None) -> list:
    """``obstacles`` as a list (None: empty), each a :class:`HalfPlane`, :class:`Disk` or :class:`Obstacle`;
    with ``mesh``, none may hold a node of the body at rest (a ValueError names the first)."""
    if obstacles is None:
        return []
    if isinstance(obstacles, (HalfPlane, Disk, Obstacle)):
        obstacles = [obstacles]
    try:
        obs = list(obstacles)
    except TypeError:
        raise TypeError(f"obstacles must be a list of HalfPlane, Disk or Obstacle, got {type(obstacles).__name__}") \
            from None
    for i, o in enumerate(obs):
        if not isinstance(o, (HalfPlane, Disk, Obstacle)):
            raise TypeError(f"obstacles[{i}] must be a HalfPlane, Disk or Obstacle, got {type(o).__name__}")
    if mesh is not None:
        for i, o in enumerate(obs):
            g = o.gap(mesh.points)
            if g.min() < 0:
                k = int(np.argmin(g))
                raise ValueError(f"obstacles[{i}] ({o!r}) holds node {k} of the body at rest (gap {g[k]:.3g}): "
                                 "place the obstacle outside the body")
    return obs


#: the load fractions at which :func:`check_prescribed` looks at the prescribed nodes' path
PATH_FRACTIONS = np.linspace(0.0, 1.0, 65)


def check_prescribed(obstacles, nodes, positions, tolerance: float, what: str = "dragged") -> None:
    """Refuse prescribed nodes that would have to enter a rigid obstacle: a node held at a place inside one
    (deeper than ``tolerance``, the contact's gap) can never be reached, and a solve asked to would stall.

    Parameters
    ----------
    obstacles : list of :class:`HalfPlane`, :class:`Disk`, :class:`Obstacle` (as :func:`check_obstacles`
        gives).
    nodes : (k,) node numbers of the prescribed nodes.
    positions : callable ``s -> (k, 2)``, their positions at load fraction ``s`` in [0, 1] (a drag's path),
        or a fixed (k, 2) array.
    tolerance : the penetration allowed (length units), the contact gap.
    what : how the nodes are prescribed, for the message (``"dragged"``, ``"anchored"``).

    Raises
    ------
    ValueError
        Naming the first such node, the obstacle, the penetration depth and the load fraction at which the
        path first enters it (its target when only that is inside).
    """
    nodes = np.asarray(nodes, dtype=np.int64).reshape(-1)
    if not len(obstacles) or not len(nodes):
        return
    fixed = not callable(positions)
    # the target first (its depth is what the user must change), then the path to it
    for s in (1.0,) if fixed else (1.0, *PATH_FRACTIONS[:-1]):
        x = np.asarray(positions if fixed else positions(float(s)), dtype=float).reshape(-1, 2)
        for i, o in enumerate(obstacles):
            g = o.gap(x)
            if g.min() < -tolerance:
                j = int(np.argmin(g))
                final = np.asarray(positions if fixed else positions(1.0), dtype=float).reshape(-1, 2)
                where = "its target" if s == 1.0 else f"{s:.0%} of the way along its drag (target " \
                    f"({final[j, 0]:.4g}, {final[j, 1]:.4g}))"
                raise ValueError(
                    f"node {int(nodes[j])} is {what} to ({x[j, 0]:.4g}, {x[j, 1]:.4g}), {-g[j]:.3g} deep inside "
                    f"obstacles[{i}] ({o!r}) at {where}: a prescribed node cannot enter a rigid obstacle (more than "
                    f"the contact gap {tolerance:.3g}), so the solve could never reach it; move the {what} nodes' "
                    "target or path outside the obstacle")
