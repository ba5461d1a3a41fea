"""Equilibria of the quadratic-element body (:class:`~mdsr_opt.mechanics.quadratic.QuadraticModel`): external
driving, and ropes with capstan friction ending on rigid fixtures.

Both are solved by Newton's method on the equilibrium equations with load continuation:

* :func:`solve_quadratic_external`: anchors held, drag nodes moved along straight lines with the load
  fraction ``s``; unknowns the free coordinates; ``grad E = 0`` on them.
* :func:`solve_quadratic_internal`: ropes (:class:`~mdsr_opt.mechanics.capstan.CapstanRope`) pulled to
  ``(1 - s a_c) L0_c``; unknowns the reduced coordinates ``q`` of the body whose fixtures move rigidly
  (:class:`~mdsr_opt.mechanics.fixtures.RigidReduction`) less a three-coordinate gauge, and each rope's
  pulled-end tension ``tau_c``; equations ``P^T (grad E + sum_c tau_c sum_i w_ci grad l_ci) = 0`` and
  ``sum_i l_ci = (1 - s a_c) L0_c`` (DESIGN.md section 4). The capstan weights ``w_ci`` depend on the
  state through the path's turning; the Newton matrix includes that dependence
  (:meth:`~mdsr_opt.mechanics.capstan.CapstanRope.weight_coupling`). A rope that would push (``tau_c < 0``) goes slack: its
  equation is dropped and its tension set to 0 until its path is longer than the rope again.

Each load step is solved by :func:`~mdsr_opt.mechanics.dampednewton.damped_newton`: Newton steps damped by a
backtracking line search on the scaled residual that also refuses a state with an element inverted at a
quadrature point or a vertex, chord steps near the answer, a solve that creeps given up as stalled. A load step
that fails is halved (down to
``min_step``); the failure status names the element the last refused trial state inverted, if any. Success
means every scaled residual at most ``tol``: forces relative to ``|params| * size`` (the stiffness times the
body's size), rope lengths relative to ``L0``. Stability is not checked: the continuation
follows the branch from rest (internal driving: and past its end, another).

Internal driving: the branch from rest may end before the full load (a limit point, e.g. where a strip
compressed beside a strongly contracted rope, wrinkled one way, carries no more: no load step beyond
converges, however small). There the failed step's load is solved once more from the last equilibrium by pseudo-transient
continuation (:func:`~mdsr_opt.mechanics.pseudotransient.pseudo_transient`, at most
:data:`TRANSIENT_ITERATIONS` steps): the damped motion of the body to an equilibrium of another branch, from
which the stepping goes on; the status says at which load the branch from rest was left. When that solve
does not converge either, the failure says so.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..core.results import compact_repr, to_jsonable
from .align import align
from .capstan import CapstanRope, turning_angles
from .dampednewton import damped_newton
from .fixtures import RigidReduction
from .pseudotransient import pseudo_transient
from .quadratic import QuadraticModel
from .sparselu import PatternRestriction, ReusedOrdering

__all__ = ["QuadraticResult", "solve_quadratic_external", "solve_quadratic_internal"]


@dataclass(eq=False)
class QuadraticResult:
    """An equilibrium of :mod:`~mdsr_opt.mechanics.quadsolve`.

    Attributes
    ----------
    x : (N, 2) ndarray
        Node positions (vertices, then edge midpoints); internal driving: aligned to rest.
    success : bool
    status : str
    iterations : int
        Newton iterations over all load steps.
    steps : int
        Accepted load steps.
    residual : float
        The largest scaled residual at the returned state.
    tension, end_tension, turning : (c,) ndarray
        Internal driving: each rope's tension at its pulled end and at its far end, and its total turning
        angle (rad).
    slack : (c,) bool ndarray
    achieved, commanded : (c,) ndarray
        ``1 - L / L0`` of each rope's path; the contractions asked for.
    state : ndarray or None
        Internal driving, on success: the solver's unknowns (reduced coordinates in its gauge, tensions), to
        start another solve from (``start=``).
    """

    x: np.ndarray
    success: bool
    status: str
    iterations: int = 0
    steps: int = 0
    residual: float = float("nan")
    tension: np.ndarray = field(default_factory=lambda: np.zeros(0))
    end_tension: np.ndarray = field(default_factory=lambda: np.zeros(0))
    turning: np.ndarray = field(default_factory=lambda: np.zeros(0))
    slack: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    achieved: np.ndarray = field(default_factory=lambda: np.zeros(0))
    commanded: np.ndarray = field(default_factory=lambda: np.zeros(0))
    state: np.ndarray | None = None

    def __repr__(self) -> str:
        return compact_repr(self, ("success", "status", "iterations", "steps", "residual", "commanded", "achieved"))

    def to_dict(self) -> dict:
        """Every field as JSON-ready values (arrays as nested lists, NaN as None)."""
        return {f: to_jsonable(getattr(self, f)) for f in self.__dataclass_fields__}


class _Upright:
    """``model.upright`` of the node positions ``x_of(z)``, remembering the last state it refused: which
    element, inverted at a quadrature point or only at a vertex (a quadratic element whose curved edge
    folds), so that a failure can say why Newton's steps were refused."""

    def __init__(self, model: QuadraticModel, x_of: Callable):
        self.model, self.x_of, self.refused = model, x_of, None

    def __call__(self, z) -> bool:
        x = self.x_of(z)
        if self.model.upright(x):
            self.refused = None
            return True
        jq = self.model.jacobians(x).min(1)
        jv = self.model.vertex_jacobians(x).min(1)
        e = int(np.argmin(np.minimum(jq, jv)))
        self.refused = (e, "a quadrature point" if jq[e] <= 0.0 else "a vertex", self.model.elements[e][:3])
        return False

    def why(self) -> str:
        """Text for a failure status: the element the last refused trial state inverted, or ''."""
        if self.refused is None:
            return ""
        e, where, nodes = self.refused
        return (f"; the last trial step inverted element {e} (nodes {', '.join(str(int(k)) for k in nodes)}) "
                f"at {where}")


