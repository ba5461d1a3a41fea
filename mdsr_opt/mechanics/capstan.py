"""A rope with capstan friction in its channel.

A rope pulled by a servo at one end slides in a moulded channel; where the channel turns, the rope presses on
its wall and friction takes up part of the pull. Along the route the tension falls as the capstan law says,
``T(s) = T_0 exp(-mu theta(s))``, ``theta(s)`` the rope's accumulated turning angle from the pulled end. On a
chain of straight segments ``i = 0 .. k-1`` (segment 0 at the pulled end) the turning at the node between
segments ``i - 1`` and ``i`` is the angle between their directions, ``theta_0 = 0`` and ``theta_i`` the sum of
the turnings up to segment ``i``, so the segment tensions are ``T_i = tau exp(-mu theta_i)``. The rope's force
on the body is ``sum_i T_i grad l_i(x)``, and its length is held: ``sum_i l_i(x) = (1 - a) L0``.

With ``mu = 0`` every segment carries ``tau`` and the rope is the exact sliding cable of
:func:`~mdsr_opt.mechanics.equilibrium.solve_internal`. The turning angles are those of the current state, and
:meth:`CapstanRope.weight_coupling` gives the change of the force through them for a Newton matrix.

Example
-------
>>> import numpy as np
>>> rope = CapstanRope(np.array([0, 1, 2]), mu=0.5)
>>> x = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])   # a right-angle turn at node 1
>>> rope.weights(x).round(6).tolist()                      # exp(-0.5 * pi / 2) on the second segment
[1.0, 0.455938]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..core.checks import positive_float

__all__ = ["CapstanRope", "quadratic_chain", "turning_angles"]


def quadratic_chain(mesh, nodes, midnodes) -> np.ndarray:
    """A node chain along edges of ``mesh`` with the midpoint node of each of its edges inserted
    (``midnodes[row]`` for each row of ``mesh.edges``): the rope's path on the quadratic mesh."""
    nodes = np.asarray(nodes, dtype=np.int64)
    rows = mesh.edge_rows(nodes[:-1], nodes[1:])
    if (rows < 0).any():
        k = int(np.flatnonzero(rows < 0)[0])
        raise ValueError(f"nodes {nodes[k]} and {nodes[k + 1]} of the chain are not joined by a mesh edge")
    out = np.empty(2 * len(nodes) - 1, dtype=np.int64)
    out[0::2] = nodes
    out[1::2] = np.asarray(midnodes)[rows]
    return out


def turning_angles(x, chain) -> np.ndarray:
    """Accumulated turning angle ``theta_i`` of each segment of the chain (from its first node), (k,):
    ``theta_0 = 0`` and ``theta_i = theta_{i-1} + angle(d_{i-1}, d_i)`` with the unsigned angle between
    consecutive segment directions in ``[0, pi]``."""
    x = np.asarray(x, dtype=float).reshape(-1, 2)
    d = np.diff(x[np.asarray(chain)], axis=0)
    cross = d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]
    dot = (d[:-1] * d[1:]).sum(1)
    return np.concatenate([[0.0], np.cumsum(np.arctan2(np.abs(cross), dot))])


