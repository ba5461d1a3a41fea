"""The design's rivals for comparison studies: nested (adjoint gradients) and derivative-free."""

from __future__ import annotations

import logging
import math
import time
from typing import Callable
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..mechanics.anchors import body_size
from .problem import ForwardSolver, DesignProblem

_LOG = logging.getLogger(__name__)

#: a design of the outer loops (nested, derivative-free) says how far it got at most this often (seconds of
#: wall time): each of its forward solves may take seconds with contact, and nothing else is printed meanwhile
PROGRESS_SECONDS = 10.0
#: the nested search's failed trial steps in a row (a forward solve failed, e.g. the outline crossed itself)
#: it backs off from, each by the line search's shorter step, before it gives up
MAX_BACKOFFS = 8
#: a failed trial step's value: this many times the last accepted one, plus one
BACKOFF_FACTOR = 4.0
#: Nelder-Mead's ``fatol``: the differences of its simplex's points agree within this share of the body's size
DIFF_ATOL = 1e-9
#: Powell's ``ftol``: the objective's relative decrease in a sweep below which it stops
POWELL_FTOL = 1e-10


# ---------------------------------------------------------------------------------------------- outer loops
class _Outer:
    """Objective of the reduced problem ``a -> J(x*(a))`` with a record of every evaluation."""

    def __init__(self, prob: DesignProblem, fwd: ForwardSolver, clock: Callable[[], float], penalty: float = 1e6,
                 length: float = 1.0):
        self.prob, self.fwd, self.clock = prob, fwd, clock
        self.length = length  # the caller's length of one unit of the problem's body (for the progress line)
        self.penalty = penalty
        self.history: list[tuple[float, float]] = []
        self.best: tuple[float, np.ndarray, np.ndarray] | None = None
        self.failures: list[str] = []
        self.n_eval = 0
        self.last: tuple[float, np.ndarray] | None = None  # the nested search's last accepted value and gradient
        self.backoffs = 0  # its failed trial steps in a row
        self._started = self._said = time.monotonic()

    def _eval(self, a):
        a = np.clip(np.asarray(a, dtype=float), 0.0, self.prob.a_upper)
        x, ok, status = self.fwd.solve(a)
        self.n_eval += 1
        if not ok:
            self.failures.append(status)
            self._progress()
            return None, a, x, None, None
        J, al, dJ = self.prob.objective(x.reshape(-1, 2))
        if self.best is None or J < self.best[0]:
            self.best = (J, a.copy(), x.copy())
        self.history.append((self.clock(), math.sqrt(self.best[0]) * self.prob.h))
        self._progress()
        return J, a, x, al, dJ

    def _progress(self) -> None:
        """An INFO record (``mdsr run`` prints it) when :data:`PROGRESS_SECONDS` have passed since the last."""
        now = time.monotonic()
        if now - self._said < PROGRESS_SECONDS:
            return
        self._said = now
        d = self.history[-1][1] if self.history else None
        best = "none yet" if d is None else \
            f"{d * self.length:.4g} ({100 * d / body_size(self.prob.mesh):.3g} % of the body's size)"
        _LOG.info("design: %d forward solve(s) in %.0f s, best difference so far %s (%d failed)", self.n_eval,
                  now - self._started, best, len(self.failures))

    def value(self, a) -> float:
        J, *_ = self._eval(a)
        return self.penalty if J is None else J

    def value_and_grad(self, a):
        J, a, x, _al, dJ = self._eval(a)
        if J is None:  # a trial step whose body crossed itself, or whose solve failed: backed off
            self.backoffs += 1
            if self.backoffs > MAX_BACKOFFS or self.last is None:
                raise _ForwardFailed(self.failures[-1])
            # a value well above the last accepted one (the line search shortens its step), its slope kept
            return BACKOFF_FACTOR * self.last[0] + 1.0, self.last[1]
        g = _reduced_gradient(self.prob, a, x, dJ)
        self.last, self.backoffs = (J, g), 0
        return J, g


class _ForwardFailed(RuntimeError):
    pass


def _reduced_gradient(prob: DesignProblem, a, x, dJ) -> np.ndarray:
    """``dJ/da`` at an equilibrium ``x`` of contractions ``a`` by the implicit-function theorem.

    The equilibrium solves ``F(x, kappa; a) = [sc grad E(x, a) + J_C(x)^T kappa ; C(x) + E a] = 0`` on the
    free dofs, with the active muscle constraints (the rigid end patches; the cable's taut ropes; a slack
    rope's row drops out, and so does its contraction's influence). One adjoint solve with the symmetric
    KKT matrix ``K = [[H, A^T], [A, 0]]`` (``H`` the Hessian of the Lagrangian) gives
    ``dJ/da = -lambda^T dF/da`` with ``K lambda = [dJ/dx ; 0]``. Without constraints ``K = H``.
    """
    free = prob.free
    sc = 1.0 / (prob.Et * prob.h)
    p = prob.params(a)
    H = prob.model.hessian(x, p) * sc
    blk = prob.block
    dFa = sc * prob.dg_da(x)[free]
    if blk.nc:
        kap = blk.multipliers(x, prob.model.gradient(x, p) * sc, free)
        act = np.ones(blk.nc, dtype=bool)
        if blk.rope:
            act[:prob.m] = kap[:prob.m] > 1e-9 * max(1.0, float(np.abs(kap).max()))
        H = (H + blk.hessian(x, kap)).tocsr()
        A = blk.jacobian(x)[np.nonzero(act)[0]][:, np.nonzero(free)[0]]
        K = sp.bmat([[H[free][:, free], A.T], [A, None]]).tocsc()
        Ea = np.zeros((blk.nc, prob.m))
        if blk.rope:
            Ea[:prob.m] = np.eye(prob.m)
        dFa = np.vstack([dFa, Ea[act]])
        rhs = np.concatenate([dJ[free], np.zeros(int(act.sum()))])
    else:
        K = H[free][:, free].tocsc()
        rhs = dJ[free]
    lam = spla.spsolve(K, rhs)
    return -(dFa.T @ lam)