#: largest change of a contraction from a ``start`` result that is first tried in one Newton solve at the
#: full load (a larger change is stepped)
START_FULL_STEP = 0.05

#: most pseudo-transient steps of a solve past a limit point of the internal driving's load path
#: (:func:`~mdsr_opt.mechanics.pseudotransient.pseudo_transient`)
TRANSIENT_ITERATIONS = 200

#: scaled residual at which an intermediate load step is accepted (the last one meets ``tol``)
INTERMEDIATE_TOL = 1e-3


def _continue(solve_at: Callable, z0: np.ndarray, min_step: float, first_step: float = 0.25,
              secant: bool = True, snap: Callable | None = None):
    """Load continuation from ``s = 0`` (state ``z0``) to 1: ``solve_at(t, z_start, final, s) -> (z, converged,
    iterations, residual)`` for a step from the equilibrium at ``s`` to ``t`` (``final`` at ``t = 1``). Returns ``(z, s, converged, iterations, steps, residual, status)`` (``s`` the last
    load fraction reached). ``snap``: called as ``solve_at`` when a step fails at the smallest step (the branch
    from rest ends at a limit point): a solve that may reach an equilibrium at ``t`` of another branch (a
    pseudo-transient one); when it converges the stepping goes on from there and the status says where."""
    s, z, ds = 0.0, z0, first_step
    prev = None  # (s, z) of the step before, for a secant predictor
    iters = steps = 0
    res = 0.0
    snapped = []  # the load fractions whose limit point a snap passed
    while s < 1.0:
        t = min(1.0, s + ds)
        start = z
        if secant and prev is not None and s > prev[0]:  # else solve_at predicts from the state at s
            start = z + (t - s) / (s - prev[0]) * (z - prev[1])
        zt, conv, it, res = solve_at(t, start, t >= 1.0, s)
        if not conv and start is not z:  # the predictor overshot: from the last state
            zt, conv, it2, res = solve_at(t, z, t >= 1.0, s)
            it += it2
        iters += it
        if conv:
            prev, s, z = (s, z), t, zt
            steps += 1
            if it <= 6:
                ds = min(1.0, 1.5 * ds)
        else:  # half the step that failed (a step cut short at the end of the load, t = 1, halved
            ds = 0.5 * (t - s)  # from its own length: never the same failed step again)
            if ds < min_step:
                failed = (f"load step {s:.4g} -> {t:.4g} failed (residual {res:.3g}) with the smallest step "
                          f"{min_step:g}")
                if snap is None:
                    return z, s, False, iters, steps, res, failed
                zt, conv, it, res_t = snap(t, z, t >= 1.0, s)
                iters += it
                if not conv:
                    return z, s, False, iters, steps, res, (f"{failed}, and a pseudo-transient solve from there did "
                                                         f"not converge either (residual {res_t:.3g})")
                snapped.append(s)
                prev, s, z, res = None, t, zt, res_t  # a new branch: no secant across the snap
                steps += 1
                ds = min_step
    if snapped:
        at = ", ".join(f"{v:.4g}" for v in snapped)
        return z, s, True, iters, steps, res, (f"converged (the load steps from rest stalled at load {at}: passed "
                                               "by a pseudo-transient solve to another branch)")
    return z, s, True, iters, steps, res, "converged"