@dataclass(frozen=True)
class CapstanRope:
    """One rope along a node ``chain`` (pulled at ``chain[0]``) with friction coefficient ``mu``.

    Attributes
    ----------
    chain : (k + 1,) int ndarray
    mu : float
        Coefficient of friction between rope and channel (0: the exact cable).
    """

    chain: np.ndarray
    mu: float = 0.0

    def __post_init__(self):
        c = np.asarray(self.chain, dtype=np.int64).ravel()
        if len(c) < 2 or len(np.unique(c)) != len(c):
            raise ValueError("a rope's chain needs at least two distinct nodes, none twice")
        object.__setattr__(self, "chain", c)
        object.__setattr__(self, "mu", positive_float(self.mu, "mu (rope friction)", allow_zero=True))

    def lengths(self, x) -> np.ndarray:
        """Segment lengths (k,)."""
        x = np.asarray(x, dtype=float).reshape(-1, 2)
        return np.linalg.norm(np.diff(x[self.chain], axis=0), axis=1)

    def length(self, x) -> float:
        return float(self.lengths(x).sum())

    def weights(self, x) -> np.ndarray:
        """``exp(-mu theta_i)``: each segment's tension over the pulled end's."""
        return np.exp(-self.mu * turning_angles(x, self.chain))

    def weight_coupling(self, x, n_nodes: int) -> sp.csr_matrix:
        """``M = sum_i grad l_i (grad w_i)^T`` (2n, 2n), the change of the rope's force ``sum_i w_i grad l_i``
        through its weights ``w_i = exp(-mu theta_i(x))`` (the turning of the path), so that a Newton step
        sees how friction changes as the rope bends. ``grad theta_i`` sums the gradients of the turning angles
        at the nodes before segment ``i``; at a straight node (no turning) the angle's gradient is taken as 0.
        Dense over the rope's nodes, zero elsewhere."""
        c = self.chain
        k = len(c) - 1
        n2 = 2 * n_nodes
        if self.mu == 0.0 or k < 2:
            return sp.csr_matrix((n2, n2))
        x = np.asarray(x, dtype=float).reshape(-1, 2)
        d = np.diff(x[c], axis=0)
        ln = np.linalg.norm(d, axis=1)
        u = d / ln[:, None]
        w = self.weights(x)
        m = 2 * (k + 1)
        Gl = np.zeros((k, m))  # grad l_i over the chain's coordinates
        idx = np.arange(k)
        Gl[idx, 2 * idx], Gl[idx, 2 * idx + 1] = -u[:, 0], -u[:, 1]
        Gl[idx, 2 * idx + 2], Gl[idx, 2 * idx + 3] = u[:, 0], u[:, 1]
        a, b = d[:-1], d[1:]  # the turn at chain node j (1 .. k-1) between segments j-1 and j
        cr = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
        dt = (a * b).sum(1)
        sgn = np.sign(cr)
        den = cr ** 2 + dt ** 2
        # d atan2(cr, dt) = (dt d cr - cr d dt) / den, with d cr/da = (b_y, -b_x), d cr/db = (-a_y, a_x)
        ga = (dt[:, None] * np.column_stack([b[:, 1], -b[:, 0]]) - cr[:, None] * b) * (sgn / den)[:, None]
        gb = (dt[:, None] * np.column_stack([-a[:, 1], a[:, 0]]) - cr[:, None] * a) * (sgn / den)[:, None]
        A = np.zeros((k - 1, m))  # grad of the turning angle at node j = 1 .. k-1
        j = np.arange(1, k)
        # a = x_j - x_{j-1}, b = x_{j+1} - x_j
        A[j - 1, 2 * (j - 1)], A[j - 1, 2 * (j - 1) + 1] = -ga[:, 0], -ga[:, 1]
        A[j - 1, 2 * j], A[j - 1, 2 * j + 1] = ga[:, 0] - gb[:, 0], ga[:, 1] - gb[:, 1]
        A[j - 1, 2 * (j + 1)], A[j - 1, 2 * (j + 1) + 1] = gb[:, 0], gb[:, 1]
        # grad w_i = -mu w_i sum_{j <= i} A_j: M = -mu sum_j (sum_{i >= j} w_i grad l_i) A_j^T
        S = np.cumsum((w[:, None] * Gl)[::-1], axis=0)[::-1]  # S[i] = sum_{i' >= i} w_i' grad l_i'
        Mloc = -self.mu * (S[1:].T @ A)
        dofs = np.column_stack([2 * c, 2 * c + 1]).ravel()
        rows = np.repeat(dofs, m)
        cols = np.tile(dofs, m)
        return sp.csr_matrix((Mloc.ravel(), (rows, cols)), shape=(n2, n2))

    def forces(self, x, weights, n_nodes: int) -> tuple[np.ndarray, np.ndarray, sp.csr_matrix]:
        """For segment weights ``w``: ``f = sum_i w_i grad l_i`` and ``g = sum_i grad l_i`` (2n,) and
        ``H = sum_i w_i hess l_i`` (2n, 2n), the weights held fixed (see :meth:`weight_coupling`)."""
        x = np.asarray(x, dtype=float).reshape(-1, 2)
        a, b = self.chain[:-1], self.chain[1:]
        d = x[b] - x[a]
        ln = np.linalg.norm(d, axis=1)
        u = d / ln[:, None]
        w = np.asarray(weights, dtype=float)
        f = np.zeros((n_nodes, 2))
        g = np.zeros((n_nodes, 2))
        np.add.at(f, a, -w[:, None] * u)
        np.add.at(f, b, w[:, None] * u)
        np.add.at(g, a, -u)
        np.add.at(g, b, u)
        B = (w / ln)[:, None, None] * (np.eye(2)[None] - u[:, :, None] * u[:, None, :])  # (k, 2, 2)
        rows, cols, vals = [], [], []
        for p, q, sign in ((a, a, 1.0), (b, b, 1.0), (a, b, -1.0), (b, a, -1.0)):
            for i in range(2):
                for j in range(2):
                    rows.append(2 * p + i)
                    cols.append(2 * q + j)
                    vals.append(sign * B[:, i, j])
        H = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(2 * n_nodes, 2 * n_nodes))
        return f.ravel(), g.ravel(), H
