"""Design verification: a forward re-solve from rest and the stability of state and target."""

from __future__ import annotations

import time
from types import SimpleNamespace
from typing import Sequence
import numpy as np
from numpy.typing import ArrayLike

from ..body.checks import check_target_shape
from ..body.fingerprint import check_same_mesh
from ..body.mesh import Mesh
from ..body.muscles import Muscle, check_distinct_ropes, check_muscles
from ..core.checks import as_float_array, positive_float
from ..mechanics.align import align, node_weights
from ..mechanics.anchors import check_anchor_radius
from ..mechanics.equilibrium import check_held, external_stability, solve_internal
from ..mechanics.loadsteps import check_mesh_material, upright
from ..mechanics.stability import check_stability
from ..mechanics.units import Units
from .contactdesign import check_design_contact, contact_minimum
from .problem import DesignProblem
from .results import DesignResult, Verification

__all__ = ['check_minimum', 'verify_design']

#: a forward re-solve that lands this close to the design's state (after rigid alignment, relative to the
#: body's size; both solved to 1e-10, they agree to about 1e-13 at 3k nodes) is that state: its stability
#: check is the design's (:func:`verify_design`), which saves a factorisation
SAME_STATE_RTOL = 1e-9


def check_minimum(mesh: Mesh, material, muscles: Sequence[Muscle], contractions: ArrayLike, x: ArrayLike, *,
                  muscle_model: str = "cable", stiffness: float = 10.0,
                  anchor_radius: float | None = None, lowest: bool = True,
                  tol: float = 1e-8, contact: bool = False, obstacles=None,
                  contact_gap: float | None = None, held=None) -> tuple[bool, float, float]:
    """Is ``x`` a strict minimum of the internal-driving energy (rigid gauge pinned)?

    With muscle constraints (the exact cable's taut ropes, the rigid anchor patches) the test is on the
    Hessian of the Lagrangian restricted to the tangent space of the active constraints.

    Returns ``(positive_definite, min_eigenvalue, residual)``: whether the (reduced) free-coordinate Hessian
    is positive definite, from the inertia of a sparse symmetric factorisation
    (:func:`~mdsr_opt.mechanics.stability.check_stability`, no eigen-solve of the Hessian); its smallest eigenvalue
    relative to ``E t`` (when positive definite an estimate by LOBPCG preconditioned by the factor; else the
    curvature along the direction of most negative curvature found, an upper bound); and the scaled KKT
    residual that :func:`~mdsr_opt.solve_internal` accepts its states by
    (:func:`~mdsr_opt.mechanics.residual.kkt_residual`: the max-norm of the free gradient of the Lagrangian
    relative to ``E t size``, ropes pulling only within ``tol L0`` of their targets, and the constraints'
    violation): a state ``solve_internal`` returned as a success at ``tol`` has it at most ``tol``. With
    ``lowest=False`` the eigenvalue estimate is skipped when the state is positive definite (NaN returned;
    the inertia alone decides, 30-100x cheaper at thousands of nodes). The check runs on the body scaled to
    unit size and stiffness (:class:`~mdsr_opt.mechanics.units.Units`).

    With contact (``contact=True`` and/or ``obstacles``, as in :func:`~mdsr_opt.solve_internal`) the test is
    on the tangent space of the active ropes, anchor patches and pushing contacts: a contact solve started at
    ``x`` must stay there and be stable (:func:`~mdsr_opt.synthesis.contactdesign.contact_minimum`); the
    eigenvalue is then NaN. ``held``: nodes clamped at rest (:func:`~mdsr_opt.solve_internal`), pinned
    instead of the gauge.

    Example
    -------
    >>> from mdsr_opt import Mesh, NeoHookean, Muscle, solve_internal
    >>> mesh = Mesh.rectangle(4.0, 1.0, 8, 2)
    >>> res = solve_internal(mesh, NeoHookean(1.0, 0.3), [Muscle(range(0, 9))], [0.2])
    >>> pd, lam, r = check_minimum(mesh, NeoHookean(1.0, 0.3), [Muscle(range(0, 9))], [0.2], res.x)
    >>> pd, lam > 0, r < 1e-6
    (True, True, True)
    """
    check_mesh_material(mesh, material)
    mus = check_muscles(mesh, muscles)
    if not mus:
        raise ValueError("check_minimum needs at least one muscle")
    if muscle_model not in ("springs", "cable"):
        raise ValueError(f"muscle_model must be 'springs' or 'cable', got {muscle_model!r}")
    if muscle_model == "cable":
        check_distinct_ropes(mus)
    a = as_float_array(np.atleast_1d(contractions), "contractions", shape=(len(mus),))
    tol = positive_float(tol, "tol")
    radius = check_anchor_radius(mesh, anchor_radius)
    ckw = check_design_contact(mesh, material, contact, obstacles, contact_gap, "derivative-free")
    hold = check_held(mesh, held, mus)
    if ckw:
        ok, residual, _ = contact_minimum(mesh, material, mus, a, mesh._check_state(x), ckw,
                                          muscle_model=muscle_model, stiffness=stiffness, anchor_radius=radius,
                                          tol=tol, held=hold)
        return ok, float("nan"), residual
    units = Units(mesh, material)  # checked on the unit body (size and E t about 1)
    x = units.state_in(mesh._check_state(x))
    prob = DesignProblem(units.unit_mesh, units.unit_material, mus, x, np.ones(mesh.n_nodes), muscle_model,
                         stiffness, 0.99, anchor_radius=units.to_unit(radius), held=hold)
    return _stability(prob, a, x.reshape(-1), tol, lowest=bool(lowest))