def _checks(tol, max_iter, min_step):
    tol = float(tol)
    if not (np.isfinite(tol) and 0.0 < tol < 1.0):
        raise ValueError(f"tol must lie in (0, 1), got {tol}")
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise ValueError(f"max_iter must be a positive integer, got {max_iter!r}")
    min_step = float(min_step)
    if not 0.0 < min_step <= 1.0:
        raise ValueError(f"min_step must lie in (0, 1], got {min_step}")
    return tol, int(max_iter), min_step


def _full_load_first(solve_at: Callable, near, z0: np.ndarray, min_step: float, s_from: float = 0.0,
                     on_fail: Callable[[], None] | None = None, first: dict | None = None, **continue_kw):
    """:func:`_continue`'s result: one Newton solve at the full load from ``near`` (``(unknowns, what they
    are)``, or None; ``solve_at``'s keywords ``first``), else, or when it fails (after ``on_fail()``), the
    load stepped from ``z0``; the iterations of both tries count."""
    tried = 0
    if near is not None:
        z, conv, tried, res = solve_at(1.0, near[0], True, s_from, **(first or {}))
        if conv:
            return z, 1.0, True, tried, 1, res, f"converged (from {near[1]})"
        if on_fail is not None:
            on_fail()
    done = _continue(solve_at, z0, min_step, **continue_kw)
    return done[:3] + (done[3] + tried,) + done[4:]


def _checked_guess(guess, n: int) -> np.ndarray | None:
    guess = None if guess is None else np.asarray(guess, dtype=float)
    if guess is not None and (guess.shape != (n, 2) or not np.isfinite(guess).all()):
        raise ValueError(f"guess must be finite node positions of shape ({n}, 2), got shape {guess.shape}")
    return guess


def _force_scale(model: QuadraticModel) -> float:
    return float(np.abs(model.params).max()) * float(model.mesh.size)


