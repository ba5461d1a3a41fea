"""External and internal driving: equilibria of a soft body, with load stepping and a linear-elastic guess.

``solve_external`` holds anchors at rest and drags nodes to prescribed positions; the rest settle at
minimum strain energy. ``solve_internal`` contracts muscles in a free body (three gauge coordinates pinned,
which carry no load because muscle forces are self-equilibrated) and returns the state rigidly aligned to
the rest shape.

Both start from a Newton predictor (at rest it is the linear-elastic solution) and, when the predictor
would invert an element or the solver fails, step the load: drags or contractions are applied in
fractions that adapt (halving on failure, doubling on success). A returned state never has an inverted
element; a failure is reported in the result (``success=False``, ``status``, ``iterations``,
``residual``) and raised only by :meth:`EquilibriumResult.raise_on_failure`.

Example
-------
>>> from mdsr_opt import Mesh, NeoHookean, solve_external
>>> mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
>>> left = [i for i, (x, y) in enumerate(mesh.points) if x == 0.0]
>>> right = {i: (x + 1.0, y) for i, (x, y) in enumerate(mesh.points) if x == 4.0}
>>> res = solve_external(mesh, NeoHookean(E=1.0, nu=0.3), anchors=left, drags=right)
>>> res.success, res.min_J > 0
(True, True)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
import scipy.sparse.linalg as spla

from ._checks import as_float_array, as_index_array, positive_float
from .align import align
from .backends import available_backends, check_backend, interruptible, minimize
from .drags import RigidDrag, drag_path
from .stability import check_stability
from .mesh import Mesh
from .backends import CONSTRAINED_BACKENDS, supports_constraints
from .model import get_model, spring_parameters
from .constrained import ConstrainedModel
from .muscle_constraints import (MuscleConstraints, check_anchor_radius, rigid_groups, spring_segments,
                                 spring_stiffness)
from .muscles import Muscle, check_contractions, check_muscles

__all__ = ["EquilibriumResult", "SolverFailure", "solve_external", "solve_internal", "available_backends",
           "external_stability"]


class SolverFailure(RuntimeError):
    """Raised by :meth:`EquilibriumResult.raise_on_failure` when a solve did not succeed."""


@dataclass
class EquilibriumResult:
    """The outcome of an equilibrium solve.

    Attributes
    ----------
    x : (n, 2) deformed node positions (the last accepted state if the solve failed).
    energy : total energy at ``x`` (elastic plus muscle springs).
    elastic_energy : strain energy of the body alone.
    success : solver converged, residual small and no element inverted.
    status : solver status text (or the reason for failure).
    iterations : solver iterations summed over load steps.
    residual : max-norm of the energy gradient over the free coordinates, relative to ``E t size``; with
        muscle constraints that of the Lagrangian (least-squares multipliers): the KKT residual.
    min_J : smallest element ``det F``.
    steps : load fractions accepted (``[1.0]`` when no stepping was needed).
    build_time, solve_time : seconds spent building the model/solver (0 when reused) and solving.
    commanded, achieved, stroke, tension, slack, rest_lengths : internal driving, one entry per muscle: the
        contraction asked; the contraction reached, ``1 - L/L0`` with ``L`` the node chain's length in ``x``;
        the stroke ``achieved * L0`` (length units, what a servo winds in); the tension (cable: the rope
        constraint's multiplier, never negative; springs: the springs' mean force
        ``K L0/L0_free (a - achieved)``, negative when they push); slack (cable: the path is shorter than the
        rope, so achieved > commanded at zero tension; springs: not pulling); ``L0``.
    anchor_radius : internal driving: the radius of the rigid anchor patches at the muscles' ends.
    """

    x: np.ndarray
    energy: float
    elastic_energy: float
    success: bool
    status: str
    iterations: int
    residual: float
    min_J: float
    steps: list = field(default_factory=list)
    build_time: float = 0.0
    solve_time: float = 0.0
    backend: str = "ipopt"
    mode: str = "external"
    rotation: np.ndarray | None = None  # internal driving: rotation applied to align with rest
    translation: np.ndarray | None = None
    muscle_model: str | None = None  # internal driving: "springs" or "cable"
    stable: bool | None = None  # the free (reduced) Hessian is positive definite; None when not checked
    stability: dict | None = None  # StabilityCheck.summary(): n_negative, n_zero, curvature, method, time
    # internal driving, per muscle (see solve_internal):
    commanded: np.ndarray | None = None  # contraction asked
    achieved: np.ndarray | None = None  # 1 - L/L0 along the node chain in the returned state
    stroke: np.ndarray | None = None  # achieved * L0 (length units): the rope length taken in
    tension: np.ndarray | None = None  # rope tension (cable: the multiplier; springs: the rod force)
    slack: np.ndarray | None = None  # cable: path shorter than the rope (achieved > commanded); springs: not pulling
    rest_lengths: np.ndarray | None = None  # L0 per muscle
    anchor_radius: float | None = None  # radius of the rigid anchor patches at the muscles' ends

    def raise_on_failure(self) -> "EquilibriumResult":
        if not self.success:
            raise SolverFailure(f"{self.mode} driving with backend {self.backend!r} failed: {self.status} "
                                f"(iterations {self.iterations}, residual {self.residual:.3g}, "
                                f"min J {self.min_J:.3g})")
        return self

    def summary(self) -> dict:
        out = {"mode": self.mode, "backend": self.backend, "success": self.success, "status": self.status,
               "iterations": self.iterations, "energy": self.energy, "residual": self.residual,
               "min_J": self.min_J, "n_steps": len(self.steps), "build_time": self.build_time,
               "solve_time": self.solve_time, "stable": self.stable}
        if self.achieved is not None:
            out.update(muscle_model=self.muscle_model, anchor_radius=self.anchor_radius,
                       **{k: [float(v) if k != "slack" else bool(v) for v in getattr(self, k)]
                          for k in ("commanded", "achieved", "stroke", "tension", "slack")})
        return out


# ---------------------------------------------------------------------------------- input checks
def _check_mesh_material(mesh, material):
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a mdsr_opt.Mesh, got {type(mesh).__name__}")
    if not hasattr(material, "psi_expr") or not hasattr(material, "params"):
        raise TypeError(f"material must be a material such as NeoHookean, got {type(material).__name__}")


def _parse_drags(drags, n) -> tuple[np.ndarray, np.ndarray]:
    """``(indices, final positions (k, 2))`` of ``drags``; ``n`` is the mesh (or its node count when no drag
    is a :class:`~mdsr_opt.drags.RigidDrag`, whose final positions depend on the rest positions)."""
    if isinstance(n, Mesh):
        path = drag_path(drags, n)
    else:
        path = drag_path(drags, _NodeCount(int(n)))
        if any(isinstance(how, RigidDrag) for _, how in path.parts):
            raise ValueError("rigid drags need the mesh: use mdsr_opt.drags.drag_path(drags, mesh)")
    return path.nodes, path.final


class _NodeCount:
    """Stands in for a mesh when only the node count is known (rest positions unused by straight drags)."""

    def __init__(self, n):
        self.n_nodes = n
        self.points = np.zeros((n, 2))


def _check_common(tol, max_iter, backend, min_step=None):
    tol = positive_float(tol, "tol")
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise ValueError(f"max_iter must be a positive integer, got {max_iter!r}")
    check_backend(backend)
    if min_step is not None:
        _check_min_step(min_step)
    return tol


def _check_min_step(min_step) -> float:
    """``min_step`` must be a number in (0, 1]: 0, NaN or a negative value would let load stepping halve
    its step forever."""
    if isinstance(min_step, bool) or not isinstance(min_step, (int, float, np.integer, np.floating)):
        raise TypeError(f"min_step must be a number in (0, 1], got {type(min_step).__name__}")
    if not (np.isfinite(min_step) and 0.0 < min_step <= 1.0):
        raise ValueError(f"min_step must be in (0, 1] (the smallest load fraction tried), got {min_step!r}")
    return float(min_step)


def _initial_guess(initial_guess, mesh) -> tuple[bool, np.ndarray]:
    """``(predict, x_start)`` for ``initial_guess`` = ``"predictor"``, ``"rest"`` or an (n, 2) state."""
    X = mesh.points.reshape(-1).copy()
    if isinstance(initial_guess, str):
        if initial_guess not in ("predictor", "rest"):
            raise ValueError("initial_guess must be 'predictor', 'rest' or an (n, 2) array, "
                             f"got {initial_guess!r}")
        return initial_guess == "predictor", X
    x0 = mesh._check_state(initial_guess)
    if _min_J(mesh, x0.reshape(-1)) <= 0.0:
        raise ValueError("initial_guess inverts an element (det F <= 0)")
    return False, np.array(x0, dtype=float).reshape(-1)


# ---------------------------------------------------------------------------------- core loop
def _factor(model, p, x, fixed):
    """Hessian blocks at ``x`` and an LU of the free block; cached for the rest state, whose factors every
    repeated solve of a scene with new drags (same fixed nodes, same parameters) shares."""
    at_rest = np.array_equal(x, model.mesh.points.reshape(-1))
    key = (fixed.tobytes(), np.asarray(p, dtype=float).tobytes()) if at_rest else None
    cache = model.__dict__.setdefault("_rest_factors", {})
    if key is not None and key in cache:
        return cache[key]
    free = ~fixed
    H = model.hessian(x, p)
    Hff = H[free][:, free].tocsc()
    # symmetric mode with a minimum-degree ordering: about twice as fast as spsolve's default here
    lu = spla.splu(Hff, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    out = (H[free][:, fixed].tocsr(), lu)
    if key is not None:
        if len(cache) >= 8:
            cache.pop(next(iter(cache)))
        cache[key] = out
    return out


def _predict(model, p, x, fixed, values):
    """Newton step from ``x`` with the fixed coordinates moved to ``values``: the linear-elastic solution at rest."""
    if hasattr(model, "predict"):  # a constrained model linearises its constraints too (a KKT step)
        return model.predict(p, x, fixed, values)
    free = ~fixed
    try:
        Hfc, lu = _factor(model, p, x, fixed)
    except RuntimeError:  # singular: e.g. a free island of nodes
        return None
    g = model.gradient(x, p)
    dz = lu.solve(-(g[free] + Hfc @ (values - x[fixed])))
    if not np.all(np.isfinite(dz)):
        return None
    y = x.copy()
    y[free] += dz
    y[fixed] = values
    return y


def _min_J(mesh, xflat):
    return float(mesh.jacobians(xflat.reshape(-1, 2)).min())


def _continuation(mesh, model, p_of, fixed, values_of, x_start, backend, tol, max_iter, options, min_step,
                  verbose, predict=True):
    """Apply the load fraction ``s`` from 0 to 1 adaptively; returns (x, status, success, iters, steps, time).

    With ``predict=False`` each load step starts from the current state with the fixed coordinates moved
    (no Newton predictor): the "poor first guess" of the comparison studies. At full load the state must be
    stable (:func:`_settle`): a saddle is left along its negative curvature, or the solve fails. A SIGINT
    raises :class:`KeyboardInterrupt` (never a failed step)."""
    min_step = _check_min_step(min_step)
    with interruptible():
        x = x_start.copy()
        s, ds = 0.0, 1.0
        steps, iters, t_solve, t_build = [], 0, 0.0, 0.0
        status = "not started"
        while s < 1.0 - 1e-12:
            if ds < min_step:
                return (x, f"load stepping stalled at fraction {s:.4g} ({status})", False, iters, steps, t_solve,
                        t_build)
            s_new = min(1.0, s + ds)
            p = p_of(s_new)
            vals = values_of(s_new)
            t0 = time.perf_counter()
            if predict:
                guess = _predict(model, p, x, fixed, vals)
            else:
                guess = x.copy()
                guess[fixed] = vals
            t_solve += time.perf_counter() - t0
            if guess is None or _min_J(mesh, guess) <= 0.0:
                status = "predictor inverted an element" if predict else "first guess inverts an element"
                ds /= 2
                continue
            out = minimize(model, p, guess, fixed, vals, backend=backend, tol=tol, max_iter=max_iter,
                           options=options)
            iters += out.iterations
            t_solve += out.solve_time
            t_build += out.build_time
            status = out.status
            if out.success and np.all(np.isfinite(out.x)) and _min_J(mesh, out.x) > 0.0:
                x, s = out.x, s_new
                steps.append(s)
                if verbose:
                    print(f"  load {s:.4f}: {out.status}, {out.iterations} iterations")
                ds = min(2 * ds, 1.0 - s) if s < 1.0 else ds
            else:
                ds /= 2
        x, note, ok, it, t = _settle(mesh, model, p_of(1.0), fixed, values_of(1.0), x, backend, tol, max_iter,
                                     options, verbose)
    return x, status + note, ok, iters + it, steps, t_solve + t, t_build


#: saddle escape: re-solves from perturbed states, and the perturbation's largest node move / body size
_RESTARTS = 4
_KICK = 0.02


def _stability_at(model, p, xflat, fixed):
    """:class:`~mdsr_opt.stability.StabilityCheck` of the equilibrium ``xflat`` with ``fixed`` coordinates.

    For a model with muscle constraints, the Hessian of the Lagrangian (least-squares multipliers) on the
    tangent space of the active rows (rigid patches, taut ropes). The last check is cached on the model, so
    the solve and its result share one factorisation."""
    pk = np.concatenate(model.split(p)[:2]) if hasattr(model, "split") else p  # multipliers are refitted
    key = (np.asarray(xflat, dtype=float).tobytes(), np.asarray(pk, dtype=float).tobytes(), fixed.tobytes())
    cached = model.__dict__.get("_last_stability")
    if cached is not None and cached[0] == key:
        return cached[1]
    A = None
    if hasattr(model, "multipliers"):  # a ConstrainedModel
        lam, taut = model.multipliers(xflat, p, fixed)
        pe, targets, _ = model.split(p)
        H = model.hessian(xflat, model.params(pe, targets if model.n_targets else None, lam))
        active = np.ones(model.n_rows, dtype=bool)
        active[:model.n_targets] = taut
        if active.any():
            A = model.jacobian(xflat)[active]
    else:
        H = model.hessian(xflat, p)
    chk = check_stability(H, ~fixed, A)
    model.__dict__["_last_stability"] = (key, chk)
    return chk


def _kick(mesh, model, p, x, direction, scale=1.0):
    """``x`` moved along ``+-direction`` by ``_KICK`` x the body size at the largest node move (smaller if an
    element would invert), on the side of lower energy; None when no such state keeps every element upright."""
    d = direction.reshape(-1, 2)
    amp = scale * _KICK * mesh.size / max(float(np.linalg.norm(d, axis=1).max()), 1e-300)
    best = None
    for sign in (1.0, -1.0):
        a = amp
        for _ in range(8):
            y = x + sign * a * direction
            if _min_J(mesh, y) > 0.0:
                e = model.energy(y, p)
                if np.isfinite(e) and (best is None or e < best[0]):
                    best = (e, y)
                break
            a /= 2
    return None if best is None else best[1]


def _settle(mesh, model, p, fixed, values, x, backend, tol, max_iter, options, verbose):
    """Only a stable equilibrium is a success: at a saddle, step along its negative curvature and re-solve.

    Returns ``(x, status note, success, iterations, seconds)``."""
    t0 = time.perf_counter()
    chk = _stability_at(model, p, x, fixed)
    iters, tries, scale = 0, 0, 1.0
    while not chk.stable and tries < _RESTARTS and chk.direction is not None:
        tries += 1
        y = _kick(mesh, model, p, x, chk.direction, scale)
        if y is None:
            break
        out = minimize(model, p, y, fixed, values, backend=backend, tol=tol, max_iter=max_iter, options=options)
        iters += out.iterations
        if not (out.success and np.all(np.isfinite(out.x)) and _min_J(mesh, out.x) > 0.0):
            scale /= 2  # keep x and try a smaller kick
            continue
        if verbose:
            print(f"  left a saddle (curvature {chk.curvature:.3g}): {out.status}, {out.iterations} iterations")
        x = out.x
        chk = _stability_at(model, p, x, fixed)
    t = time.perf_counter() - t0
    if chk.stable:
        note = f"; left a saddle along its negative curvature ({tries} re-solve(s))" if tries else ""
        return x, note, True, iters, t
    what = (f"a saddle: {chk.n_negative} direction(s) of negative curvature (lowest {chk.curvature:.3g})"
            if chk.n_negative else f"{chk.n_zero} zero-curvature direction(s)")
    return (x, f"; rejected: not a stable equilibrium ({what}); {tries} re-solve(s) from perturbed states "
               f"found no stable state", False, iters, t)


def _result(mesh, model, material, p, p_elastic, xflat, fixed, status, success, iters, steps, t_build, t_solve,
            backend, mode, tol_residual=1e-5):
    if hasattr(model, "grad_fn"):  # an EnergyModel: energy and gradient from one call
        f, g = model.grad_fn(xflat, p)
        energy, g = float(f), np.asarray(g).ravel()
    else:
        g, energy = model.gradient(xflat, p), model.energy(xflat, p)
    scale = material.E * material.thickness * mesh.size
    residual = float(np.abs(g[~fixed]).max()) / scale if (~fixed).any() else 0.0
    mj = _min_J(mesh, xflat)
    ok = bool(success and mj > 0 and residual <= tol_residual)
    if success and not ok:
        status = f"{status}; rejected: residual {residual:.3g}, min J {mj:.3g}"
    chk = None
    if ok or "not a stable equilibrium" in status:  # the continuation's check (cached), or a fresh one
        chk = _stability_at(model, p, xflat, fixed)
        if ok and not chk.stable:
            ok = False
            status = f"{status}; rejected: not a stable equilibrium ({chk.n_negative} negative, {chk.n_zero} " \
                     "zero curvature directions)"
    if ok and mesh.boundary_crosses(xflat.reshape(-1, 2)):
        # every element upright, yet the body folds through itself: contact is not modelled
        ok = False
        status = f"{status}; rejected: the boundary crosses itself (self-contact is not modelled)"
    same = p_elastic is p or np.array_equal(np.asarray(p_elastic), np.asarray(p))
    return EquilibriumResult(x=xflat.reshape(-1, 2).copy(), energy=energy,
                             elastic_energy=energy if same else model.energy(xflat, p_elastic), success=ok,
                             status=status,
                             iterations=iters, residual=residual, min_J=mj, steps=steps,
                             build_time=t_build, solve_time=t_solve, backend=backend, mode=mode,
                             stable=None if chk is None else chk.stable,
                             stability=None if chk is None else chk.summary())


# ---------------------------------------------------------------------------------- external driving
def solve_external(mesh: Mesh, material, anchors: Sequence[int] | np.ndarray | None,
                   drags: Mapping[int, Sequence[float]] | tuple | None, *, backend: str = "ipopt",
                   tol: float = 1e-8, max_iter: int = 200, options: dict | None = None,
                   min_step: float = 1.0 / 256, verbose: bool = False,
                   initial_guess: str | np.ndarray = "predictor") -> EquilibriumResult:
    """External driving: anchors stay at rest, drag nodes move to given positions, the rest settle.

    Parameters
    ----------
    mesh, material : the body.
    anchors : node indices held at their rest positions.
    drags : ``{node: (x, y)}`` (straight moves), ``(indices, positions (k, 2))``, a
        :class:`~mdsr_opt.drags.RigidDrag` (rotate nodes through an angle about a centre, optionally with a
        shift; load stepping follows the arc), or a list of dicts and RigidDrags.
    backend : one of :func:`available_backends`.
    tol, max_iter : solver tolerance and iteration cap per load step.
    options : extra options for the backend (e.g. ``{"ipopt.print_level": 5}``).
    min_step : smallest load fraction tried before giving up, in (0, 1].
    verbose : print each accepted load step.
    initial_guess : ``"predictor"`` (default: every load step starts from a Newton predictor, at rest the
        linear-elastic solution), ``"rest"`` (each step starts from the current state, the rest shape at
        first, with only the fixed nodes moved) or an (n, 2) state to start the first step from (its fixed
        nodes are moved to their prescribed positions). The last two exist to study poor first guesses;
        combine them with ``min_step=1`` to forbid load stepping.

    Returns
    -------
    EquilibriumResult
        Only a stable equilibrium is a success: the Hessian on the free coordinates must be positive definite
        (``stable``, ``stability``; inertia of a sparse factorisation, :func:`~mdsr_opt.stability.check_stability`).
        At a saddle (e.g. the straight state of a compressed strip) the solve steps along the direction of
        negative curvature (2 % of the body size) and re-solves, up to 4 times; ``success=False`` with the
        reason when no stable state is found.

    Raises
    ------
    KeyboardInterrupt
        On Ctrl-C (SIGINT) during the solve, within about a solver iteration.
    """
    _check_mesh_material(mesh, material)
    tol = _check_common(tol, max_iter, backend, min_step)
    predict, x_start = _initial_guess(initial_guess, mesh)
    n = mesh.n_nodes
    anc = as_index_array(np.zeros(0, dtype=np.int64) if anchors is None else np.asarray(anchors),
                         "anchors", n=n, shape=(None,))
    if len(np.unique(anc)) != len(anc):
        raise ValueError("anchors name a node more than once")
    path = drag_path(drags, mesh)
    didx = path.nodes
    both = np.intersect1d(anc, didx)
    if len(both):
        raise ValueError(f"node {int(both[0])} is both anchored and dragged")
    nodes = np.concatenate([anc, didx])
    if len(nodes) == 0:
        raise ValueError("external driving needs fixed nodes: give anchors and/or drags")
    if len(nodes) < 2:
        raise ValueError("external driving needs at least two fixed nodes (anchors + drags) to remove rigid "
                         "motion; got 1")
    t0 = time.perf_counter()
    model = get_model(mesh, material)
    t_model = time.perf_counter() - t0  # ~0 when the mesh's model was built before
    p = model.params(material)
    fixed = np.zeros(2 * n, dtype=bool)
    fixed[2 * nodes] = True
    fixed[2 * nodes + 1] = True
    order = np.argsort(np.concatenate([2 * nodes, 2 * nodes + 1]))
    anchored = mesh.points[anc]

    def values_of(s):  # fixed coordinates at load s, in the order of the mask (anchors, then drag paths)
        at = np.vstack([anchored, path.positions(s)])
        return np.concatenate([at[:, 0], at[:, 1]])[order]

    x, status, ok, iters, steps, t_solve, t_build = _continuation(
        mesh, model, lambda s: p, fixed, values_of, x_start, backend, tol, max_iter, options, min_step, verbose,
        predict)
    return _result(mesh, model, material, p, p, x, fixed, status, ok, iters, steps, t_model + t_build, t_solve,
                   backend, "external")


def external_stability(mesh: Mesh, material, anchors, drags, x, *, lowest: bool = False):
    """Is ``x`` a stable equilibrium of external driving with these anchors and drags?

    Parameters
    ----------
    mesh, material : the body.
    anchors, drags : as in :func:`solve_external` (only which nodes are fixed matters here).
    x : (n, 2) state, e.g. a design target.
    lowest : also estimate the lowest eigenvalue of the free Hessian (see
        :func:`~mdsr_opt.stability.check_stability`).

    Returns
    -------
    check : StabilityCheck
        Of the energy's Hessian on the free coordinates at ``x``.
    residual : float
        Max-norm of the energy gradient on the free coordinates relative to ``E t size`` (small at an
        equilibrium).
    """
    _check_mesh_material(mesh, material)
    n = mesh.n_nodes
    anc = as_index_array(np.zeros(0, dtype=np.int64) if anchors is None else np.asarray(anchors),
                         "anchors", n=n, shape=(None,))
    nodes = np.union1d(anc, drag_path(drags, mesh).nodes)
    xflat = mesh._check_state(x).reshape(-1)
    model = get_model(mesh, material)
    p = model.params(material)
    fixed = np.zeros(2 * n, dtype=bool)
    fixed[2 * nodes] = fixed[2 * nodes + 1] = True
    g = model.gradient(xflat, p)
    residual = float(np.abs(g[~fixed]).max()) / (material.E * material.thickness * mesh.size) \
        if (~fixed).any() else 0.0
    return check_stability(model.hessian(xflat, p), ~fixed, lowest=lowest), residual


# ---------------------------------------------------------------------------------- internal driving
def _gauge(mesh) -> tuple[int, int, int]:
    """Three gauge coordinates (node i x & y, node j one coordinate), chosen from geometry alone."""
    P = mesh.points
    c = P.mean(0)
    d = np.linalg.norm(P - c, axis=1)
    i = int(np.lexsort((P[:, 1], P[:, 0], d))[0])
    dj = np.linalg.norm(P - P[i], axis=1)
    j = int(np.lexsort((P[:, 1], P[:, 0], -dj))[0])
    v = P[j] - P[i]
    comp = 1 if abs(v[0]) >= abs(v[1]) else 0
    return 2 * i, 2 * i + 1, 2 * j + comp


def _muscle_constraints(mesh, muscles, radius) -> MuscleConstraints:
    """The mesh's cached :class:`MuscleConstraints` for these muscles and anchor radius."""
    cache = mesh.__dict__.setdefault("_muscle_constraint_cache", {})
    key = (tuple(m.nodes for m in muscles), float(radius))
    if key not in cache:
        if len(cache) >= 16:
            cache.pop(next(iter(cache)))
        cache[key] = MuscleConstraints(mesh, muscles, radius)
    return cache[key]