def _stability(prob: DesignProblem, a, xflat, tol: float, lowest: bool = True) -> tuple[bool, float, float]:
    """``(positive_definite, min_eigenvalue / (E t), residual)`` at ``xflat`` (see :func:`check_minimum`).

    The gauge coordinates are pinned (the energy is invariant under rigid motion); with muscle constraints
    the Hessian is the Lagrangian's with least-squares multipliers, on the tangent space of the active
    rows (:meth:`DesignProblem.kkt_data`, in units of ``E t h``)."""
    H, free, A, _kap, _res = prob.kkt_data(a, xflat)
    chk = check_stability(H, free, A, lowest=lowest, order=prob.model.free_ordering(free))
    lam = float(chk.curvature) * prob.h if chk.curvature is not None else (0.0 if not chk.stable else np.nan)
    return bool(chk.stable), lam, prob.kkt_residual(a, xflat, tol)


def verify_design(mesh: Mesh, material, muscles: Sequence[Muscle], result: DesignResult, target: ArrayLike, *,
                  weights: ArrayLike | None = None, gap_rtol: float = 1e-5, anchors=None,
                  drags=None, lowest: bool = False, start: str = "rest", tol: float = 1e-10,
                  contact: bool = False, obstacles=None, contact_gap: float | None = None,
                  held=None) -> Verification:
    """Check a design independently of how it was found.

    Solves the forward internal-driving problem at ``result.contractions`` (:func:`~mdsr_opt.solve_internal`:
    energy minimised under the muscles' constraints, then its stability check), measures the largest node
    distance between that state and ``result.x`` after rigid alignment, and checks that ``result.x`` is a
    strict minimum of the energy (:func:`check_minimum`). Passes when the forward solve succeeded at ``tol``,
    the gap is at most ``gap_rtol * mesh.size``, the design's state is an equilibrium at ``tol`` (its scaled
    KKT residual, the measure ``solve_internal`` accepts its states by, at most ``tol``) and the (reduced)
    Hessian is positive definite. ``tol`` (default 1e-10) is at least as tight as ``solve_internal``'s
    default, so a verified design solves forward as a success with ``solve_internal``'s defaults too.

    ``start="rest"`` (default) load-steps from the rest shape, as a servo pulling the ropes from rest would:
    it asks that contracting the muscles from rest reaches this state rather than another stable one (a
    body with several, e.g. buckled one way or the other). The solve starts from the rest shape itself
    (``solve_internal(initial_guess="rest")``), and from the load-stepping predictor when that fails
    (``forward_start`` says which, ``forward_iterations`` counts both): the predictor's linear guess of a
    large contraction squeezes the elements along the ropes, and IPOPT took several short, regularised steps
    to leave it (the strip of ``bench_fine_design``: 15, 9 and 19 iterations from the predictor against 9, 7
    and 13 from the rest shape at 2.4k, 8k and 16.7k nodes, the same state). ``start="design"`` starts the
    forward solve from the design's own state (moved rigidly into the solver's gauge frame) instead: the
    forward solver must find it a stable equilibrium at these contractions, or move away from it (a gap) or
    fail; it does not check that the state is reached from rest, at about a third of the cost. A design
    state that cannot start a solve (an inverted element) is verified from rest. A state already within
    ``tol`` is the one that solve returns at once, so it is checked where it stands, with the solve's own
    tests (the residual, the inertia of the reduced Hessian, the boundary) and no solver run
    (``forward_iterations`` 0, ``forward_status`` says so).

    When the target came from external driving, give its ``anchors`` and ``drags`` (as in
    :func:`~mdsr_opt.solve_external`): the target must then also be a stable equilibrium of that driving
    (:func:`~mdsr_opt.mechanics.equilibrium.external_stability`), since a saddle (e.g. an unbuckled compressed strip)
    is a shape no body holds; ``target_stable`` reports it.

    The minimum test is the inertia of one sparse factorisation; ``lowest=True`` also estimates the smallest
    eigenvalue of a positive definite state (``min_eigenvalue``, NaN otherwise), an eigen-solve that costs
    30-100x the inertia at thousands of nodes. When the forward solve lands on the design's state (within
    :data:`SAME_STATE_RTOL` of the body's size after alignment) its own stability check, made at the end of
    every successful solve, answers the test.

    With contact (``contact=True`` and/or ``obstacles``, as in :func:`~mdsr_opt.solve_internal`) the forward
    solve models it, and the design's state must be a stable equilibrium with its contacts: a contact solve
    started there stays there and is stable on the tangent space of its active ropes and pushing contacts
    (:func:`~mdsr_opt.synthesis.contactdesign.contact_minimum`); ``min_eigenvalue`` is then NaN. ``contact`` of
    the result reports the forward state's contacts (pairs, normal forces, forces on nodes and obstacles).

    With ``held`` nodes (clamped at rest, as in :func:`~mdsr_opt.solve_internal`; default: the design's own,
    ``result.held``, recorded by :func:`~mdsr_opt.synthesis.contractions.design_contractions`) the
    forward solves hold them too, and gaps and the forward difference are measured where the states are,
    without rigid alignment (the held nodes fix the pose; the target is first moved rigidly onto their rest
    positions, the identity for a target solved with them anchored).

    Example
    -------
    >>> from mdsr_opt import Mesh, Muscle, NeoHookean, design_contractions, solve_internal
    >>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    >>> mat, mus = NeoHookean(1.0, 0.3), [Muscle(range(1, 16))]
    >>> target = solve_internal(mesh, mat, mus, [0.1]).x
    >>> res = design_contractions(mesh, mat, mus, target, verify=False)
    >>> verify_design(mesh, mat, mus, res, target).passed
    True
    """
    t0 = time.perf_counter()
    if start not in ("design", "rest"):
        raise ValueError(f"start must be 'design' or 'rest', got {start!r}")
    check_mesh_material(mesh, material)
    mus = check_muscles(mesh, muscles)
    y = check_target_shape(mesh, target)  # the check of every entry point that takes a target
    w = node_weights(mesh) if weights is None else as_float_array(weights, "weights", shape=(mesh.n_nodes,))
    if not isinstance(result, DesignResult):
        raise TypeError(f"result must be a DesignResult, got {type(result).__name__}")
    check_same_mesh(mesh, result.rest_mesh, "the design")  # a design of this body, not a copy scaled or moved
    if result.muscle_model == "cable":
        check_distinct_ropes(mus)
    a = np.asarray(result.contractions, dtype=float)
    tol = positive_float(tol, "tol")
    x = mesh._check_state(result.x)
    radius = getattr(result, "anchor_radius", None)
    radius = None if radius is None or not np.isfinite(radius) else float(radius)
    radius = check_anchor_radius(mesh, radius)
    ckw = check_design_contact(mesh, material, contact, obstacles, contact_gap, "derivative-free")
    hold = check_held(mesh, getattr(result, "held", None) if held is None else held, mus)
    target_check = None
    if anchors is not None or drags is not None:  # checked first: cheap, and bad anchors/drags fail before any solve
        target_check, target_residual = external_stability(mesh, material, anchors, drags, y)
    gap_tol = gap_rtol * mesh.size
    # the checks run on the unit body (size and E t about 1); lengths are reported in the caller's units
    units = Units(mesh, material)
    L, size = units.length, mesh.size
    mesh, material, x = units.unit_mesh, units.unit_material, units.state_in(x)
    prob = DesignProblem(mesh, material, mus, units.state_in(y), w, result.muscle_model, result.stiffness, 0.99,
                         anchor_radius=units.to_unit(radius), held=hold)
    if ckw:  # in the caller's units (solve_internal scales itself), the obstacles where the caller put them
        return _verify_contact(units, mus, a, result, x, prob.y, w, radius, start, tol, gap_tol, ckw,
                               target_check, target_residual if target_check is not None else None, t0, hold)
    fopts = {"muscle_model": result.muscle_model, "stiffness": result.stiffness,
             "anchor_radius": prob.anchor_radius, "tol": tol, "held": hold}
    a_fwd = np.clip(a, 0.0, 0.999)
    guess = prob.in_frame(x) if start == "design" else None  # None: an inverted state, from rest
    stopped = _stops_at_start(prob, a_fwd, guess, tol, bool(lowest)) if guess is not None else None
    if stopped is not None:  # the forward solve from the design's state would stop there: its checks, made here
        fwd, (pd, lam, residual) = stopped
        f_iters, f_start = 0, "design"
    elif guess is not None:
        fwd = solve_internal(mesh, material, mus, a_fwd, initial_guess=guess, **fopts)
        f_iters, f_start = int(fwd.iterations), "design"
    else:
        # from the rest shape itself (REST_START), and with the load-stepping predictor when that fails
        fwd = solve_internal(mesh, material, mus, a_fwd, initial_guess="rest", **fopts)
        f_iters, f_start = int(fwd.iterations), "rest"
        if not fwd.success:
            fwd = solve_internal(mesh, material, mus, a_fwd, initial_guess="predictor", **fopts)
            f_iters, f_start = f_iters + int(fwd.iterations), "rest, predictor"
    fx = fwd.x
    moved = align(x, fx).apply(x) - fx if hold is None else x - fx  # held: both where the mount holds them
    gap = float(np.linalg.norm(moved, axis=1).max()) * L
    fdiff = prob.alignment(fx).difference * L
    # the design's own state, expressed in the gauge frame used by the model
    xg = x.reshape(-1)
    inverted = not upright(mesh, x)
    if inverted:  # no energy there (log det F): not a minimum, and no Hessian to factorise
        pd, lam, residual = False, float("nan"), float("nan")
    elif stopped is not None:
        pass  # answered at the start
    elif fwd.success and gap <= SAME_STATE_RTOL * size and not lowest:
        # the forward solve reached the design's state (up to a rigid motion, which leaves the energy and
        # its curvature as they are) and found it a strict minimum: its check answers for both
        pd, lam, residual = True, np.nan, prob.kkt_residual(a, xg, tol)
    else:
        pd, lam, residual = _stability(prob, a, xg, tol, lowest=bool(lowest))
    msgs = _forward_messages(fwd, "forward re-solve", gap, gap_tol, inverted)
    if not inverted:
        if not residual <= tol:
            msgs.append(f"the design's state is not an equilibrium at its contractions (scaled KKT residual "
                        f"{residual:.3g} > tol {tol:.3g})")
        if not pd:
            msgs.append(f"the design's state is not a minimum of the energy (a saddle: curvature {lam:.3g} E t "
                        f"along its direction of negative curvature)")
    msgs += _target_messages(target_check, target_residual if target_check is not None else None)
    return Verification(passed=not msgs, gap=gap, gap_tol=gap_tol, forward_success=bool(fwd.success),
                        forward_status=fwd.status, forward_difference=float(fdiff), residual=residual,
                        positive_definite=bool(pd), min_eigenvalue=lam, message="; ".join(msgs),
                        time=time.perf_counter() - t0,
                        target_stable=None if target_check is None else bool(target_check.stable),
                        forward_iterations=f_iters, forward_start=f_start)