def solve_quadratic_external(model: QuadraticModel, anchors, drag_nodes, drag_positions, *, tol: float = 1e-9,
                             max_iter: int = 30, min_step: float = 1.0 / 256, guess=None) -> QuadraticResult:
    """External driving of ``model``: nodes ``anchors`` held at rest, ``drag_nodes`` moved to
    ``drag_positions`` (node indices of the model, midpoints included: see
    :func:`~mdsr_opt.mechanics.quadratic.extend_prescribed`). ``guess``: predicted node positions (N, 2) that
    start one Newton solve at the full load, as :func:`solve_quadratic_internal`'s (its own steps, unshifted).

    Raises
    ------
    ValueError
        Node indices out of range or given twice, positions of the wrong shape or not finite, fewer than two
        fixed nodes, a guess of the wrong shape or not finite, or bad ``tol``, ``max_iter``, ``min_step``.
    """
    if not isinstance(model, QuadraticModel):
        raise TypeError(f"model must be a QuadraticModel, got {type(model).__name__}")
    tol, max_iter, min_step = _checks(tol, max_iter, min_step)
    n = model.n_nodes
    guess = _checked_guess(guess, n)
    anc = np.asarray(anchors, dtype=np.int64).ravel()
    dn = np.asarray(drag_nodes, dtype=np.int64).ravel()
    dp = np.asarray(drag_positions, dtype=float).reshape(-1, 2)
    fixed_nodes = np.concatenate([anc, dn])
    if len(dp) != len(dn):
        raise ValueError(f"{len(dn)} drag node(s) but {len(dp)} position(s)")
    if not np.isfinite(dp).all():
        raise ValueError("drag positions must be finite")
    if len(fixed_nodes) < 2 or len(np.unique(fixed_nodes)) != len(fixed_nodes):
        raise ValueError("external driving needs at least two fixed nodes (anchors + drags), each given once")
    if fixed_nodes.min() < 0 or fixed_nodes.max() >= n:
        raise ValueError(f"node indices must lie in [0, {n})")
    X = model.points.reshape(-1)
    fixed = np.zeros(2 * n, dtype=bool)
    fixed[np.concatenate([2 * fixed_nodes, 2 * fixed_nodes + 1])] = True
    free = np.flatnonzero(~fixed)
    target = X.copy()
    target[np.concatenate([2 * dn, 2 * dn + 1])] = np.concatenate([dp[:, 0], dp[:, 1]])
    fs = _force_scale(model)

    def full(s, z):
        x = X + s * (target - X)
        x[free] = z
        return x

    fixed_idx = np.flatnonzero(fixed)
    order = ReusedOrdering()
    guard = [None]  # the inversion check of the latest load step, to say why a failed one was refused
    K_rest = model.evaluate(X, energy=False)[2]
    ff, fc = PatternRestriction(K_rest, free, free), PatternRestriction(K_rest, free, fixed_idx)

    def solve_at(t, z0, final, s):
        def system(z, jac):
            x = full(t, z)
            if jac:
                _e, g, K = model.evaluate(x, energy=False)
                Kff = ff(K)
                Kff.data /= fs
                return g[free] / fs, Kff
            return model.gradient(x)[free] / fs, None

        ok = _Upright(model, lambda z: full(t, z))
        guard[0] = ok

        # tangent predictor from the equilibrium at s: K_ff dz = -K_fc (x_c(t) - x_c(s)); none for a start at t
        K = K_rest if s == 0.0 else model.evaluate(full(s, z0), energy=False)[2] if s < t else None
        try:
            dz = order.solve(ff(K), -(fc(K) @ ((t - s) * (target - X)[fixed_idx]))) if K is not None else 0 * z0
        except RuntimeError:
            dz = np.zeros_like(z0)
        for frac in (1.0, 0.5, 0.25, 0.0):
            if ok(z0 + frac * dz):
                break
        return damped_newton(system, z0 + frac * dz, ok, tol if final else max(tol, INTERMEDIATE_TOL), max_iter, order)

    # a start at the full load from the guess (no predictor: from s = 1), else load steps
    near = None if guess is None else (guess.reshape(-1)[free], "the predicted state")
    z, s, conv, iters, steps, res, status = _full_load_first(solve_at, near, X[free], min_step, 1.0, secant=False)
    if not conv and guard[0] is not None:
        status += guard[0].why()
    x = full(s, z)
    return QuadraticResult(x=x.reshape(-1, 2), success=bool(conv), status=status, iterations=iters, steps=steps,
                           residual=float(res))


def _pull_back(red: RigidReduction, q: np.ndarray, gx: np.ndarray) -> np.ndarray:
    """``P^T gx`` (``P = red.jacobian(q)``) without forming ``P``: a gradient in the node coordinates carried
    to the reduced coordinates (an own node's two, a fixture's reference node and angle)."""
    g = np.asarray(gx, dtype=float).reshape(-1, 2)
    out = np.zeros(red.n_q)
    own, f = red.own, red.followers
    out[red.q_index[own]] = g[own, 0]
    out[red.q_index[own] + 1] = g[own, 1]
    if len(f):
        ref = red.refs[red.member[f]]
        out += np.bincount(red.q_index[ref], g[f, 0], red.n_q) + np.bincount(red.q_index[ref] + 1, g[f, 1], red.n_q)
        x = red.x_of(q)
        arm = x[f] - x[ref]
        out[2 * len(own):] += np.bincount(red.member[f], arm[:, 0] * g[f, 1] - arm[:, 1] * g[f, 0], red.n_angles)
    return out


def _gauge(red: RigidReduction) -> np.ndarray:
    """Three reduced coordinates that fix the rigid motion: an own node near the centroid (x and y) and one
    coordinate of the own node farthest from it (across the line joining them)."""
    X = red.X
    own = red.own if len(red.own) >= 2 else np.arange(red.n)
    c = X.mean(0)
    i = int(own[np.lexsort((X[own, 1], X[own, 0], np.linalg.norm(X[own] - c, axis=1)))[0]])
    j = int(own[np.lexsort((X[own, 1], X[own, 0], -np.linalg.norm(X[own] - X[i], axis=1)))[0]])
    v = X[j] - X[i]
    comp = 1 if abs(v[0]) >= abs(v[1]) else 0
    return np.array([red.q_index[i], red.q_index[i] + 1, red.q_index[j] + comp])


