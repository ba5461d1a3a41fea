"""A rope with capstan friction in its channel.

A rope pulled by a servo at one end slides in a moulded channel; where the channel turns, the rope presses on
its wall and friction takes up part of the pull. Along the route the tension falls as the capstan law says,
``T(s) = T_0 exp(-mu theta(s))``, ``theta(s)`` the rope's accumulated turning angle from the pulled end. On a
chain of straight segments ``i = 0 .. k-1`` (segment 0 at the pulled end) the turning at the node between
segments ``i - 1`` and ``i`` is the angle between their directions, ``theta_0 = 0`` and ``theta_i`` the sum of
the turnings up to segment ``i``, so the segment tensions are ``T_i = tau exp(-mu theta_i)``. The rope's force
on the body is ``sum_i T_i grad l_i(x)``, and its length is held: ``sum_i l_i(x) = (1 - a) L0``.

With ``mu = 0`` every segment carries ``tau`` and the rope is the exact sliding cable of
:func:`~mdsr_opt.mechanics.equilibrium.solve_internal`. The turning angles are those of the current state; the
Newton solve of :mod:`~mdsr_opt.mechanics.quadsolve` holds them fixed within one linearisation (a
fixed-point update), so a converged state satisfies the capstan law at its own angles.

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

    def forces(self, x, weights, n_nodes: int) -> tuple[np.ndarray, np.ndarray, sp.csr_matrix]:
        """For segment weights ``w``: ``f = sum_i w_i grad l_i`` and ``g = sum_i grad l_i`` (2n,) and
        ``H = sum_i w_i hess l_i`` (2n, 2n), the weights held fixed."""
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