def _stops_at_start(prob: DesignProblem, a, x0, tol: float, lowest: bool):
    """What the forward solve from the design's state ``x0`` (in the solver's frame) finds when ``x0`` already
    meets ``tol``: ``(forward outcome, (positive_definite, min_eigenvalue, residual))``, or None when it does
    not (or inverts an element: the solve then runs).

    :func:`~mdsr_opt.solve_internal` accepts a state by its scaled KKT residual
    (:meth:`DesignProblem.kkt_residual`), so from a start already within ``tol`` it stops there, and its
    result is that start when the start is a stable equilibrium whose boundary does not cross itself (the
    checks every solve's result passes: :func:`~mdsr_opt.mechanics.loadsteps.equilibrium_result`). Those
    checks are made here, once (the residual, the inertia of the Hessian of the Lagrangian on the tangent
    space of the active constraints, :func:`_stability`, and the boundary), instead of by a solve that would
    not move: the same answer without the solver's set-up, its own residual fits and a second residual."""
    if not upright(prob.mesh, x0):
        return None
    xflat = x0.reshape(-1)
    residual = prob.kkt_residual(a, xflat, tol)
    if not residual <= tol:
        return None
    H, free, A, _kap, _res = prob.kkt_data(a, xflat)
    chk = check_stability(H, free, A, lowest=lowest, order=prob.model.free_ordering(free))
    lam = float(chk.curvature) * prob.h if chk.curvature is not None else (0.0 if not chk.stable else np.nan)
    status = f"the design's state meets tol (scaled KKT residual {residual:.3g}): the solve from it stops there"
    ok = bool(chk.stable)
    if not ok:
        status += f"; rejected: not a stable equilibrium ({chk.n_negative} negative, {chk.n_zero} zero curvature " \
                  "directions)"
    elif prob.mesh.boundary_crosses(x0):
        ok = False
        status += "; rejected: the boundary crosses itself (contact is off: contact=True models it)"
    fwd = SimpleNamespace(x=np.array(x0, dtype=float), success=ok, status=status, iterations=0)
    return fwd, (bool(chk.stable), lam, residual)


