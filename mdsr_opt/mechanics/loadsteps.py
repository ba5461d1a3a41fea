"""Load stepping shared by external and internal driving: input checks, the Newton predictor, adaptive
load fractions, the stability check with saddle escape, and the checked result."""

from __future__ import annotations

import logging
import time
import numpy as np
import scipy.sparse.linalg as spla

from ..body.mesh import Mesh
from ..core.checks import positive_float, positive_int
from ..core.guards import check_stop, interruptible
from .backends import check_backend, minimize
from .blas import one_blas_thread
from .drags import RigidDrag, drag_path
from .kkt import OrderedFactor
from .residual import kkt_residual, meet_tolerance
from .result import EquilibriumResult
from .stability import certified_minimum, check_stability

_LOG = logging.getLogger(__name__)


# ---------------------------------------------------------------------------------- input checks
def check_mesh_material(mesh, material):
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a mdsr_opt.Mesh, got {type(mesh).__name__}")
    if not hasattr(material, "psi_expr") or not hasattr(material, "params"):
        raise TypeError(f"material must be a material such as NeoHookean, got {type(material).__name__}")


def parse_drags(drags, n) -> tuple[np.ndarray, np.ndarray]:
    """``(indices, final positions (k, 2))`` of ``drags``; ``n`` is the mesh (or its node count when no drag
    is a :class:`~mdsr_opt.mechanics.drags.RigidDrag`, whose final positions depend on the rest positions)."""
    if isinstance(n, Mesh):
        path = drag_path(drags, n)
    else:
        path = drag_path(drags, _NodeCount(int(n)))
        if any(isinstance(how, RigidDrag) for _, how in path.parts):
            raise ValueError("rigid drags need the mesh: use mdsr_opt.mechanics.drags.drag_path(drags, mesh)")
    return path.nodes, path.final


class _NodeCount:
    """Stands in for a mesh when only the node count is known (rest positions unused by straight drags)."""

    def __init__(self, n):
        self.n_nodes = n
        self.points = np.zeros((n, 2))


def check_common(tol, max_iter, backend, min_step=None):
    tol = positive_float(tol, "tol")
    positive_int(max_iter, "max_iter")
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