def _onto_gauge(red: RigidReduction, gauge, y: np.ndarray) -> np.ndarray | None:
    """The state ``y`` (N, 2) moved rigidly so that its gauge coordinates (:func:`_gauge`) are those of rest;
    None when no rigid motion does (the two gauge nodes' distance too short for the fixed component)."""
    X = red.X
    i, j = int(np.flatnonzero(red.q_index == gauge[0])[0]), int(np.flatnonzero(red.q_index == gauge[2] - (gauge[2] % 2))[0])
    comp = int(gauge[2] % 2)
    d, D = y[j] - y[i], X[j] - X[i]
    rho, phi = float(np.hypot(*d)), float(np.arctan2(d[1], d[0]))
    ratio = D[comp] / rho if rho > 0 else 2.0
    if abs(ratio) > 1.0:
        return None
    if comp == 1:  # rho sin(theta + phi) = D_y, with the x component of D's sign
        psi = np.arcsin(ratio)
        psi = psi if D[0] >= 0 else np.pi - psi
    else:          # rho cos(theta + phi) = D_x, with the y component of D's sign
        psi = np.arccos(ratio)
        psi = psi if D[1] >= 0 else -psi
    th = psi - phi
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    return (y - y[i]) @ R.T + X[i]


def _rigid_extension(model, red: RigidReduction, x: np.ndarray, xr: np.ndarray) -> np.ndarray | None:
    """A predicted state ``x`` whose fixtures were made rigid (``xr``: the fixtures' nodes moved, the rest
    as in ``x``), with the fixtures' move carried into the body: the other nodes displaced by the linear
    elastic response of the body at ``x`` to the fixtures' displacement (``K_oo d_o = -K_of d_f``), so that
    the elements at a fixture's rim follow it instead of folding. None when the result still has an
    inverted element."""
    moved = np.zeros(red.n, dtype=bool)
    moved[red.followers] = True
    moved[red.refs] = True  # each fixture whole: its reference node with its followers
    fixed = np.repeat(moved, 2)
    d = (xr - x).reshape(-1)
    K = sp.csr_matrix(model.evaluate(x, energy=False)[2])
    free = np.flatnonzero(~fixed)
    f_idx = np.flatnonzero(fixed)
    try:  # an exactly singular matrix (a body the fixtures do not hold) raises
        dfree = spla.splu(K[free][:, free].tocsc()).solve(-(K[free][:, f_idx] @ d[f_idx]))
    except RuntimeError:
        return None
    if not np.isfinite(dfree).all():
        return None
    out = x.reshape(-1).copy()
    out[f_idx] = xr.reshape(-1)[f_idx]
    out = out.reshape(-1, 2)
    for frac in (1.0, 0.5):  # the full elastic response, or half of it when that overshoots
        y = out.reshape(-1).copy()
        y[free] += frac * dfree
        y = y.reshape(-1, 2)
        if model.upright(y):
            return y
    return None


def _predicted_unknowns(model, red: RigidReduction, gauge, keep, ropes, guess, fs):
    """The unknowns of :func:`solve_quadratic_internal` for a predicted state ``guess`` (N, 2): the state
    moved rigidly onto the gauge (its gauge coordinates those of rest), its fixtures made rigid (best-fit
    angles), and each rope's tension the least-squares balance of the elastic force. None when the moved
    state has an inverted element."""
    x = _onto_gauge(red, gauge, guess)
    if x is None:
        return None
    q = red.q_of(x)
    xr = red.x_of(q)
    if not model.upright(xr):  # made rigid at its fixtures, the state folds at their rim: carry the
        xr = _rigid_extension(model, red, x, xr)  # fixtures' correction into the body elastically,
        xr = None if xr is None else _onto_gauge(red, gauge, xr)  # and onto the gauge again
        if xr is None:
            return None
        q = red.q_of(xr)
        xr = red.x_of(q)
        if not model.upright(xr):
            return None
    x = xr
    P = red.jacobian(q)
    gq = (P.T @ model.gradient(x))[keep]
    C = np.column_stack([(P.T @ r.forces(x, r.weights(x), model.n_nodes)[0])[keep] for r in ropes])
    tau = np.maximum(np.linalg.lstsq(C, -gq, rcond=None)[0], 0.0)
    return np.concatenate([q[keep], tau])