def _forward_messages(fwd, what: str, gap: float, gap_tol: float, inverted: bool) -> list[str]:
    """Why the forward re-solve (``what``) does not confirm the design's state: it failed, it ended more than
    ``gap_tol`` away, or the design's state inverts an element."""
    msgs = []
    if not fwd.success:  # the reason the solve's state was rejected, not the solver's success status before it
        status = str(fwd.status)
        why = status.split("; rejected: ", 1)[1] if "; rejected: " in status else status
        msgs.append(f"{what} failed ({why})")
    if not np.isfinite(gap) or gap > gap_tol:
        msgs.append(f"gap {gap:.3g} between the design's state and the forward re-solve exceeds {gap_tol:.3g}")
    if inverted:
        msgs.append("the design's state inverts an element (det F <= 0)")
    return msgs


def _target_messages(target_check, target_residual) -> list[str]:
    """Why the target fails its own check (unstable, or not an equilibrium of its external driving): the
    lines both verifications add; none without a target check (``None``)."""
    msgs = []
    if target_check is not None and not target_check.stable:
        msgs.append(f"the target is not a stable equilibrium of its external driving ({target_check.n_negative} "
                    f"direction(s) of negative curvature, {target_check.n_zero} zero)")
    if target_residual is not None and target_residual > 1e-5:
        msgs.append(f"the target is not an equilibrium of its external driving (residual {target_residual:.3g})")
    return msgs


