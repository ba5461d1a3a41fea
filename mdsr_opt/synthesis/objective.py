"""The pinned pose's objective ``so sum_i w_i |R(theta) x_i + t - y_i|^2`` of the design NLP, written once.

A body whose energy changes under rotation (the linear elastic material) keeps its gauge coordinates fixed,
and the design NLP aligns its state with the target by a rotation ``theta`` and translation ``t``
(:mod:`~mdsr_opt.synthesis.nlp`). The functions here state the residual and its closed-form derivatives per
node with arithmetic alone, so the same lines evaluate numpy arrays (the numpy callbacks of
:mod:`~mdsr_opt.synthesis.nlp_numeric`) and CasADi rows (the NLP assembled term by term, and the SX NLP that
CasADi differentiates, the reference the tests compare both against).

Example
-------
>>> import numpy as np
>>> X0, X1 = np.array([1.0]), np.array([0.0])
>>> rx, ry = residual(X0, X1, np.array([0.0]), np.array([1.0]), 0.0, 1.0, 0.0, 0.0)  # a quarter turn
>>> float(rx[0]), float(ry[0])
(0.0, 0.0)
"""

from __future__ import annotations

__all__ = ["HESSIAN_PARTS", "residual", "derivatives"]

#: the objective's Hessian entries per node, as (row, col) local names: ``x0``, ``x1`` the node's
#: coordinates, ``th`` the rotation, ``t0``, ``t1`` the translation (the ``t0``-``t1`` entry is zero)
HESSIAN_PARTS = [("x0", "x0"), ("x1", "x1"), ("x0", "th"), ("x1", "th"), ("x0", "t0"), ("x0", "t1"),
                 ("x1", "t0"), ("x1", "t1"), ("th", "th"), ("th", "t0"), ("th", "t1"), ("t0", "t0"),
                 ("t1", "t1")]


def residual(X0, X1, Y0, Y1, c, s, t0, t1):
    """``(rx, ry)`` per node: ``R x_i + t - y_i`` with ``R = [[c, -s], [s, c]]`` (``c, s`` the cosine and sine
    of ``theta``); ``X0, X1, Y0, Y1`` the coordinates of the state and target, per node."""
    return c * X0 - s * X1 + t0 - Y0, s * X0 + c * X1 + t1 - Y1


def derivatives(X0, X1, rx, ry, W2, c, s, exact: bool):
    """Per-node summands of the objective's derivatives at the state's coordinates ``X0, X1`` and the
    :func:`residual` ``rx, ry``, with ``W2 = 2 so w_i`` per node.

    Returns ``(gx, gv, parts)``: the gradient in the node's coordinates ``(g_x0, g_x1)``, the summands of the
    gradient in ``(theta, t0, t1)`` and the Hessian entries in the order of :data:`HESSIAN_PARTS` (those of
    the ``(theta, t)`` block are summands). Without ``exact``, the Gauss-Newton Hessian ``2 so w_i J_i' J_i``
    (``J_i`` the residual's Jacobian).
    """
    px, py = -s * X0 - c * X1, c * X0 - s * X1  # dR/dtheta x_i
    gx = (W2 * (c * rx + s * ry), W2 * (-s * rx + c * ry))
    gv = (W2 * (rx * px + ry * py), W2 * rx, W2 * ry)
    h_xth0, h_xth1, h_thth = W2 * -X1, W2 * X0, W2 * (px * px + py * py)  # R' dR/dtheta x_i = (-x_i1, x_i0)
    if exact:  # the residual's curvature r . d^2 r
        h_xth0 = h_xth0 + W2 * (-s * rx + c * ry)
        h_xth1 = h_xth1 + W2 * (-c * rx - s * ry)
        h_thth = h_thth - W2 * (rx * (c * X0 - s * X1) + ry * (s * X0 + c * X1))
    parts = [W2, W2, h_xth0, h_xth1, W2 * c, W2 * s, W2 * -s, W2 * c, h_thth, W2 * px, W2 * py, W2, W2]
    return gx, gv, parts