def solve_quadratic_internal(model: QuadraticModel, ropes: Sequence[CapstanRope], contractions,
                             fixtures: Sequence[np.ndarray] = (), *, tol: float = 1e-9, max_iter: int = 30,
                             min_step: float = 1.0 / 256, align_to_rest: bool = True,
                             start: QuadraticResult | None = None, guess=None) -> QuadraticResult:
    """Internal driving of ``model`` by ``ropes`` (chains of its nodes, pulled at their first node, with
    capstan friction) contracted by ``contractions`` (fractions of their rest lengths), the nodes of each of
    ``fixtures`` (disjoint node groups, an end node first: see
    :func:`~mdsr_opt.mechanics.fixtures.fixture_groups`) moving rigidly. With ``start`` (an earlier result of
    the same model, ropes and fixtures) the contractions are stepped from its contractions and state instead
    of from rest (contractions within :data:`START_FULL_STEP` of its own: first one Newton solve from its
    state at the full load). With ``guess`` (node positions (N, 2) predicted for ``contractions``, e.g. a coarser model's
    equilibrium interpolated onto these nodes) Newton's method starts there at the full load, with a
    pseudo-transient shift that damps its first steps (``shifted`` of
    :func:`~mdsr_opt.mechanics.dampednewton.damped_newton`); when it does not converge (or the predicted
    state has an inverted element) the load is stepped as without it. The result
    is the same equilibrium to ``tol`` when the prediction lies in its basin (``iterations`` counts both tries).

    Raises
    ------
    ValueError
        No rope, a rope node out of range, contractions not one per rope in ``[0, 1)``, overlapping fixtures,
        or bad ``tol``, ``max_iter``, ``min_step``.
    """
    if not isinstance(model, QuadraticModel):
        raise TypeError(f"model must be a QuadraticModel, got {type(model).__name__}")
    tol, max_iter, min_step = _checks(tol, max_iter, min_step)
    guess = _checked_guess(guess, model.n_nodes)
    ropes = list(ropes)
    if not ropes or not all(isinstance(r, CapstanRope) for r in ropes):
        raise ValueError("internal driving needs at least one CapstanRope")
    n = model.n_nodes
    for r in ropes:
        if r.chain.max() >= n:
            raise ValueError(f"rope node {int(r.chain.max())} out of range for {n} nodes")
    a = np.asarray(contractions, dtype=float).ravel()
    if len(a) != len(ropes) or not np.isfinite(a).all() or (a < 0).any() or (a >= 1).any():
        raise ValueError(f"contractions must be one value in [0, 1) per rope ({len(ropes)}), got {a.tolist()}")
    red = RigidReduction(model.points, fixtures)
    gauge = _gauge(red)
    keep = np.setdiff1d(np.arange(red.n_q), gauge)
    nk = len(keep)
    select = sp.csr_matrix((np.ones(nk), (keep, np.arange(nk))), shape=(red.n_q, nk))  # z -> q (gauge left out)
    order = ReusedOrdering()
    X = model.points
    L0 = np.array([r.length(X) for r in ropes])
    q_rest = red.rest_q()
    nc = len(ropes)
    fs = _force_scale(model)
    active = np.ones(nc, dtype=bool)  # a slack rope's equation is tau_c = 0
    guard = [None]  # the inversion check of the latest load step, to say why a failed one was refused

    def split(z):
        q = q_rest.copy()
        q[keep] = z[:nk]
        return q, z[nk:]

    def solve_at(s, z0, final, _s_from, shifted=False, transient=False):
        targets = (1.0 - (a0 + s * (a - a0))) * L0
        tol_s = tol if final else max(tol, INTERMEDIATE_TOL)

        def system(z, jac):
            q, tau = split(z)
            x = red.x_of(q)
            if jac:
                _e, gx, Kx = model.evaluate(x, energy=False)
            else:
                gx, Kx = model.gradient(x), None
            cols, rows, res_c = [], [], np.zeros(nc)
            Kr = None  # the ropes' stiffness, added to the body's once
            for c, rope in enumerate(ropes):
                if not active[c]:
                    res_c[c] = tau[c]
                    cols.append(np.zeros(2 * n))
                    rows.append(np.zeros(2 * n))
                    continue
                f, g, H = rope.forces(x, rope.weights(x), n)
                gx = gx + tau[c] * f
                res_c[c] = (rope.length(x) - targets[c]) / L0[c]
                if jac:
                    Hc = tau[c] * (H + rope.weight_coupling(x, n))
                    Kr = Hc if Kr is None else Kr + Hc
                    cols.append(f)
                    rows.append(g / L0[c])
            if not jac:  # a line search's trial: the residual alone
                return np.concatenate([_pull_back(red, q, gx)[keep] / fs, res_c]), None
            if Kr is not None:
                Kx = Kx + Kr
            P = red.jacobian(q) @ select  # dx / dz over the kept coordinates
            rq = np.concatenate([(P.T @ gx) / fs, res_c])
            PT = P.T.tocsr()
            Kq = ((PT @ (Kx @ P) + select.T @ red.curvature(q, gx) @ select) / fs).tocoo()
            C = (PT @ np.column_stack(cols)) / fs                          # tension columns (nk, nc)
            R = (PT @ np.column_stack(rows)).T                             # rope length rows (nc, nk)
            ci, cj = np.nonzero(C)
            ri, rj = np.nonzero(R)
            slack = np.flatnonzero(~active)                               # tau_c = 0 for a slack rope
            J = sp.coo_matrix((np.concatenate([Kq.data, C[ci, cj], R[ri, rj], np.ones(len(slack))]),
                               (np.concatenate([Kq.row, ci, nk + ri, nk + slack]),
                                np.concatenate([Kq.col, nk + cj, rj, nk + slack]))), shape=(nk + nc, nk + nc))
            return rq, J

        ok = _Upright(model, lambda z: red.x_of(split(z)[0]))
        guard[0] = ok

        if transient:
            z, conv, it, res = pseudo_transient(system, z0, ok, tol_s, max(max_iter, TRANSIENT_ITERATIONS), nk, order)
        else:
            z, conv, it, res = damped_newton(system, z0, ok, tol_s, max_iter, order, nk if shifted else 0)
        for _ in range(3):  # ropes that push go slack; slack ropes pulled taut again take up the load
            if not conv:
                break
            q, tau = split(z)
            x = red.x_of(q)
            lengths = np.array([r.length(x) for r in ropes])
            new = active.copy()
            new[active & (tau < 0)] = False
            new[~active & (lengths > targets * (1 + tol))] = True
            if (new == active).all():
                break
            active[:] = new
            z = np.concatenate([z[:nk], np.where(active, np.maximum(tau, 0.0), 0.0)])
            z, conv, it2, res = damped_newton(system, z, ok, tol_s, max_iter, order)
            it += it2
        return z, conv, it, res

    z0 = np.concatenate([q_rest[keep], np.zeros(nc)])
    a0 = np.zeros(nc)
    if start is not None:  # a solved state of the same ropes and fixtures: continue from its contractions
        if not isinstance(start, QuadraticResult) or start.state is None or len(start.state) != len(z0) \
                or len(start.commanded) != nc:
            raise ValueError("start must be a QuadraticResult of solve_quadratic_internal with the same model, "
                             "ropes and fixtures")
        z0, a0 = start.state.copy(), start.commanded.copy()
    # one Newton solve at the full load from a state near the answer, when there is one (contractions near the
    # start's, or a predicted state from the guess); load steps when there is none or it fails
    near = None
    if guess is not None:
        zg = _predicted_unknowns(model, red, gauge, keep, ropes, guess, fs)
        near = None if zg is None else (zg, "the predicted state")
    elif start is not None and np.abs(a - a0).max() <= START_FULL_STEP:
        near = (z0, "the start state")
    # from a predicted state (far from the answer: another model's equilibrium) with the pseudo-transient
    # shift; from a start state (a solve of nearly these contractions) Newton's own steps
    z, _s, conv, iters, steps, res, status = _full_load_first(
        solve_at, near, z0, min_step, on_fail=lambda: active.fill(True), first={"shifted": guess is not None},
        snap=lambda t, zs, final, s: solve_at(t, zs, final, s, transient=True))
    if not conv and guard[0] is not None:
        status += guard[0].why()
    q, tau = split(z)
    x = red.x_of(q)
    turn = np.array([turning_angles(x, r.chain)[-1] for r in ropes])
    w_end = np.array([r.weights(x)[-1] for r in ropes])
    L = np.array([r.length(x) for r in ropes])
    if align_to_rest:
        x = align(x, X).apply(x)
    return QuadraticResult(x=x, success=bool(conv), status=status, iterations=iters, steps=steps,
                           residual=float(res), tension=tau.copy(), end_tension=tau * w_end, turning=turn,
                           slack=~active, achieved=1.0 - L / L0, commanded=a.copy(),
                           state=z.copy() if conv else None)
