"""End fixtures of physical size as reduced coordinates: the nodes of a fixture move rigidly with its end node.

A rope ends on a bead, knot or plate of radius ``r_f`` cast into the body; the body nodes within ``r_f`` of the
end node (the anchor patches of :func:`~mdsr_opt.mechanics.anchors.rigid_groups`, merged where two fixtures
overlap) move with it as one rigid body. Instead of constraints with multipliers, each group is given three
coordinates -- its first node's position and an angle -- and every other member follows:
``x_k = x_r + R(phi) (X_k - X_r)``. Nodes outside every group keep their own two coordinates.

:class:`RigidReduction` maps the reduced coordinates ``q`` to the node positions ``x``, and carries a gradient
and a Hessian from ``x`` to ``q`` (``P^T g`` and ``P^T H P`` plus the curvature of the rotation, ``-g_k .
(x_k - x_r)`` on each angle).

Example
-------
>>> import numpy as np
>>> red = RigidReduction(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]), [np.array([1, 2])])
>>> red.n_q  # nodes 0 and 1 free, node 2 follows node 1: 2 + 2 + 1 angle
5
>>> q = red.rest_q(); q[-1] = np.pi / 2
>>> red.x_of(q).round(12).tolist()
[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

__all__ = ["RigidReduction", "fixture_groups"]


def fixture_groups(mesh, muscles, radius: float, midnodes: np.ndarray | None = None) -> list[np.ndarray]:
    """The rigid fixture groups of ``muscles`` on ``mesh`` at fixture radius ``radius`` (length units):
    :func:`~mdsr_opt.mechanics.anchors.rigid_groups` (each group lists an end node first), each extended,
    when ``midnodes`` gives the midpoint node of every row of ``mesh.edges``, by the midpoints of the edges
    whose two ends are in the group."""
    from .anchors import rigid_groups

    groups = rigid_groups(mesh, muscles, radius)
    if midnodes is None:
        return [np.array(g, dtype=np.int64) for g in groups]
    E = mesh.edges
    out = []
    for g in groups:
        inside = np.zeros(mesh.n_nodes, dtype=bool)
        inside[g] = True
        rows = np.flatnonzero(inside[E[:, 0]] & inside[E[:, 1]])
        out.append(np.concatenate([np.asarray(g, dtype=np.int64), np.asarray(midnodes)[rows]]))
    return out


class RigidReduction:
    """Reduced coordinates of a body whose node ``groups`` move rigidly (see the module docstring).

    Parameters
    ----------
    points : (n, 2) rest positions.
    groups : sequence of int arrays, disjoint; the first node of each is its reference node.
    """

    def __init__(self, points, groups: Sequence[np.ndarray] = ()):
        X = np.asarray(points, dtype=float).reshape(-1, 2)
        n = len(X)
        member = np.full(n, -1, dtype=np.int64)  # group of a node that follows a reference node
        refs = []
        for k, g in enumerate(groups):
            g = np.asarray(g, dtype=np.int64).ravel()
            if len(g) < 2:
                continue
            if len(np.unique(g)) != len(g) or (member[g] >= 0).any() or np.isin(g, refs).any():
                raise ValueError(f"fixture group {k} overlaps another group or repeats a node")
            member[g[1:]] = len(refs)
            refs.append(int(g[0]))
        self.X = X
        self.n = n
        self.refs = np.array(refs, dtype=np.int64)
        self.member = member
        own = np.flatnonzero(member < 0)
        self.own = own
        self.q_index = np.full(n, -1, dtype=np.int64)  # x-coordinate of an own node in q (y follows)
        self.q_index[own] = 2 * np.arange(len(own))
        self.n_angles = len(refs)
        self.n_q = 2 * len(own) + self.n_angles
        self.followers = np.flatnonzero(member >= 0)
        self._fref = self.refs[member[self.followers]]
        self._arm0 = X[self.followers] - X[self._fref]

    def rest_q(self) -> np.ndarray:
        """The reduced coordinates of the rest shape."""
        q = np.zeros(self.n_q)
        q[:2 * len(self.own)] = self.X[self.own].ravel()
        return q

    def q_of(self, x) -> np.ndarray:
        """Reduced coordinates of a state ``x`` whose groups are rigid (each angle from the group's best-fit
        rotation)."""
        x = np.asarray(x, dtype=float).reshape(-1, 2)
        q = np.zeros(self.n_q)
        q[:2 * len(self.own)] = x[self.own].ravel()
        arm = x[self.followers] - x[self._fref]
        cross = self._arm0[:, 0] * arm[:, 1] - self._arm0[:, 1] * arm[:, 0]
        dot = (self._arm0 * arm).sum(1)
        g = self.member[self.followers]
        s, c = np.bincount(g, cross, self.n_angles), np.bincount(g, dot, self.n_angles)
        q[2 * len(self.own):] = np.arctan2(s, c)
        return q

    def _angles(self, q):
        phi = q[2 * len(self.own):][self.member[self.followers]]
        return np.cos(phi), np.sin(phi)

    def x_of(self, q) -> np.ndarray:
        """Node positions (n, 2) of the reduced coordinates ``q``."""
        q = np.asarray(q, dtype=float)
        x = np.empty((self.n, 2))
        x[self.own] = q[:2 * len(self.own)].reshape(-1, 2)
        c, s = self._angles(q)
        a = self._arm0
        x[self.followers] = x[self._fref] + np.column_stack([c * a[:, 0] - s * a[:, 1], s * a[:, 0] + c * a[:, 1]])
        return x

    def jacobian(self, q) -> sp.csr_matrix:
        """``P = dx/dq`` (2n, n_q), sparse."""
        x = self.x_of(q)
        rows, cols, vals = [], [], []
        own = self.own
        rows += [2 * own, 2 * own + 1]
        cols += [self.q_index[own], self.q_index[own] + 1]
        vals += [np.ones(len(own)), np.ones(len(own))]
        f, r = self.followers, self._fref
        rows += [2 * f, 2 * f + 1]
        cols += [self.q_index[r], self.q_index[r] + 1]
        vals += [np.ones(len(f)), np.ones(len(f))]
        arm = x[f] - x[r]
        ang = 2 * len(own) + self.member[f]
        rows += [2 * f, 2 * f + 1]
        cols += [ang, ang]
        vals += [-arm[:, 1], arm[:, 0]]
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(2 * self.n, self.n_q))

    def curvature(self, q, gx) -> sp.csr_matrix:
        """The second-derivative term of ``d^2 E / dq^2`` for a gradient ``gx`` (2n,) in ``x``: on each angle,
        ``sum_k gx_k . d^2 x_k / d phi^2 = -sum_k gx_k . (x_k - x_r)``, with the mixed angle-reference terms
        zero (the arm does not depend on ``x_r``)."""
        x = self.x_of(q)
        f, r = self.followers, self._fref
        arm = x[f] - x[r]
        g = np.asarray(gx, dtype=float).reshape(-1, 2)[f]
        d = np.bincount(self.member[f], -(g * arm).sum(1), self.n_angles)
        idx = 2 * len(self.own) + np.arange(self.n_angles)
        return sp.csr_matrix((d, (idx, idx)), shape=(self.n_q, self.n_q))
