"""Coulomb friction between body nodes and rigid obstacles: a lagged, smoothed dissipation potential per load
step.

Quasi-static Coulomb friction (stick while the tangential force is below ``mu N``, then slip) is posed per
load step as a potential added to the energy, so each step stays a minimisation:

``D(x) = sum_k mu N_k (sqrt(u_k^2 + eps^2) - eps)``,  ``u_k = t_k . (x_k - x0_k)``

for each contact point ``k`` of the body on an obstacle (a node; or, for a disk touching a boundary segment
between its nodes, the material point of the segment it touches at the step's start), with ``x0`` the state at the start of the step, ``t_k`` the
obstacle's tangent there and ``N_k`` the normal force *lagged*: taken from the previous solve of the same
step and the step solved again until it changes by less than :data:`LAG_RTOL` of the largest (a fixed point;
at most :data:`LAG_ITER` solves). The tangential force ``mu N u / sqrt(u^2 + eps^2)`` is below ``mu N``
(slip: it approaches it once ``|u| >> eps``); a sticking node creeps by ``eps (F/mu N) / sqrt(1 - (F/mu N)^2)``
per step under a tangential force ``F`` (``eps`` = :data:`EPS` times the body's size: 1e-5: a node held at
half its friction limit moves 0.6e-5 of the size per step). These are the errors of the model.

Example
-------
>>> import numpy as np
>>> ft = FrictionTerm(np.array([0]), np.array([[1.0, 0.0]]), np.zeros(2), np.array([2.0]), 0.5, 1e-3)
>>> round(float(ft.energy(np.array([1.0, 0.0]))), 6)     # slipping 1 along the tangent: about mu N |u|
0.999
>>> np.round(ft.gradient(np.array([1.0, 0.0])), 6).tolist()   # the friction force: mu N at most
[1.0, 0.0]
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

__all__ = ["FrictionTerm", "EPS", "LAG_RTOL", "LAG_ITER", "friction_expr", "friction_params", "n_friction_params"]

#: the smoothing length of the friction potential, relative to the body's size
EPS = 1e-5
#: the lagged normal forces are a fixed point to this fraction of the largest normal force
LAG_RTOL = 1e-3
#: solves of one load step at most for the lagged normal forces
LAG_ITER = 8


class FrictionTerm:
    """``D(x)`` of the module docstring for contact points ``nodes`` with unit tangents ``t`` (k, 2), start state
    ``x0`` (2n,), lagged normal forces ``N`` (k,), coefficient ``mu`` and smoothing length ``eps``.

    ``nodes``: (k,) body nodes, or (k, 2) node pairs with ``weights`` (k, 2): a contact point on a boundary
    segment, the material point ``w_a x_a + w_b x_b`` (a disk touching a segment between its nodes); ``u`` is
    then that point's move along ``t``, and its friction force is shared by the two nodes by their weights."""

    def __init__(self, nodes, t, x0, N, mu, eps, weights=None):
        nodes = np.asarray(nodes, dtype=np.int64)
        if nodes.ndim == 1:
            nodes = np.column_stack([nodes, nodes])
            weights = np.column_stack([np.ones(len(nodes)), np.zeros(len(nodes))])
        self.pairs = nodes.reshape(-1, 2)
        self.weights = np.asarray(weights, dtype=float).reshape(-1, 2)
        #: per contact its body node, -1 for a point on a segment
        self.nodes = np.where(self.weights[:, 1] == 0.0, self.pairs[:, 0], -1)
        self.t = np.asarray(t, dtype=float).reshape(-1, 2)
        self.x0 = np.asarray(x0, dtype=float).reshape(-1)
        self.N = np.asarray(N, dtype=float)
        self.mu, self.eps = float(mu), float(eps)
        self.n_dof = len(self.x0)

    def _point(self, x) -> np.ndarray:
        X = np.asarray(x, dtype=float).reshape(-1, 2)
        return self.weights[:, :1] * X[self.pairs[:, 0]] + self.weights[:, 1:] * X[self.pairs[:, 1]]

    def _u(self, x):
        return ((self._point(x) - self._point(self.x0)) * self.t).sum(1)

    def tangential_move(self, x) -> np.ndarray:
        """How far each contact point moved along its tangent since the step's start ``x0`` (k,)."""
        return self._u(x)

    def energy(self, x) -> float:
        u = self._u(x)
        return float((self.mu * self.N * (np.sqrt(u * u + self.eps ** 2) - self.eps)).sum())

    def forces(self, x) -> np.ndarray:
        """The tangential friction force on each contact point (k,), along ``-t`` for positive values."""
        u = self._u(x)
        return self.mu * self.N * u / np.sqrt(u * u + self.eps ** 2)

    def slipping(self, x, rtol: float = 0.99) -> np.ndarray:
        """Contacts whose friction force has reached ``rtol`` of ``mu N`` (k,) bool."""
        return np.abs(self.forces(x)) >= rtol * self.mu * self.N - 1e-300

    def gradient(self, x) -> np.ndarray:
        g = np.zeros(self.n_dof)
        f = self.forces(x)
        for j in range(2):
            np.add.at(g, 2 * self.pairs[:, j], self.weights[:, j] * f * self.t[:, 0])
            np.add.at(g, 2 * self.pairs[:, j] + 1, self.weights[:, j] * f * self.t[:, 1])
        return g

    def hessian(self, x) -> sp.csc_matrix:
        u = self._u(x)
        k = self.mu * self.N * self.eps ** 2 / (u * u + self.eps ** 2) ** 1.5
        r, c, v = [], [], []
        for ja in range(2):
            for jb in range(2):
                for i in range(2):
                    for j in range(2):
                        r.append(2 * self.pairs[:, ja] + i)
                        c.append(2 * self.pairs[:, jb] + j)
                        v.append(k * self.weights[:, ja] * self.weights[:, jb] * self.t[:, i] * self.t[:, j])
        return sp.csc_matrix((np.concatenate(v), (np.concatenate(r), np.concatenate(c))),
                             shape=(self.n_dof, self.n_dof))


