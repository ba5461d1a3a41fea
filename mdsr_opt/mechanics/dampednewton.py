"""Damped Newton's method on a square system of equations, for the quadratic-element solves
(:mod:`~mdsr_opt.mechanics.quadsolve`).

:func:`damped_newton` takes a function ``system(z, jac) -> (scaled residual, Jacobian or None)`` and a start.
Each Newton step is damped by a backtracking line search on the residual that also refuses a state the caller's
``ok`` refuses (an inverted element). A solve that creeps (its residual falling by less than 10 % over
:data:`STALL_ITERATIONS` iterations, or :data:`SHORT_STEPS` steps in a row cut to :data:`SHORT_STEP` of the Newton
step) is given up as stalled, so that the caller takes a smaller load step instead.

Chord steps: once a full Newton step has cut the residual to :data:`CHORD_RATIO` of what it was (the iterates
are in Newton's region of fast convergence), the next steps solve with that step's factorisation instead of a
new Jacobian's, for as long as each cuts the residual to :data:`CHORD_RATIO` of the one before and keeps ``ok``;
the first that does not is dropped and a Newton step is taken from where the last accepted step ended. A
chord step costs a solve with the factors and one residual, a Newton step a Jacobian and a factorisation.
Either way the solve stops at a residual of at most ``tol``.

Example
-------
>>> import numpy as np
>>> def system(z, jac):  # z**3 = 8, with its derivative
...     return z ** 3 - 8.0, np.diag(3 * z ** 2) if jac else None
>>> z, converged, iterations, residual = damped_newton(system, np.array([1.0]), lambda z: True, 1e-12, 30)
>>> converged, round(float(z[0]), 9)
(True, 2.0)
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from .sparselu import ReusedOrdering

__all__ = ["damped_newton", "STALL_ITERATIONS", "SHORT_STEPS", "SHORT_STEP", "SHIFT", "CHORD_RATIO"]

#: a Newton solve stops as stalled once its residual fell by less than 10 % over this many iterations (after
#: twice as many): damped steps that creep, where a smaller load step converges sooner
STALL_ITERATIONS = 6

#: a Newton solve also stops as stalled after this many consecutive steps the line search cut to at most
#: :data:`SHORT_STEP` of the Newton step: the Newton step is dominated by a soft mode it overshoots (a slender
#: part swung far along its tangent), and the damped steps that follow creep
SHORT_STEPS = 2
SHORT_STEP = 1.0 / 32

#: :func:`damped_newton`'s first pseudo-transient shift over the median diagonal entry of the shifted block
SHIFT = 1e-3

#: the fall of the residual (new over old, in the largest entry) that a full Newton step must reach for its
#: factorisation to be kept for chord steps, and that each chord step must reach to be accepted
CHORD_RATIO = 0.1


def _max_abs(r: np.ndarray) -> float:
    return float(np.abs(r).max()) if r.size else 0.0


def damped_newton(system: Callable, z0: np.ndarray, ok: Callable, tol: float, max_iter: int,
                  order: ReusedOrdering | None = None, shifted: int = 0):
    """Damped Newton on ``system(z, jac) -> (scaled residual, Jacobian or None)`` from ``z0`` (``ok(z)``: whether
    a state may be taken); returns ``(z, converged, iterations, residual)``, ``iterations`` counting Newton and
    chord steps; a solve that stalls (:data:`STALL_ITERATIONS`, :data:`SHORT_STEPS`) returns as not converged.
    The Jacobian is asked for only at a state that does not meet ``tol`` (the residual of an accepted step is
    the line search's). ``order`` keeps the fill-reducing order of the linear solves (shared by the calls of
    one solve).

    ``shifted`` > 0: the first ``shifted`` unknowns get a pseudo-transient shift on the diagonal, :data:`SHIFT`
    x their median diagonal entry at the start times the square of the residual's fall since (a far start's
    soft modes take damped steps, the last steps are Newton's; the equations are unchanged)."""
    order = order if order is not None else ReusedOrdering()
    z = z0.copy()
    if not ok(z):
        return z, False, 0, float("inf")
    r = system(z, False)[0]
    norm = _max_abs(r)
    seen = [norm]
    short = 0  # consecutive steps cut to at most SHORT_STEP
    shift0 = None
    chord = None  # the factorisation kept for chord steps (solves with it), or None
    for it in range(max_iter):
        if norm <= tol:
            return z, True, it, norm
        if it >= 2 * STALL_ITERATIONS and norm > 0.9 * seen[-1 - STALL_ITERATIONS]:
            return z, False, it, norm  # stalled: the caller takes a smaller load step instead
        if chord is not None:
            zt = z + chord(-r)
            if np.isfinite(zt).all() and ok(zt):
                rt = system(zt, False)[0]
                if np.isfinite(rt).all() and _max_abs(rt) <= CHORD_RATIO * norm:
                    z, r, norm = zt, rt, _max_abs(rt)
                    seen.append(norm)
                    short = 0
                    continue
            chord = None  # too slow a fall: a Newton step from the last accepted state
        r, J = system(z, True)
        if shifted:
            if shift0 is None:
                shift0 = SHIFT * float(np.median(np.abs(J.diagonal()[:shifted])))
            d = np.zeros(J.shape[0])
            d[:shifted] = shift0 * (norm / seen[0]) ** 2
            J = (J + sp.diags(d)).tocsr()
        try:
            lu = order.factor(J)
            dz = lu(-r)
        except RuntimeError:  # an exactly singular matrix
            return z, False, it, norm
        if not np.isfinite(dz).all():
            return z, False, it, norm
        phi = float(r @ r)
        alpha = 1.0
        for _ in range(12):
            zt = z + alpha * dz
            if ok(zt):
                rt, _unused = system(zt, False)
                if np.isfinite(rt).all() and float(rt @ rt) <= (1.0 - 1e-4 * alpha) * phi:
                    break
            alpha *= 0.5
        else:
            return z, False, it, norm
        short = short + 1 if alpha <= SHORT_STEP else 0
        z, r = zt, rt
        before, norm = norm, _max_abs(r)
        seen.append(norm)
        if alpha == 1.0 and norm <= CHORD_RATIO * before:
            chord = lu
        if short >= SHORT_STEPS and norm > tol:
            return z, False, it + 1, norm  # stalled: the caller takes a smaller load step instead
    return z, norm <= tol, max_iter, norm