def _verify_contact(units, mus, a, result, x, y, w, radius, start, tol, gap_tol, ckw, target_check, target_residual,
                    t0, hold=None) -> Verification:
    """:func:`verify_design` with contact, on the caller's body (``units.mesh``; ``x`` the design's state on
    the unit body)."""
    mesh, material, L = units.mesh, units.material, units.length
    xc = x * L
    opts = dict(muscle_model=result.muscle_model, stiffness=result.stiffness, anchor_radius=radius, tol=tol,
                held=hold)
    guess = "predictor" if start == "rest" else xc
    fwd = solve_internal(mesh, material, mus, np.clip(a, 0.0, 0.999), initial_guess=guess, align_to_rest=False,
                         **opts, **ckw)
    fx = np.asarray(fwd.x, dtype=float)
    fixed_frame = bool(ckw.get("obstacles")) or hold is not None
    moved = fx - xc if fixed_frame else align(xc, fx).apply(xc) - fx
    gap = float(np.linalg.norm(moved, axis=1).max())
    r = fx - y * L
    fdiff = float(np.sqrt((w * (r ** 2).sum(1)).sum() / w.sum())) if hold is not None else \
        align(fx, y * L, w).difference
    inverted = not upright(units.unit_mesh, x)
    msgs = []
    if inverted:
        pd, residual = False, float("nan")
    elif fwd.success and gap <= SAME_STATE_RTOL * mesh.size:
        pd, residual = bool(fwd.stable), float(fwd.residual)  # the forward solve's own check answers
    else:
        pd, residual, _ = contact_minimum(mesh, material, mus, a, xc, ckw, **opts)
    msgs += _forward_messages(fwd, "forward re-solve with contact", gap, gap_tol, inverted)
    if not inverted and (not pd or not residual <= tol):
        msgs.append("the design's state is not a stable equilibrium with its contacts (a contact solve started "
                    f"there moves away, fails or finds a saddle; residual {residual:.3g})")
    msgs += _target_messages(target_check, target_residual)
    return Verification(passed=not msgs, gap=gap, gap_tol=gap_tol, forward_success=bool(fwd.success),
                        forward_status=fwd.status, forward_difference=float(fdiff), residual=residual,
                        positive_definite=bool(pd), min_eigenvalue=float("nan"), message="; ".join(msgs),
                        time=time.perf_counter() - t0,
                        target_stable=None if target_check is None else bool(target_check.stable),
                        contact=fwd.contact)
