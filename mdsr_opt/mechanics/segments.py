"""A spring's energy and the closed-form derivatives of a segment's length, shared by the edge springs and
the ropes.

For a segment ``d = x_b - x_a`` of length ``l = |d|`` and direction ``u = d / l``, with ``P = I - u u'``:
``grad l = u`` (at ``b``; ``-u`` at ``a``), ``Hessian l = P / l`` and, along a relative move ``dv``, the
third derivative ``D^3 l [dv] = -(q u' + u q' + (u . dv) P) / l^2`` with ``q = P dv``. A spring
``k/2 (l - c)^2`` has the third derivative ``-k c D^3 l``; a rope's length is a sum of them.

Every function takes per-segment arrays (``d``, ``dv`` of shape (n, 2)) and works on all at once.

Example
-------
>>> import numpy as np
>>> d, dv = np.array([[2.0, 0.0]]), np.array([[0.0, 1.0]])
>>> length_hessian_product(d, dv).tolist()        # P dv / l: the perpendicular part, over the length
[[0.0, 0.5]]
>>> float(length_third(d, dv)[0, 0, 1])           # -(q u' + u q')/l^2: q = (0, 1), u = (1, 0)
-0.25
"""

from __future__ import annotations

import numpy as np

__all__ = ["spring_energy", "length_direction", "length_hessian_product", "length_third", "pair_blocks"]


def spring_energy(length, k, rest):
    """``k/2 (length - rest)^2``: the one statement of a spring's energy (numpy arrays or CasADi symbols), for
    the edge springs of the per-segment muscles and the sliding cables (``length`` their path length)."""
    return k / 2 * (length - rest) ** 2


def length_direction(d) -> tuple[np.ndarray, np.ndarray]:
    """``(l (n,), u (n, 2))``: the lengths (at least 1e-300) and unit directions of the segments ``d``."""
    d = np.asarray(d, dtype=float)
    ln = np.maximum(np.sqrt((d * d).sum(1)), 1e-300)
    return ln, d / ln[:, None]


def length_hessian_product(d, dv) -> np.ndarray:
    """``Hessian(l) dv = (I - u u') dv / l`` per segment (n, 2): the product's part at ``b`` (``-`` it at ``a``)."""
    ln, u = length_direction(d)
    dv = np.asarray(dv, dtype=float)
    return (dv - (u * dv).sum(1)[:, None] * u) / ln[:, None]


def length_third(d, dv) -> np.ndarray:
    """``D^3 l [dv]`` per segment (n, 2, 2): the derivative of ``Hessian(l)`` along the relative move ``dv``
    (the block at ``(a, a)`` and ``(b, b)``; minus it at ``(a, b)`` and ``(b, a)``)."""
    ln, u = length_direction(d)
    dv = np.asarray(dv, dtype=float)
    ud = (u * dv).sum(1)
    q = dv - ud[:, None] * u
    P = np.eye(2)[None] - u[:, :, None] * u[:, None, :]
    return -(q[:, :, None] * u[:, None, :] + u[:, :, None] * q[:, None, :] + ud[:, None, None] * P) \
        / (ln ** 2)[:, None, None]


def pair_blocks(K) -> np.ndarray:
    """The (4, 4, n) blocks ``[[K, -K], [-K, K]]`` of per-segment 2 x 2 blocks ``K`` (n, 2, 2), segment last
    (the layout of :class:`~mdsr_opt.mechanics.newton.NewtonEnergy`'s spring blocks)."""
    K = np.asarray(K, dtype=float)
    H = np.empty((len(K), 4, 4))
    H[:, :2, :2] = K
    H[:, 2:, 2:] = K
    H[:, :2, 2:] = -K
    H[:, 2:, :2] = -K
    return np.ascontiguousarray(np.transpose(H, (1, 2, 0)))
