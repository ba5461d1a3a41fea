"""Pseudo-transient continuation: an equilibrium reached past a limit point of a load path.

A load continuation (:mod:`~mdsr_opt.mechanics.quadsolve`) follows the branch of equilibria from rest. Where
that branch turns back (a limit point: a compressed strip that wrinkles one way can carry no more load, the
body snaps to another shape), no load step beyond it converges, however small: Newton's method from the last
equilibrium stalls with a residual that does not fall, its steps dominated by the nearly singular mode.
The physical body does not stop there: it moves, damped, to an equilibrium of another branch.

:func:`pseudo_transient` follows that motion in pseudo time: each step solves ``(J + D_k) dz = -r`` with a
diagonal shift ``D_k`` on the first ``shifted`` unknowns (the coordinates; not the ropes' tensions), the
median diagonal entry of their block of the first Jacobian times the residual's fall since the start,
``|r_k| / |r_0|`` (switched evolution relaxation: long pseudo time steps as the residual falls, Newton's
steps at the end). A step is shortened (halved) only where the caller's ``ok`` refuses the state (an
inverted element); the residual may rise on the way. The solve ends at a residual of at most ``tol``, or
fails: after ``max_iter`` steps, a residual not finite or :data:`DIVERGED` times the start's, a singular
matrix, or a step ``ok`` refuses 12 times halved.

Example
-------
>>> import numpy as np
>>> def system(z, jac):  # z**3 = 8, with its derivative
...     return z ** 3 - 8.0, np.diag(3 * z ** 2) if jac else None
>>> z, converged, iterations, residual = pseudo_transient(system, np.array([1.0]), lambda z: True, 1e-12, 100, 1)
>>> converged, round(float(z[0]), 9)
(True, 2.0)
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from .sparselu import ReusedOrdering

__all__ = ["DIVERGED", "pseudo_transient"]

#: the solve fails once its residual exceeds this many times the residual it started from
DIVERGED = 1e3


def _max_abs(r: np.ndarray) -> float:
    return float(np.abs(r).max()) if r.size else 0.0


def pseudo_transient(system: Callable, z0: np.ndarray, ok: Callable, tol: float, max_iter: int, shifted: int,
                     order: ReusedOrdering | None = None):
    """Pseudo-transient continuation on ``system(z, jac) -> (scaled residual, Jacobian or None)`` from ``z0``
    (``ok(z)``: whether a state may be taken), the first ``shifted`` unknowns shifted (module docstring).
    Returns ``(z, converged, iterations, residual)`` as
    :func:`~mdsr_opt.mechanics.dampednewton.damped_newton`."""
    if isinstance(shifted, bool) or not isinstance(shifted, (int, np.integer)) or not 0 < shifted <= len(z0):
        raise ValueError(f"shifted must be a count of unknowns in [1, {len(z0)}], got {shifted!r}")
    order = order if order is not None else ReusedOrdering()
    z = np.asarray(z0, dtype=float).copy()
    if not ok(z):
        return z, False, 0, float("inf")
    r = system(z, False)[0]
    norm = norm0 = _max_abs(r)
    if not np.isfinite(norm):
        return z, False, 0, norm
    scale = None
    for it in range(max_iter):
        if norm <= tol:
            return z, True, it, norm
        r, J = system(z, True)
        if scale is None:
            scale = float(np.median(np.abs(J.diagonal()[:shifted])))
        d = np.zeros(J.shape[0])
        d[:shifted] = scale * min(1.0, norm / norm0)
        try:
            dz = order.factor(sp.csr_matrix(J) + sp.diags(d, format="csr"))(-r)
        except RuntimeError:  # an exactly singular matrix
            return z, False, it, norm
        if not np.isfinite(dz).all():
            return z, False, it, norm
        alpha = 1.0
        for _ in range(12):
            if ok(z + alpha * dz):
                break
            alpha *= 0.5
        else:
            return z, False, it, norm
        z = z + alpha * dz
        r = system(z, False)[0]
        norm = _max_abs(r)
        if not np.isfinite(norm) or norm > DIVERGED * norm0:
            return z, False, it + 1, norm
    return z, norm <= tol, max_iter, norm