def initial_guess_of(initial_guess, mesh) -> tuple[bool, np.ndarray]:
    """``(predict, x_start)`` for ``initial_guess`` = ``"predictor"``, ``"rest"`` or an (n, 2) state."""
    X = mesh.points.reshape(-1).copy()
    if isinstance(initial_guess, str):
        if initial_guess not in ("predictor", "rest"):
            raise ValueError("initial_guess must be 'predictor', 'rest' or an (n, 2) array, "
                             f"got {initial_guess!r}")
        return initial_guess == "predictor", X
    x0 = mesh._check_state(initial_guess)
    if min_jacobian(mesh, x0.reshape(-1)) <= 0.0:
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
    if getattr(model, "is_numeric", False):  # the mesh's fill-reducing ordering, made once
        fi = np.flatnonzero(free)
        order = model.free_ordering(free)
        lu = OrderedFactor(spla.splu(H[fi[order]][:, fi[order]].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0,
                                options={"SymmetricMode": True}), order)
    else:
        # symmetric mode with a minimum-degree ordering: about twice as fast as spsolve's default here
        lu = spla.splu(H[free][:, free].tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
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


def predict_state(model, p, x, fixed, values):
    """The load-stepping predictor: a Newton (KKT, for a constrained model) step from ``x`` with the fixed
    coordinates moved to ``values`` (the linear-elastic solution at rest); None when it fails."""
    return _predict(model, p, x, fixed, values)


def min_jacobian(mesh, xflat) -> float:
    """The smallest ``J = det F = det Ds / det Dm`` over the triangles.

    Parameters
    ----------
    mesh : Mesh
    xflat : (2n,) or (n, 2) array of node positions.

    Returns
    -------
    float
        ``min J``, as ``mesh.jacobians(x).min()`` up to rounding, without its batched 2 x 2 inverses and
        determinants; ``J <= 0`` marks an inverted element.
    """
    t = mesh.triangles
    x = np.asarray(xflat, dtype=float).reshape(-1)
    xs, ys = x[0::2], x[1::2]
    x0, y0 = xs[t[:, 0]], ys[t[:, 0]]
    det_ds = (xs[t[:, 1]] - x0) * (ys[t[:, 2]] - y0) - (xs[t[:, 2]] - x0) * (ys[t[:, 1]] - y0)
    return float((det_ds / (2.0 * mesh.areas)).min())


def upright(mesh, xflat) -> bool:
    """Every coordinate of ``xflat`` ((2n,) or (n, 2)) finite and every element upright (:func:`min_jacobian`
    > 0): a state with an energy, from which a solve can start."""
    return bool(np.all(np.isfinite(xflat))) and min_jacobian(mesh, xflat) > 0.0


#: IPOPT's tolerance for the load steps before the last, when the solve's own is tighter: their states only
#: start the next step (the last is solved to the solve's own tolerance). External driving (anchors, drags)
#: keeps 1e-6: a drag that buckles the body passes its states along the unstable unbuckled branch, and
#: from a loosely converged one the last step ran off along the buckling mode (on 27 buckled strips with
#: iteration caps of 8-20, 15 solves succeeded with 1e-3 or 1e-4 against 17 with 1e-6; with the default cap
#: all the same)
INTERMEDIATE_TOL = 1e-6

#: The same for internal driving (muscles: :func:`~mdsr_opt.solve_internal`). Measured on 24 strips of 1k
#: and 3k nodes with 1-8 ropes and the muscle scenes' cases on their meshes and prototypes: at tol 1e-10,
#: 896 IPOPT iterations against 914 with 1e-6 and 915 with every step at 1e-10; at tol 1e-8, 878 against
#: 895; on 30 random layouts of 2-4 ropes on a 32 x 8 strip 293 against 302; on 36 strips squeezed by one
#: or two ropes under iteration caps of 6-200, 545 against 664, the same successes; no case took more
#: iterations, and the equilibria agree to 1e-11 in energy. The 3k-node, 4-rope design's verification
#: takes 6 iterations (7 with 1e-6, 8 with 1e-10)
INTERNAL_INTERMEDIATE_TOL = 1e-3

#: iterations a load step may take before it is halved (unless it is already within 4x of ``min_step``):
#: a 50 % cable contraction at 600 nodes spent 400 of its 473 iterations on a full-load attempt that did not
#: converge, then succeeded in two halves of 35 and 38 iterations
STEP_ITER_CAP = 100


def load_continuation(mesh, model, p_of, fixed, values_of, x_start, backend, tol, max_iter, options, min_step,
                  verbose, predict=True, settle=True, intermediate_tol=None, on_step=None):
    """Apply the load fraction ``s`` from 0 to 1 adaptively; returns (x, status, success, iters, steps, time).

    Load steps before the last are solved to ``intermediate_tol`` (default :data:`INTERMEDIATE_TOL`) when
    ``tol`` is tighter.

    With ``predict=False`` each load step starts from the current state with the fixed coordinates moved
    (no Newton predictor): the "poor first guess" of the comparison studies. At full load the state must be
    stable (:func:`_settle`): a saddle is left along its negative curvature, or the solve fails; with
    ``settle=False`` that check is skipped. A SIGINT
    raises :class:`KeyboardInterrupt` (never a failed step).

    ``on_step``: called as ``on_step(x, s)`` with each accepted load step's state and load fraction (before
    the stability check at full load); a
    string it returns stops the load stepping there, a failure naming it (e.g. a contact solve's contact-free
    first try whose path touches, :mod:`~mdsr_opt.mechanics.contactfree`)."""
    min_step = _check_min_step(min_step)
    loose = INTERMEDIATE_TOL if intermediate_tol is None else float(intermediate_tol)
    with interruptible(), one_blas_thread():
        x = x_start.copy()
        s, ds = 0.0, 1.0
        steps, iters, t_solve, t_build = [], 0, 0.0, 0.0
        status = "not started"
        certified = False  # the last accepted step's state: a strict minimum by IPOPT's inertia test
        while s < 1.0 - 1e-12:
            check_stop()  # an interrupt a step swallowed (e.g. in a predictor's CasADi call) stops here
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
            if guess is None or min_jacobian(mesh, guess) <= 0.0:
                status = "predictor inverted an element" if predict else "first guess inverts an element"
                ds /= 2
                continue
            # a step that needs many iterations is usually too long: give it STEP_ITER_CAP and halve it
            # instead of spending the whole budget; near min_step the whole budget (nothing shorter to try)
            cap = max_iter if ds < 4 * min_step else min(max_iter, STEP_ITER_CAP)
            if s_new >= 1.0:  # the state returned: held to the tolerance contract
                out = solve_step(mesh, model, p, guess, fixed, vals, backend, tol, cap, options)
            else:  # a state that only starts the next step, solved to a looser tolerance
                out = minimize(model, p, guess, fixed, vals, backend=backend, tol=max(tol, loose), max_iter=cap,
                               options=options)
            iters += out.iterations
            t_solve += out.solve_time
            t_build += out.build_time
            status = out.status
            if out.success and upright(mesh, out.x):
                x, s, certified = out.x, s_new, out.certified
                steps.append(s)
                if verbose:
                    print(f"  load {s:.4f}: {out.status}, {out.iterations} iterations")
                why = on_step(x, s) if on_step is not None else None
                if why is not None:
                    return x, f"stopped at load fraction {s:.4g}: {why}", False, iters, steps, t_solve, t_build
                ds = min(2 * ds, 1.0 - s) if s < 1.0 else ds
            else:
                ds /= 2
        if not settle:  # the caller takes any equilibrium (e.g. a warm start): no stability check
            return x, status, True, iters, steps, t_solve, t_build
        x, note, ok, it, t = _settle(mesh, model, p_of(1.0), fixed, values_of(1.0), x, backend, tol, max_iter,
                                     options, verbose, certified)
    return x, status + note, ok, iters + it, steps, t_solve + t, t_build


def solve_step(mesh, model, p, guess, fixed, values, backend, tol, max_iter, options):
    """One solve of a load step (:func:`~mdsr_opt.mechanics.backends.minimize`) held to the tolerance
    contract: a state the backend calls converged is accepted only when its scaled KKT residual
    (:func:`~mdsr_opt.mechanics.residual.kkt_residual`) is at most ``tol``, after Newton polishing if it
    stopped short (:func:`~mdsr_opt.mechanics.residual.meet_tolerance`); otherwise it is a failure naming
    the residual. A polished state loses IPOPT's certificate of a minimum (the stability check decides)."""
    out = minimize(model, p, guess, fixed, values, backend=backend, tol=tol, max_iter=max_iter, options=options)
    if out.success and upright(mesh, out.x):
        x, res, polished = meet_tolerance(model, out.x, p, fixed, tol, upright=lambda y: upright(mesh, y),
                                          lam=out.lam_g)
        if polished:
            out.x, out.certified = x, False
        if not res.value <= tol:
            out.success = False
            out.status += f"; rejected: residual {res.value:.3g} > tol {tol:.3g}"
    return out


#: saddle escape: re-solves from perturbed states, and the perturbation's largest node move / body size
_RESTARTS = 4


_KICK = 0.02


def _stability_at(model, p, xflat, fixed):
    """:class:`~mdsr_opt.mechanics.stability.StabilityCheck` of the equilibrium ``xflat`` with ``fixed`` coordinates.

    For a model with muscle constraints, the Hessian of the Lagrangian (least-squares multipliers) on the
    tangent space of the active rows (rigid patches, taut ropes). The last check is cached on the model, so
    the solve and its result share one factorisation."""
    key = _stability_key(model, p, xflat, fixed)
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
    if A is None:
        order = model.free_ordering(~fixed) if getattr(model, "is_numeric", False) else None
    else:  # the KKT matrix of the constrained check is ordered from the energy model's ordering
        order = model.model.free_ordering(~fixed)
    chk = check_stability(H, ~fixed, A, order=order)
    model.__dict__["_last_stability"] = (key, chk)
    return chk


def _stability_key(model, p, xflat, fixed) -> tuple:
    """What :func:`_stability_at` caches its last check under: the state, the parameters (not a constrained
    model's multipliers, which it refits) and the fixed coordinates."""
    pk = np.concatenate(model.split(p)[:2]) if hasattr(model, "split") else p
    return np.asarray(xflat, dtype=float).tobytes(), np.asarray(pk, dtype=float).tobytes(), fixed.tobytes()


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
            if min_jacobian(mesh, y) > 0.0:
                e = model.energy(y, p)
                if np.isfinite(e) and (best is None or e < best[0]):
                    best = (e, y)
                break
            a /= 2
    return None if best is None else best[1]


def _settle(mesh, model, p, fixed, values, x, backend, tol, max_iter, options, verbose, certified=False):
    """Only a stable equilibrium is a success: at a saddle, step along its negative curvature and re-solve.
    ``certified``: the solve that reached ``x`` showed it a strict minimum itself
    (:func:`~mdsr_opt.mechanics.stability.ipopt_certifies_minimum`), which is then its check (made once,
    not again).

    Returns ``(x, status note, success, iterations, seconds)``."""
    t0 = time.perf_counter()
    if certified:
        model.__dict__["_last_stability"] = (_stability_key(model, p, x, fixed), certified_minimum())
    chk = _stability_at(model, p, x, fixed)
    iters, tries, scale = 0, 0, 1.0
    while not chk.stable and tries < _RESTARTS and chk.direction is not None:
        check_stop()
        tries += 1
        y = _kick(mesh, model, p, x, chk.direction, scale)
        if y is None:
            break
        out = solve_step(mesh, model, p, y, fixed, values, backend, tol, max_iter, options)
        iters += out.iterations
        if not (out.success and upright(mesh, out.x)):
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


def equilibrium_result(mesh, model, material, p, p_elastic, xflat, fixed, status, success, iters, steps, t_build, t_solve,
            backend, mode, tol, check_stability=True, residual=None):
    """The checked :class:`EquilibriumResult` of a state: a success only when the solve succeeded, every
    element is upright, the scaled KKT residual is at most ``tol`` (``residual``, the value of
    :func:`~mdsr_opt.mechanics.residual.kkt_residual` when the caller has it: with constraints; else the
    energy gradient's) and the state is stable (unless ``check_stability=False``)."""
    if getattr(model, "is_numeric", False):  # an EnergyModel in numpy: energy and gradient from one object
        en = model.numeric(p)
        energy, g = float(en.energy(xflat)), en.gradient(xflat)
    elif hasattr(model, "grad_fn"):  # an EnergyModel: energy and gradient from one call
        f, g = model.grad_fn(xflat, p)
        energy, g = float(f), np.asarray(g).ravel()
    else:
        g, energy = None, model.energy(xflat, p)
    if residual is None:
        residual = kkt_residual(model, xflat, p, fixed, tol, material.E * material.thickness * mesh.size,
                                gradient=g).value
    mj = min_jacobian(mesh, xflat)
    ok = bool(success and mj > 0 and residual <= tol)
    if success and not ok:
        status = f"{status}; rejected: residual {residual:.3g} (tol {tol:.3g}), min J {mj:.3g}"
    chk = None
    if check_stability and (ok or "not a stable equilibrium" in status):  # the continuation's (cached), or fresh
        with one_blas_thread():
            chk = _stability_at(model, p, xflat, fixed)
        if ok and not chk.stable:
            ok = False
            status = f"{status}; rejected: not a stable equilibrium ({chk.n_negative} negative, {chk.n_zero} " \
                     "zero curvature directions)"
    if ok and mesh.boundary_crosses(xflat.reshape(-1, 2)):
        # every element upright, yet the body folds through itself: contact is off
        ok = False
        status = f"{status}; rejected: the boundary crosses itself (contact is off: contact=True models it)"
    same = p_elastic is p or np.array_equal(np.asarray(p_elastic), np.asarray(p))
    _LOG.debug("%s solve on %d nodes (%s): %s, %s iteration(s) in %d load step(s), residual %.3g (tol %.3g), "
               "min J %.3g, build %.3f s, solve %.3f s", mode, mesh.n_nodes, backend, status, iters, len(steps or ()),
               residual, tol, mj, t_build, t_solve)
    return EquilibriumResult(x=xflat.reshape(-1, 2).copy(), energy=energy,
                             elastic_energy=energy if same else model.energy(xflat, p_elastic), success=ok,
                             status=status,
                             iterations=iters, residual=residual, min_J=mj, steps=steps,
                             build_time=t_build, solve_time=t_solve, backend=backend, mode=mode,
                             stable=None if chk is None else chk.stable,
                             stability=None if chk is None else chk.summary())
