"""Drags for external driving: straight moves to given positions, or rigid motions along a path.

A drag moves some nodes from their rest positions to prescribed ones as the load fraction ``s`` goes
from 0 to 1; the other nodes settle. Two kinds, which may be mixed in one list:

- a straight move ``{node: (x, y)}`` (or the pair ``(indices, positions (k, 2))``): at load ``s`` a node
  is at ``X + s (x - X)``;
- a :class:`RigidDrag`: the nodes rotate rigidly through ``angle`` (radians, counter-clockwise) about
  ``center`` and translate by ``shift``; at load ``s`` a node is at ``c + R(s angle) (X - c) + s shift``, so
  load stepping follows the arc (a strip's end can curl through 180 degrees, where straight
  interpolation would pass the end through the body).

Example
-------
>>> import numpy as np
>>> from mdsr_opt import Mesh
>>> mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
>>> end = np.flatnonzero(mesh.points[:, 0] == 4.0)
>>> path = drag_path([RigidDrag(end, np.pi / 2, (4.0, 0.0))], mesh)
>>> np.round(path.positions(1.0)[-1], 6)  # the top right corner (4, 1) turned a quarter about (4, 0)
array([3., 0.])
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..core.checks import as_float_array, node_indices

__all__ = ["RigidDrag", "DragPath", "drag_path"]

_FORMS = ("drags must be a dict {node: (x, y)}, a pair (node indices, positions (k, 2)), a RigidDrag, or a "
          "list of dicts and RigidDrags")


@dataclass(frozen=True)
class RigidDrag:
    """Drag ``nodes`` rigidly: rotate them through ``angle`` about ``center``, then translate by ``shift``.

    Parameters
    ----------
    nodes : sequence of int
        Node indices moved together.
    angle : float
        Rotation angle in radians (counter-clockwise positive); any size, e.g. ``np.pi`` for a half turn.
    center : (2,) float
        Centre of the rotation, in the rest frame.
    shift : (2,) float
        Translation added after the rotation (default none). At load ``s`` a node at rest position ``X`` is
        at ``center + R(s * angle) (X - center) + s * shift``.
    """

    nodes: tuple
    angle: float
    center: tuple
    shift: tuple = (0.0, 0.0)

    def __post_init__(self):
        nodes = tuple(int(i) for i in node_indices(self.nodes, "RigidDrag nodes"))
        if not nodes:
            raise ValueError("RigidDrag needs at least one node")
        a = self.angle
        if isinstance(a, bool) or not isinstance(a, (int, float, np.integer, np.floating)) or not np.isfinite(a):
            raise ValueError(f"RigidDrag angle must be a finite number (radians), got {a!r}")
        c = as_float_array(self.center, "RigidDrag center", shape=(2,))
        t = as_float_array(self.shift, "RigidDrag shift", shape=(2,))
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "angle", float(a))
        object.__setattr__(self, "center", (float(c[0]), float(c[1])))
        object.__setattr__(self, "shift", (float(t[0]), float(t[1])))

    def positions(self, rest: np.ndarray, s: float) -> np.ndarray:
        """Positions at load fraction ``s`` of nodes whose rest positions are ``rest`` (k, 2)."""
        th = s * self.angle
        R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        c = np.asarray(self.center)
        return c + (rest - c) @ R.T + s * np.asarray(self.shift)


@dataclass
class DragPath:
    """The dragged nodes and their positions along the load path (see :func:`drag_path`)."""

    nodes: np.ndarray  # (k,) int
    rest: np.ndarray  # (k, 2)
    parts: list  # (slice into nodes, RigidDrag or (k_i, 2) final positions)

    @property
    def final(self) -> np.ndarray:
        """Positions at load 1."""
        return self.positions(1.0)

    def positions(self, s: float) -> np.ndarray:
        """(k, 2) positions at load fraction ``s`` in [0, 1]."""
        out = np.empty_like(self.rest)
        for sl, how in self.parts:
            X = self.rest[sl]
            out[sl] = how.positions(X, s) if isinstance(how, RigidDrag) else X + s * (how - X)
        return out


def _is_scalar_int(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool)


def _looks_like_pairs(drags) -> bool:
    """``[(node, (x, y)), ...]``: a list of (node, position) pairs, which is not an accepted form."""
    items = list(drags)
    return bool(items) and all(isinstance(it, (tuple, list)) and len(it) == 2 and _is_scalar_int(it[0])
                               and np.ndim(it[1]) == 1 for it in items)


def _one(d, n):
    """``(indices, RigidDrag or final positions)`` of one drag item."""
    if isinstance(d, RigidDrag):
        return node_indices(np.array(d.nodes), "RigidDrag nodes", n=n), d
    if isinstance(d, Mapping):
        keys = list(d.keys())
        if any(not _is_scalar_int(k) for k in keys):
            bad = next(k for k in keys if not _is_scalar_int(k))
            raise TypeError(f"drags keys must be integer node indices, got {bad!r}; {_FORMS}")
        idx = node_indices(np.array(keys, dtype=np.int64), "drags (node indices)", n=n)
        pos = as_float_array([d[k] for k in keys], "drags (positions)", shape=(len(keys), 2)) \
            if keys else np.zeros((0, 2))
        return idx, pos
    raise TypeError(f"{_FORMS}; got an item of type {type(d).__name__}")


def drag_path(drags, mesh) -> DragPath:
    """Parse ``drags`` (any accepted form) into a :class:`DragPath` over ``mesh``'s nodes.

    Raises
    ------
    TypeError
        ``drags`` is none of the accepted forms (e.g. a list of ``(node, (x, y))`` pairs).
    ValueError
        A node index out of range, a node dragged twice (in any form, even to the same place), or positions
        of the wrong shape.

    Node indices are checked by :func:`~mdsr_opt.core.checks.node_indices` in every form: integers only (a
    float such as ``16.0`` is refused, never rounded), in range, each node once.
    """
    n = mesh.n_nodes
    parts = []
    if drags is None:
        items = []
    elif isinstance(drags, (Mapping, RigidDrag)):
        items = [drags]
    elif isinstance(drags, (tuple, list)):
        if _looks_like_pairs(drags):
            raise TypeError(f"{_FORMS}; got a list of (node, position) pairs: write "
                            "dict([(node, (x, y)), ...]) instead")
        if len(drags) == 2 and not any(isinstance(d, (Mapping, RigidDrag)) for d in drags):
            if _is_scalar_int(drags[0]):
                raise TypeError(f"{_FORMS}; got a single (node, position) pair: write {{node: (x, y)}}")
            idx = node_indices(drags[0], "drags[0] (node indices)", n=n)
            pos = as_float_array(drags[1], "drags[1] (positions)", shape=(len(idx), 2))
            items = [dict(zip(idx.tolist(), pos))] if len(idx) else []
        else:
            items = list(drags)
    else:
        raise TypeError(f"{_FORMS}; got {type(drags).__name__}")
    all_idx = []
    k = 0
    for d in items:
        idx, how = _one(d, n)
        parts.append((slice(k, k + len(idx)), how))
        all_idx.append(idx)
        k += len(idx)
    nodes = np.concatenate(all_idx) if all_idx else np.zeros(0, dtype=np.int64)
    path = DragPath(nodes=nodes.astype(np.int64), rest=mesh.points[nodes].astype(float).reshape(-1, 2),
                    parts=parts)
    if len(np.unique(nodes)) != len(nodes):
        u, c = np.unique(nodes, return_counts=True)
        k = int(u[c > 1][0])
        at = path.final[nodes == k]
        where = "to the same place" if np.all(at == at[0]) else \
            "to " + " and to ".join(f"({p[0]:.6g}, {p[1]:.6g})" for p in at)
        raise ValueError(f"drags name node {k} more than once ({where}): give each node once")
    return path