def _constrained_model(emodel, mc, ropes) -> ConstrainedModel:
    cache = emodel.__dict__.setdefault("_constrained_cache", {})
    key = (id(mc), bool(ropes))
    if key not in cache or cache[key].constraints is not mc:
        if len(cache) >= 16:
            cache.pop(next(iter(cache)))
        cache[key] = ConstrainedModel(emodel, mc, ropes)
    return cache[key]


def solve_internal(mesh: Mesh, material, muscles: Sequence[Muscle], contractions, *, model: str = "cable",
                   stiffness: float = 10.0, anchor_radius: float | None = None, backend: str = "ipopt",
                   tol: float = 1e-8, max_iter: int = 200, options: dict | None = None,
                   min_step: float = 1.0 / 256, align_to_rest: bool = True, verbose: bool = False,
                   initial_guess: str | np.ndarray = "predictor") -> EquilibriumResult:
    """Internal driving: muscles contract by fractions ``contractions`` of their rest lengths in a free body.

    Parameters
    ----------
    muscles : list of :class:`Muscle` (or node lists) along mesh edges.
    contractions : one value in ``[0, 1)`` per muscle.
    model : ``"cable"`` (default) or ``"springs"``.

        - ``"cable"``: an inextensible rope sliding along the muscle's node chain, pulled in by a servo:
          ``min E_e(x)`` subject to ``L_c(x) <= (1 - a_c) L0_c`` for every muscle, solved exactly by the NLP
          (no penalty). The tension is the constraint's multiplier, never compressive; a rope that would have
          to push goes slack (``slack=True``, achieved < commanded).
        - ``"springs"``: the paper's dummy springs, one per segment, with the stiffness stated per unit rest
          length so the model does not depend on the mesh: a segment of rest length ``l0`` is a spring
          ``k/2 (l - (1 - a) l0)^2`` with ``k = K / l0`` and ``K = stiffness * E * thickness * D`` (``D`` the body's diameter)
          (a rod of axial stiffness ``K``; see
          :func:`~mdsr_opt.muscle_constraints.segment_spring_parameters`).
    stiffness : ``kappa`` of the springs model (ignored by the cable).
    anchor_radius : radius (length units) of the rigid patch that anchors each muscle end: the body nodes
        within it at rest move rigidly with the end node. Default
        :func:`~mdsr_opt.muscle_constraints.default_anchor_radius` (0.04 x the body's diameter); 0 ends each muscle
        on its node alone. Used with both models.
    backend : one of :func:`available_backends`; with constraints (the cable, or any anchor patch) only those
        of :data:`~mdsr_opt.backends.CONSTRAINED_BACKENDS` (not ``"newton"`` or ``"scipy"``).
    align_to_rest : rigidly align the result to the rest shape (the body's pose is otherwise arbitrary).
    initial_guess : ``"predictor"``, ``"rest"`` or an (n, 2) state, as in :func:`solve_external` (the
        three gauge coordinates of a given state are set to their rest values).

    Returns
    -------
    EquilibriumResult
        With, per muscle, ``commanded``, ``achieved`` (``1 - L/L0`` along the node chain in the returned
        state), ``stroke`` (``achieved * L0``, length units), ``tension`` and ``slack``. Load stepping moves
        the rope targets ``(1 - s a) L0`` (or the springs' rest lengths) with the load fraction ``s``. Only a
        stable state is a success: the Hessian of the Lagrangian must be positive definite on the tangent
        space of the active constraints (taut ropes, anchor patches; ``stable``, ``stability``).

    Example
    -------
    >>> import numpy as np
    >>> from mdsr_opt import Mesh, Muscle, NeoHookean, solve_internal
    >>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    >>> bottom = Muscle([int(i) for i in np.argsort(mesh.points[:, 0]) if mesh.points[i, 1] == 0.0])
    >>> res = solve_internal(mesh, NeoHookean(1.0, 0.3), [bottom], [0.3])
    >>> res.success, round(float(res.achieved[0]), 6), round(float(res.stroke[0]), 6), bool(res.tension[0] > 0)
    (True, 0.3, 1.2, True)
    """
    _check_mesh_material(mesh, material)
    tol = _check_common(tol, max_iter, backend)
    if model not in ("springs", "cable"):
        raise ValueError(f"model must be 'springs' or 'cable', got {model!r}")
    stiffness = positive_float(stiffness, "stiffness")
    radius = check_anchor_radius(mesh, anchor_radius)
    mus = check_muscles(mesh, muscles)
    if not mus:
        raise ValueError("internal driving needs at least one muscle")
    a = check_contractions(contractions, len(mus))
    predict, x_start = _initial_guess(initial_guess, mesh)
    n = mesh.n_nodes
    # the chain inside the anchor patches keeps its length: the rest must take up the whole stroke
    k_seg, a_fac = spring_segments(mesh, material, mus, stiffness, radius)
    if np.any(a * a_fac >= 1.0):
        c = int(np.argmax(a * a_fac))
        raise ValueError(f"muscle {c}: its anchor patches cover so much of it that a contraction of {a[c]:g} "
                         f"would shorten the rest by {a[c] * a_fac[c]:.3g} >= 1; give a smaller anchor_radius")
    constrained = model == "cable" or len(rigid_groups(mesh, mus, radius)) > 0
    if constrained and not supports_constraints(backend):
        why = "the exact cable" if model == "cable" else f"the rigid anchor patches (anchor_radius={radius:g})"
        raise ValueError(f"backend {backend!r} cannot take constraints, which {why} needs; use one of "
                         f"{', '.join(CONSTRAINED_BACKENDS)}" + ("" if model == "cable" else
                                                                 ", or anchor_radius=0"))
    t0 = time.perf_counter()
    mc = _muscle_constraints(mesh, mus, radius)
    emodel = get_model(mesh, material)
    cm = _constrained_model(emodel, mc, model == "cable") if constrained else None
    t_model = time.perf_counter() - t0  # ~0 when the mesh's model was built before
    L0 = mc.rest_lengths
    K = spring_stiffness(mesh, material, stiffness)

    def p_energy(s):
        if model == "springs":
            return emodel.params(material, springs=spring_parameters(mesh, mus, s * a * a_fac, k_seg))
        return emodel.params(material)

    def p_of(s):
        return cm.params(p_energy(s), (1.0 - s * a) * L0) if cm is not None else p_energy(s)

    p_el0 = emodel.params(material)
    fixed = np.zeros(2 * n, dtype=bool)
    fixed[list(_gauge(mesh))] = True
    X = mesh.points.reshape(-1).copy()
    vals = X[fixed]
    solver_model = cm if cm is not None else emodel
    x, status, ok, iters, steps, t_solve, t_build = _continuation(
        mesh, solver_model, p_of, fixed, lambda s: vals, x_start, backend, tol, max_iter, options, min_step,
        verbose, predict)
    p1 = p_of(1.0)
    p_el = p_el0
    taut = np.ones(len(mus), dtype=bool)
    if cm is not None:
        lam, taut_c = cm.multipliers(x, p1, fixed)
        if model == "cable":
            taut = taut_c
        p1 = cm.params(cm.split(p1)[0], cm.split(p1)[1], lam)
        p_el = cm.params(p_el0, cm.split(p1)[1])
    res = _result(mesh, solver_model, material, p1, p_el, x, fixed, status, ok, iters, steps,
                  t_model + t_build, t_solve, backend, "internal")
    res.muscle_model = model
    res.anchor_radius = radius
    res.rest_lengths = L0.copy()
    res.commanded = a.copy()
    L = mc.lengths(x)
    res.achieved = 1.0 - L / L0
    res.stroke = L0 - L
    if model == "cable":
        res.tension = np.where(taut, lam[:len(mus)], 0.0) if cm is not None else np.zeros(len(mus))
        # slack: the path is shorter than the rope (a rope at its length with no load is taut, not slack)
        res.slack = res.achieved > a + 1e-7
    else:
        # the springs' mean force over the free segments, K (L_free / L0_free - (1 - a')), from the whole
        # chain's length since the anchored segments keep their rest lengths
        res.tension = K * a_fac * (a - res.achieved)
        res.slack = res.tension <= 0.0
    if cm is not None and res.success:
        _check_feasible(res, cm, x, p1, mesh)
    if align_to_rest:
        al = align(res.x, mesh.points)
        res.x = al.apply(res.x)
        res.rotation, res.translation = al.R, al.t
    return res


def _check_feasible(res, cm, x, p, mesh, rtol: float = 1e-7) -> None:
    """Reject a constrained solution whose ropes are longer than their targets or whose anchors deformed."""
    v = cm.values(x)
    _, targets, _ = cm.split(p)
    nt = cm.n_targets
    over = float(np.max((v[:nt] - targets) / cm.constraints.rest_lengths)) if nt else 0.0
    rig = float(np.abs(v[nt:]).max()) / mesh.size if len(v) > nt else 0.0
    if over > rtol or rig > rtol:
        res.success = False
        res.status = f"{res.status}; rejected: rope longer than its target by {over:.3g} L0, anchor patch " \
                     f"deformed by {rig:.3g} x size"