def run_nested(prob, a0, fwd, tol, max_iter, outer_options, clock, length: float = 1.0):
    """The nested search (L-BFGS-B on ``a -> J(x*(a))`` with adjoint gradients) from ``a0``.

    A trial step whose forward solve fails (its outline crosses itself, say) is backed off: its value is
    :data:`BACKOFF_FACTOR` times the last accepted one, so the line search tries a shorter step; after
    :data:`MAX_BACKOFFS` failed trials in a row (or a failed first solve) the search gives up, a failure.
    """
    from scipy.optimize import minimize

    obj = _Outer(prob, fwd, clock, length=length)
    opts = {"maxiter": max_iter, "ftol": tol ** 2, "gtol": tol}
    opts.update(outer_options or {})
    try:
        res = minimize(obj.value_and_grad, a0, jac=True, method="L-BFGS-B",
                       bounds=[(0.0, u) for u in prob.a_upper], options=opts)
    except _ForwardFailed as exc:
        return obj, False, f"forward solve failed: {exc}" + (
            f" ({obj.backoffs - 1} shorter step(s) failed before it)" if obj.backoffs > 1 else ""), obj.n_eval
    status = f"L-BFGS-B: {res.message}"
    if obj.failures:  # trial steps backed off: said, the design verified all the same
        status += f"; {len(obj.failures)} trial step(s) backed off: their forward solve failed ({obj.failures[-1]})"
    return obj, bool(res.success), status, int(res.nit)


def run_derivative_free(prob, a0, fwd, tol, max_iter, outer, outer_options, clock, length: float = 1.0):
    """The derivative-free search of ``a`` from ``a0`` (Nelder-Mead or Powell after ``outer``).

    Its stopping test means the same for a body in any units and any number of muscles: the contractions
    (fractions of a rest length) of the search's points agree within ``tol`` (the simplex's extent in
    every muscle for Nelder-Mead), and so do their differences (the rms node distance from the target, a
    length) within :data:`DIFF_ATOL` of the body's size (Nelder-Mead searches the difference as a share of
    the body's size, which orders its points as the objective ``J`` does: its moves are the same; Powell
    asks the objective's relative decrease per sweep to fall below :data:`POWELL_FTOL`). Both bounds lie
    above the noise of the warm-started forward solves (about ``1e-13`` of ``J`` at ``inner_tol = 1e-10``),
    which a test on ``J`` itself (``tol ** 2``) lay below: the search sat at its answer until the evaluation
    cap. A search that stops at the cap passes when its last points meet the test all the same; else it
    fails, its ``status`` saying how far apart they were.
    """
    from scipy.optimize import minimize

    obj = _Outer(prob, fwd, clock, length=length)
    bounds = [(0.0, u) for u in prob.a_upper]
    share = prob.h / body_size(prob.mesh)  # J -> the difference as a share of the body's size

    def fraction(a):
        J = obj.value(a)
        return J if J >= obj.penalty else share * math.sqrt(max(J, 0.0))

    if outer == "nelder-mead":
        opts = {"maxfev": max_iter, "maxiter": max_iter, "xatol": tol, "fatol": DIFF_ATOL, "adaptive": prob.m > 2}
        opts.update(outer_options or {})
        res = minimize(fraction, a0, method="Nelder-Mead", bounds=bounds, options=opts)
        ok = bool(res.success)
        if not ok and res.status in (1, 2):  # the cap: met the test on its last simplex all the same?
            sim, fsim = res.final_simplex
            dx, df = float(np.abs(sim[1:] - sim[0]).max()), float(np.abs(fsim[1:] - fsim[0]).max())
            ok = dx <= opts["xatol"] and df <= opts["fatol"]
            res.message += (f" (its last simplex met the test: contractions within {dx:.3g} <= xatol, differences "
                            f"within {df:.3g} <= fatol of the body's size)" if ok else
                            f" (its last simplex: contractions {dx:.3g} apart, xatol {opts['xatol']:.3g}; differences "
                            f"{df:.3g} of the body's size apart, fatol {opts['fatol']:.3g})")
    else:
        opts = {"maxfev": max_iter, "xtol": tol, "ftol": POWELL_FTOL}
        opts.update(outer_options or {})
        res = minimize(obj.value, a0, method="Powell", bounds=bounds, options=opts)
        ok = bool(res.success)
    ok = ok and not obj.failures
    status = f"{'Nelder-Mead' if outer == 'nelder-mead' else 'Powell'}: {res.message}"
    if obj.failures:
        status += f"; {len(obj.failures)} forward solve(s) failed ({obj.failures[-1]})"
    return obj, ok, status, int(res.nit)