def friction_expr(x, pairs, P):
    """``D`` as a CasADi expression of the MX ``x`` for ``k = len(pairs)`` contact points on the node pairs
    ``pairs`` (k, 2) (a node contact: the node twice), their data in the MX parameter column ``P`` (length
    :func:`n_friction_params`) = ``[mu, eps, the points' start (2k), N (k), t (2k), weights (2k)]``."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    k = len(pairs)
    if k == 0:
        return ca.MX(0)
    mu, eps = P[0], P[1]
    x0 = P[2:2 + 2 * k]
    N = P[2 + 2 * k:2 + 3 * k]
    t = P[2 + 3 * k:2 + 5 * k]
    w = P[2 + 5 * k:2 + 7 * k]
    pa, pb = pairs[:, 0], pairs[:, 1]
    px = w[0::2] * x[(2 * pa).tolist()] + w[1::2] * x[(2 * pb).tolist()]
    py = w[0::2] * x[(2 * pa + 1).tolist()] + w[1::2] * x[(2 * pb + 1).tolist()]
    u = (px - x0[0::2]) * t[0::2] + (py - x0[1::2]) * t[1::2]
    return mu * ca.dot(N, ca.sqrt(u * u + eps ** 2) - eps)


def n_friction_params(k: int) -> int:
    """The length of :func:`friction_expr`'s parameter column for ``k`` contact points."""
    return 2 + 7 * int(k)


def friction_params(term: FrictionTerm) -> np.ndarray:
    """The parameter column of :func:`friction_expr` for ``term``."""
    return np.concatenate([[term.mu, term.eps], term._point(term.x0).reshape(-1), term.N, term.t.reshape(-1),
                           term.weights.reshape(-1)])
