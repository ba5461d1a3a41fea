"""Driving-quantity design: :func:`design_contractions`, one entry for every method."""

from __future__ import annotations

import logging
import time
import warnings
from typing import Sequence
import numpy as np
from numpy.typing import ArrayLike

from ..core.guards import interruptible
from ..mechanics.backends import check_options
from ..body.fingerprint import mesh_fingerprint
from ..body.mesh import Mesh
from ..body.muscles import Muscle
from ..core.checks import as_float_array, positive_float, positive_int
from ..mechanics.align import align
from ..mechanics.anchors import body_size, check_anchor_radius
from ..mechanics.blas import one_blas_thread
from ..mechanics.equilibrium import check_held, solve_internal
from ..mechanics.loadsteps import upright
from ..mechanics.obstacles import check_obstacles
from ..mechanics.units import Units
from ..plot.style import muscle_label
from .contactdesign import check_design_contact, gradient_method, unit_contact
from .contactroute import design_gradient_first
from .nlp import ACCEPTABLE, run_flattened
from .fabrication import WALL_FRACTION
from .fallback import FALLBACK_METHOD, NESTED_HINT, design_with_fallback
from .problem import ForwardSolver, DesignProblem, check_inputs, fixture_overlaps, initial_guess_of, short_ropes
from .results import DesignResult, METHODS, MuscleWarning, report_muscles
from .rivals import run_derivative_free, run_nested
from .verify import verify_design

_LOG = logging.getLogger(__name__)

#: how often a design whose end fixtures meet is made again with the muscles concerned capped lower
FIXTURE_REDESIGNS = 2
#: the share beyond ``2 r + wall`` its ends are aimed at when a muscle is capped again
FIXTURE_MARGIN = 0.01

__all__ = ['check_design_options', 'design_contractions', 'warn_saturated']


# ---------------------------------------------------------------------------------------------- public API
@interruptible()  # Ctrl-C inside the design NLP (CasADi swallows it) raises KeyboardInterrupt
@one_blas_thread()  # as the forward solves run: the design NLP's MUMPS too (see mdsr_opt.mechanics.blas)
def design_contractions(mesh: Mesh, material, muscles: Sequence[Muscle], target: ArrayLike, *,
                        method: str | None = None, a_max: float = 0.6, initial_guess: ArrayLike | None = None,
                        weights: ArrayLike | None = None, interior_weight: float = 0.5,
                        muscle_model: str = "cable", stiffness: float = 10.0, anchor_radius: float | None = None,
                        tol: float | None = None,
                        max_iter: int | None = None, hessian: str = "exact", scaling: str = "auto",
                        warm_start: bool | str | ArrayLike = True, outer: str = "nelder-mead", options: dict | None = None,
                        inner_tol: float = 1e-10, verify: bool | str = True, skip_verification=None,
                        gap_rtol: float = 1e-5,
                        derivatives: str = "numeric", contact: bool = False, obstacles=None,
                        contact_gap: float | None = None, fixture_wall: float | None = None,
                        held=None) -> DesignResult:
    """Find the contractions that make the muscle-driven body match ``target`` after rigid alignment.

    Parameters
    ----------
    mesh, material : the body.
    muscles : sequence of Muscle (or node lists), at least one, along mesh edges.
    target : (n, 2) array
        Target node positions, in any pose (only the shape matters).
    method : {"flattened", "nested", "derivative-free"}, optional
        See the module docstring. Default ``"flattened"``, or ``"nested"`` with ``held`` nodes (the flattened
        NLP pins the three gauge coordinates only). With contact and no method: that method without the
        contacts, kept when a forward solve with them from rest at its contractions touches nothing and
        lands on its state and it passes its verification with them; else ``"derivative-free"`` with the
        contacts, started from its contractions (:mod:`~mdsr_opt.synthesis.contactdesign`; ``method`` of
        the result says which, ``status`` why). ``"derivative-free"`` named with contact searches with the
        contacts from the start; ``"flattened"`` and ``"nested"`` named with contact are refused. Without
        contact, a default flattened design that fails (not converged, or rejected by its verification) is
        made again by ``"nested"`` (:mod:`~mdsr_opt.synthesis.fallback`; the result's ``method``,
        ``fallback`` and ``status`` say so); a named ``"flattened"``, or one given IPOPT ``options``, is not,
        its failure's ``status`` suggesting ``"nested"``.
    a_max : float, default 0.6
        Upper bound on every contraction, in ``(0, 1)``. A rope mostly inside its end patches gets a lower
        one, :func:`~mdsr_opt.synthesis.problem.contraction_caps`: its free part (outside its end patches)
        shortens by at most ``max(a_max, 0.6)``, or a little more than the target shortens it.
    initial_guess : (m,) array, optional
        Starting contractions; default: each muscle's geometric contraction ``1 - L_target / L_rest``
        clipped to ``[0, 0.9 a_max]``.
    weights : (n,) array, optional
        Node weights ``e_i``; default :func:`~mdsr_opt.mechanics.align.node_weights` with ``interior_weight``.
    interior_weight : float in [0.3, 0.7], default 0.5
    muscle_model : {"cable", "springs"}, default "cable"
        As in :func:`~mdsr_opt.solve_internal`: the exact rope (its path length is ``(1 - a) L0``, its
        tension a multiplier) or the paper's per-segment dummy springs.
    stiffness : float, default 10
        Muscle spring stiffness relative to ``E t`` (springs only).
    anchor_radius : float, optional
        Radius of the rigid patch at each muscle end (a length, >= 0); default
        :func:`~mdsr_opt.mechanics.anchors.default_anchor_radius` (a fraction of the body's size).
    fixture_wall : float, optional
        The wall (a length, >= 0) the two end fixtures of a rope (disks of ``anchor_radius``) keep between
        them in the designed state: no contraction leaves less than ``2 anchor_radius + fixture_wall`` of a
        taut rope between its ends (:func:`~mdsr_opt.synthesis.problem.fixture_caps`), and a design whose
        state does (:func:`~mdsr_opt.synthesis.problem.fixture_overlaps`) is no success, its ``status``
        naming the rope and the lengths. Default: the fabrication's default wall,
        :data:`~mdsr_opt.synthesis.fabrication.WALL_FRACTION` of the body's diameter.
    tol : float, optional
        Optimiser tolerance: IPOPT's ``tol`` (flattened, default 1e-10), the projected-gradient tolerance
        (nested, default 1e-10), the tolerance on ``a`` (derivative-free, default 1e-7: Nelder-Mead's
        ``xatol``, its simplex's extent in every contraction; its ``fatol`` bounds the spread of the
        simplex's differences as a share of the body's size, :data:`~mdsr_opt.synthesis.rivals.DIFF_ATOL`,
        so the test means the same in any units: :func:`~mdsr_opt.synthesis.rivals.run_derivative_free`).
    max_iter : int, optional
        IPOPT iterations (default 500), L-BFGS-B iterations (default 500), or function evaluations
        (derivative-free, default ``400 * m``).
    hessian : {"exact", "gauss-newton"}
        Flattened only: the exact Hessian of the Lagrangian, or the objective's Gauss-Newton Hessian.
    scaling : {"auto", "size"}
        Flattened only: objective over ``sum(e) h^2`` and constraints over ``E t h`` (``h`` the mean edge
        length), or the objective normalised by the body's size instead (for comparison studies).
    warm_start : {True, "target", "rest", False} or (n, 2) array
        Flattened only: start the NLP from an equilibrium at the initial contractions, found by a forward
        solve started from the target shape (``True`` or ``"target"``: any equilibrium, not checked for
        stability; from rest, stable, when that solve fails; and the whole design repeated from rest when
        its verification fails), from a shape given as an array (in any pose; handled as the target is: e.g.
        an earlier design's state, near an equilibrium at these contractions) or from rest (``"rest"``: the
        stable equilibrium load stepping reaches); ``False`` starts from the rest shape itself. The verification always solves from rest. Started from
        a reachable target the forward solve takes one or two iterations instead of two load steps.
    derivatives : {"numeric", "assembled", "casadi"}
        Flattened only, how IPOPT gets the NLP's exact derivatives: ``"numeric"``, numpy callbacks with
        nothing symbolic to build; ``"assembled"``, an MX graph assembled term by term from small per-term
        functions (linear in the mesh size); ``"casadi"``, the NLP in SX differentiated by CasADi (the
        reference; slow to build). All are exact; iterates agree to rounding.
    outer : {"nelder-mead", "powell"}
        Derivative-free only: the scipy method.
    options : dict, optional
        Extra options for IPOPT (flattened, without the ``ipopt.`` prefix) or scipy's ``minimize``
        (Nelder-Mead's ``fatol`` is a share of the body's size, its objective the difference over the size).
    inner_tol : float
        Tolerance of the forward solves (the scaled KKT residual of :func:`~mdsr_opt.solve_internal`); the
        verification uses it too, or the solver's default 1e-8 when that is tighter.
    verify : {True, "rest", "design", False}
        Run :func:`verify_design` (recommended; without it ``success`` reflects the optimiser only, and
        nothing checks that the design's state is stable or reached from rest: the warm start from the
        target is not checked for stability either). ``True`` or ``"rest"``: its forward re-solve starts
        from rest (it also asks that a solve from the rest shape lands on the design's state);
        ``"design"``: it starts from the design's state, and certifies that state a stable equilibrium of
        the designed contractions (the forward solver's KKT residual within its tolerance, the reduced
        Hessian positive definite) without asking where a solve from rest lands, at a fraction of the
        cost. A flattened design that IPOPT ends at its acceptable tolerances (``status`` starting
        ``"Solved_To_Acceptable_Level"``) is a success only when verified.
    skip_verification : callable, optional
        For a caller that discards some designs before using them (:func:`~mdsr_opt.synthesis.acceptance.
        design_active`, which makes a layout with idle muscles again without them): called with the design
        found, before its verification; a non-empty string it returns is why the verification is left out
        (the result has no ``verification``, its ``status`` says so, and it must not be used as a verified
        design). The flattened design asks it first with a preview (``contractions``, ``slack`` as the
        tension polish would leave them, ``success``) and leaves a design it discards unpolished.
    gap_rtol : float
        Verification tolerance on the state gap, relative to ``mesh.size``.
    contact, obstacles, contact_gap :
        Contact, as in :func:`~mdsr_opt.solve_internal`: self-contact of the boundary (``contact=True``) and
        rigid obstacles (:class:`~mdsr_opt.Disk`, :class:`~mdsr_opt.HalfPlane`, :class:`~mdsr_opt.Obstacle`,
        in the frame of the body at rest, which the forward solves then hold at its gauge, or at its ``held``
        nodes: give them for a body mounted on a base, as :func:`design_pipeline` does). Every forward
        solve of the design and the verification's (from rest, and the design state's stability on the
        tangent space of its pushing contacts) models them; the design's state ``x`` stays in the obstacles'
        frame. The search takes them by ``method="derivative-free"`` only; without a method a gradient design
        that never touches them is checked with them and kept (``method`` above;
        :mod:`~mdsr_opt.synthesis.contactdesign`); ``tol``, ``max_iter``, ``outer`` and ``options`` are then
        the derivative-free search's, when it runs. ``contact`` of the result reports the verified state's
        contact forces.
    held : node indices, optional
        Nodes clamped at their rest positions in every forward solve and the verification, as a robot
        mounted on its base (:func:`~mdsr_opt.solve_internal`'s ``held``; at least two nodes, integers in range,
        each once). Without them (the default) the body is the paper's free body and the target is matched
        after the best rigid alignment; with them the pose is the mount's, so the target is moved rigidly
        onto the held nodes' rest positions (the identity for a target solved with them anchored) and
        matched where it is, without alignment (``rotation`` the identity, ``translation`` zero), and
        obstacles stand where they are relative to the mount. Give the target's anchors to design a gripper
        clamped where its target was. Designed by ``"nested"`` or ``"derivative-free"`` (refused with
        ``"flattened"``). Verify such a design with :func:`verify_design` with the same ``held``.

    Returns
    -------
    DesignResult
        A muscle whose contraction ends at ``a_max`` is flagged in ``saturated`` and named in a
        :class:`~mdsr_opt.synthesis.results.MuscleWarning`.

    Raises
    ------
    TypeError, ValueError
        Bad input: a target of the wrong shape, with NaN or inf, or inverting a triangle (a mirror image
        inverts all; :func:`~mdsr_opt.body.checks.check_target_shape`, the check of every design entry
        point), muscles not on the mesh, ``a_max`` outside (0, 1), an empty muscle list, an unknown method.

    Example
    -------
    >>> import numpy as np
    >>> from mdsr_opt import Mesh, Muscle, NeoHookean
    >>> mesh = Mesh.rectangle(4.0, 1.0, 16, 4)
    >>> stretched = mesh.points * 1.1                     # muscles cannot stretch a body
    >>> res = design_contractions(mesh, NeoHookean(1.0, 0.3), [Muscle(range(1, 16))], stretched)
    >>> res.success, res.difference > 0.01
    (True, True)
    """
    initial = initial_guess
    clock0 = time.perf_counter()
    if method is None and (contact is True or check_obstacles(obstacles)):
        # contact, no method named: a gradient design without it, checked with it, else derivative-free
        common = {"a_max": a_max, "initial_guess": initial_guess, "weights": weights,
                  "interior_weight": interior_weight, "muscle_model": muscle_model, "stiffness": stiffness,
                  "anchor_radius": anchor_radius, "warm_start": warm_start, "inner_tol": inner_tol, "verify": verify,
                  "skip_verification": skip_verification, "gap_rtol": gap_rtol, "fixture_wall": fixture_wall,
                  "held": held}
        ckw = check_design_contact(mesh, material, contact, obstacles, contact_gap, None)  # at the door
        if outer not in ("nelder-mead", "powell"):
            raise ValueError(f"outer must be 'nelder-mead' or 'powell', got {outer!r}")
        check_design_options(options, "derivative-free", outer)
        return design_gradient_first(design_contractions, mesh, material, muscles, target, clock0, common,
                                     {"hessian": hessian, "scaling": scaling, "derivatives": derivatives},
                                     {"tol": tol, "max_iter": max_iter, "outer": outer, "options": options},
                                     {"contact": contact, "obstacles": obstacles, "contact_gap": contact_gap},
                                     ckw, VERIFY_TOL)
    # a default flattened design that fails is made again by the nested method, unless the caller addressed the
    # flattened method: named it, or gave IPOPT options (synthesis.fallback)
    named = method is not None or options is not None
    if method is None:  # held nodes: the flattened NLP pins the gauge only
        method = gradient_method(held)
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(map(repr, METHODS))}, got {method!r}")
    if hessian not in ("exact", "gauss-newton"):
        raise ValueError(f"hessian must be 'exact' or 'gauss-newton', got {hessian!r}")
    if scaling not in ("auto", "size"):
        raise ValueError(f"scaling must be 'auto' or 'size', got {scaling!r}")
    if outer not in ("nelder-mead", "powell"):
        raise ValueError(f"outer must be 'nelder-mead' or 'powell', got {outer!r}")
    if isinstance(warm_start, np.bool_):
        warm_start = bool(warm_start)
    shaped = isinstance(warm_start, (np.ndarray, list, tuple))  # a start shape: checked with the mesh below
    if not shaped and not (isinstance(warm_start, bool) or
                           (isinstance(warm_start, str) and warm_start in ("target", "rest"))):
        raise ValueError(f"warm_start must be True, False, 'target', 'rest' or an (n, 2) array of node positions, "
                         f"got {warm_start!r}")
    if derivatives not in ("numeric", "assembled", "casadi"):
        raise ValueError(f"derivatives must be 'numeric', 'assembled' or 'casadi', got {derivatives!r}")
    options = check_design_options(options, method, outer)
    if isinstance(verify, np.bool_):
        verify = bool(verify)
    if not (isinstance(verify, bool) or (isinstance(verify, str) and verify in ("rest", "design"))):
        raise ValueError(f"verify must be True, False, 'rest' or 'design', got {verify!r}")
    if skip_verification is not None and not callable(skip_verification):
        raise TypeError(f"skip_verification must be a function of the design or None, got "
                        f"{type(skip_verification).__name__}")
    mus, y, a_max, w, stiffness, a0 = check_inputs(mesh, material, muscles, target, a_max, weights,
                                                    interior_weight, muscle_model, stiffness, initial)
    ckw = check_design_contact(mesh, material, contact, obstacles, contact_gap, method)
    hold = check_held(mesh, held, mus)
    if hold is not None and method == "flattened":
        raise ValueError("held nodes are designed by method='nested' or 'derivative-free' (the flattened NLP pins "
                         "the body's three gauge coordinates only), got method='flattened'")
    anchor_radius = check_anchor_radius(mesh, anchor_radius)
    fixture_wall = WALL_FRACTION * body_size(mesh) if fixture_wall is None else \
        positive_float(fixture_wall, "fixture_wall", allow_zero=True)
    if shaped:
        warm_start = as_float_array(warm_start, "warm_start", shape=(mesh.n_nodes, 2))
    m = len(mus)
    if tol is None:
        tol = {"flattened": 1e-10, "nested": 1e-10, "derivative-free": 1e-7}[method]
    tol = positive_float(tol, "tol")
    if max_iter is None:
        max_iter = 400 * m if method == "derivative-free" else 500
    max_iter = positive_int(max_iter, "max_iter")
    inner_tol = positive_float(inner_tol, "inner_tol")
    gap_rtol = positive_float(gap_rtol, "gap_rtol")
    if a0 is None:
        a0 = initial_guess_of(mesh, mus, y, a_max)

    # designed on the unit body (size and E t about 1: every tolerance means the same in any units), the
    # result mapped back to the caller's units before its verification
    units = Units(mesh, material)
    prob = DesignProblem(units.unit_mesh, units.unit_material, mus, units.state_in(y), w, muscle_model, stiffness,
                         a_max, units.to_unit(anchor_radius), units.to_unit(fixture_wall), held=hold)
    # within each muscle's cap (a rope mostly inside its end patches may shorten less than a_max)
    a0 = np.minimum(a0, np.where(prob.a_upper < a_max, 0.9 * prob.a_upper, prob.a_upper))
    warm = "target" if warm_start is True else warm_start
    if isinstance(warm, np.ndarray):
        warm = units.state_in(warm)  # a start shape, on the unit body
    args = (prob, method, a0, tol, int(max_iter), hessian, scaling, outer, options, inner_tol, derivatives, clock0,
            verify, gap_rtol, units, ckw, skip_verification)
    res = _fixtures_apart(args, warm, clock0, fixture_wall)
    if method == "flattened" and not res.success and not named:  # the nested method from the best start
        nested = (prob, FALLBACK_METHOD, None, tol, int(max_iter), hessian, scaling, outer, {}) + args[9:]
        res = design_with_fallback(res, lambda start: _fixtures_apart(nested[:2] + (start,) + nested[3:], "rest",
                                                                      clock0, fixture_wall),
                                   a0, prob.a_upper, clock0)
    elif method == "flattened" and not res.success:
        res.status += NESTED_HINT
    res.muscle_names = tuple(muscle_label(mu, i) for i, mu in enumerate(mus))
    res.stress_unit = getattr(material, "stress_unit", None)
    res.fixture_wall = float(fixture_wall)  # a length: the caller's units
    res.held = None if hold is None else tuple(int(i) for i in hold)
    if res.saturated.any():
        warn_saturated(res, mus)
    return res


def _fixtures_apart(args, warm, clock0, fixture_wall) -> DesignResult:
    """:func:`_design_from`, made again (at most :data:`FIXTURE_REDESIGNS` times) with the muscles whose end
    fixtures meet in the designed state capped below the contraction that brought them there."""
    prob, method, a0 = args[:3]
    mus, mesh = prob.muscles, args[14].mesh
    res = _design_from(args, warm, clock0)
    for _ in range(FIXTURE_REDESIGNS):
        # end fixtures that meet in the designed state (a rope slack, or its patches' edges shortened):
        # their muscles capped below the contraction that brought them there, and the design made again
        met = (fixture_overlaps(res.x, mus, res.anchor_radius, fixture_wall, 1e-9 * mesh.size, rest=mesh.points)
               if np.isfinite(res.x).all() else [])
        if not met:
            break
        for c, d, need in met:
            scale = (1.0 - res.contractions[c]) * need * (1.0 + FIXTURE_MARGIN) / max(d, 1e-300)
            prob.a_upper[c] = min(prob.a_upper[c], max(0.0, 1.0 - scale))
        caps = ", ".join(f"{muscle_label(mus[c], int(c))} to a <= {prob.a_upper[c]:.4g}" for c, _d, _n in met)
        args = (prob, method, np.minimum(a0, prob.a_upper)) + args[3:]
        first = res
        res = _design_from(args, warm, clock0)
        res.status += f" (designed again with {caps}: at the contractions first found their end fixtures met)"
        res.count_in([first], clock0)
    return res


def _design_from(args, warm, clock0) -> DesignResult:
    """:func:`_design` warm-started at ``warm``, and again from rest when a design warm-started from the
    target fails its verification (the answer when that one succeeds)."""
    res, fwd, rejected = _design(*args, warm=warm)
    if fwd.started_from == "target" and rejected:
        # the equilibrium found from the target may lie on another branch than the one reached from rest
        # (the verification's): the design again, warm-started from rest, is the answer when it succeeds
        _LOG.info("design: rejected by its verification (%s); designing again from rest",
                  res.verification.message if res.verification is not None else res.status)
        again, _, _ = _design(*args, warm="rest")
        where = "given shape" if isinstance(warm, np.ndarray) else "target"
        first = res
        if again.success:
            res = again
            res.status += f" (warm-started from rest after the design warm-started from the {where} failed " \
                          f"its verification: {first.verification.message})"
        else:
            # the second design's reason once: said in full only when it differs from the first's
            why = again.verification.message if again.verification is not None else again.status
            same = first.verification is not None and why == first.verification.message
            res.status += " (again from rest: " + ("rejected the same way)" if same else f"{again.status})")
        # the counters and clocks cover both designs; the history is the returned one's
        res.iterations = first.iterations + again.iterations
        res.n_forward = first.n_forward + again.n_forward
        res.inner_iterations = first.inner_iterations + again.inner_iterations
        res.time = time.perf_counter() - clock0
        res.build_time = max(first.build_time, again.build_time)
        res.solve_time = res.time - res.build_time
    return res


def warn_saturated(res: DesignResult, muscles) -> None:
    """Warn (:class:`~mdsr_opt.synthesis.results.MuscleWarning`) naming the muscles of ``res`` whose
    contraction is at its bound, ``a_max`` or its end fixtures' cap
    (:attr:`~mdsr_opt.synthesis.results.DesignResult.saturated`)."""
    sat, capped = np.flatnonzero(res.saturated), res.capped
    names = ", ".join(f"{muscle_label(muscles[i], i)} (a = {res.contractions[i]:.4g}"
                      + (", the most its rope can shorten between its end fixtures)" if capped[i] else ")")
                      for i in sat)
    how = "raise a_max, add muscles" if not capped[sat].all() else "add muscles, give smaller end fixtures"
    bound = f"their bound (a_max = {res.a_max:g}, or their end fixtures' cap)" if capped.any() else \
        f"a_max = {res.a_max:g}"
    warnings.warn(f"muscle(s) {names} saturated at {bound}: the design is the best within the bound, not the "
                  f"target; {how} or accept the difference {res.difference:.3g}", MuscleWarning, stacklevel=5)


def _design(prob, method, a0, tol, max_iter, hessian, scaling, outer, options, inner_tol, derivatives, clock0,
            verify, gap_rtol, units, ckw, skip, warm) -> tuple[DesignResult, ForwardSolver, bool]:
    """One design by ``method`` from ``a0`` (``warm``: the flattened NLP's warm start) of the unit problem
    ``prob``, checked, mapped to the caller's ``units`` and verified there; returns the result, the forward
    solver it used and whether the verification rejected a design the optimiser had found."""
    mesh = units.mesh  # the caller's body; the design runs on its unit copy, umesh
    umesh, mus, y, w = prob.mesh, prob.muscles, prob.y, prob.w
    fwd = ForwardSolver(prob, inner_tol, 200)
    fwd.contact = unit_contact(ckw, units)
    t_solve0 = time.perf_counter()

    def clock():
        return time.perf_counter() - t_solve0

    build_time = prob.build_time
    bt = 0.0
    if method == "flattened":
        out, status, iters, bt = run_flattened(prob, a0, fwd, tol, max_iter, hessian, scaling, warm,
                                                options, clock, derivatives, defer=skip if verify else None)
        build_time += bt
        kappa = None
        if out is None:
            x, a, ok, hist, d0 = fwd.x, a0, False, [], float("nan")
        else:
            x, a, ok, hist, d0 = out["x"], out["a"], out["success"], out["history"], out["initial_difference"]
            kappa = out["kappa"]
    else:
        if method == "nested":
            obj, ok, status, iters = run_nested(prob, a0, fwd, tol, max_iter, options, clock, units.length)
        else:
            obj, ok, status, iters = run_derivative_free(prob, a0, fwd, tol, max_iter, outer, options, clock,
                                                         units.length)
        hist = obj.history
        kappa = None
        d0 = hist[0][1] if hist else float("nan")
        if obj.best is None:
            x, a, ok = fwd.x, a0, False
        else:
            _J, a, x = obj.best
    build_time += fwd.build_time
    if ckw and np.all(np.isfinite(a)):
        # the state a servo reaches from rest at these contractions: contact states reached along the search's
        # path of warm starts may differ from it by about the contact gap (another set of touching pairs)
        r = solve_internal(umesh, prob.material, mus, np.clip(a, 0.0, 0.999), muscle_model=prob.muscle_model,
                           stiffness=prob.stiffness, anchor_radius=prob.anchor_radius, tol=inner_tol,
                           align_to_rest=False, held=prob.held, **fwd.contact)
        if r.success:
            x = np.asarray(r.x, dtype=float).reshape(-1)
    if upright(umesh, x) and not ckw:  # the equilibrium at a to the verification's tolerance (the NLP's rows meet their own)
        x = prob.polished(a, x, min(inner_tol, VERIFY_TOL))
    x2 = x.reshape(-1, 2)
    # aligned to rest, unless obstacles or held nodes hold the body in their frame
    x_rest = x2 if ckw.get("obstacles") or prob.held is not None else align(x2, umesh.points).apply(x2)
    al = prob.alignment(x_rest)
    t_end = time.perf_counter()
    if method == "flattened":  # seconds of solving: the NLP's build is not part of the trace
        hist = [(t - bt, d) for t, d in hist] + [(t_end - t_solve0 - bt, al.difference)]
    total = t_end - clock0
    res = DesignResult(method=method, contractions=np.asarray(a, dtype=float).copy(), x=x_rest, rotation=al.R,
                       translation=al.t, difference=al.difference, success=bool(ok), status=status,
                       iterations=int(iters), n_forward=fwd.n_solves, inner_iterations=fwd.iterations,
                       build_time=build_time, solve_time=total - build_time, time=total,
                       initial_contractions=np.asarray(a0, dtype=float).copy(), initial_difference=float(d0),
                       a_max=prob.a_max, muscle_model=prob.muscle_model, stiffness=prob.stiffness, history=list(hist),
                       anchor_radius=prob.anchor_radius, rest_lengths=prob.L0.copy(),
                       rest_mesh=mesh_fingerprint(mesh), a_upper=np.asarray(prob.a_upper, dtype=float).copy())
    err = np.linalg.norm(al.apply(x_rest) - prob.y, axis=1)  # per node, after the same rigid motion
    if err.size and np.isfinite(err).all():
        k = int(np.argmax(err))
        res.max_error, res.max_error_node = float(err[k]), k
        res.relative_max_error = float(err[k]) / body_size(umesh)
    report_muscles(prob, res, x, kappa)
    if method != "flattened" and prob.muscle_model == "cable" and res.slack.any():
        # any contraction below the one its path reached leaves a rope slack with the same shape: report
        # that one (the rope then just reaches its length, at zero tension), as the flattened design's
        # polish does, rather than wherever the outer search stopped on the flat side
        sl = res.slack & np.isfinite(res.achieved)
        res.contractions[sl] = np.clip(res.achieved[sl], 0.0, prob.a_upper[sl])
    capped = np.flatnonzero((prob.a_upper < prob.a_max) & (res.contractions >= prob.a_upper - 1e-3))
    if len(capped):  # at a cap below a_max: the best within the bound, as a contraction at a_max is
        res.status += "; at the most their ropes can shorten (the end fixtures hold much of each rope, or would meet): " \
                      + ", ".join(f"{muscle_label(mus[c], int(c))} a = {prob.a_upper[c]:.4g}" for c in capped)
    if not upright(umesh, res.x):
        res.success = False
        res.status += "; rejected: the design's state inverts an element"
    met = (fixture_overlaps(res.x, mus, prob.anchor_radius, prob.fixture_wall, rest=umesh.points)
           if prob.fixture_wall is not None else [])
    short = short_ropes(umesh.points, mus, prob.anchor_radius, prob.fixture_wall) if prob.fixture_wall is not None else []
    if short:  # no contraction helps: said, the layout's to fix (routing drops such stubs)
        res.status += "; " + "; ".join(
            f"rope {muscle_label(mus[c], int(c))} is shorter at rest ({l0 * units.length:.4g}) than its two end "
            f"fixtures need ({need * units.length:.4g}): this layout does not fit its fixtures" for c, l0, need in short)
    if met:  # the fixtures would meet in the silicone: nothing a workshop can build (the prototype's fixtures)
        L, r = units.length, prob.anchor_radius * units.length
        res.success = False
        res.status += "; rejected: end fixtures meet in the designed state: " + "; ".join(
            f"rope {muscle_label(mus[c], int(c))} at a = {res.contractions[c]:.4g} leaves {d * L:.4g} of rope between "
            f"its end fixtures' centres ({mus[c].length(umesh.points) * L:.4g} at rest), less than two fixtures of radius "
            f"{r:.4g} with a wall {prob.fixture_wall * L:.4g} need ({need * L:.4g})" for c, d, need in met)
    res = _in_units(res, units)
    if res.success and not verify and status.startswith(ACCEPTABLE):
        res.success = False
        res.status += "; not verified (verify=False), so IPOPT's acceptable exit is not a success"
    why = str(skip(res) or "") if verify and skip is not None and res.success else ""
    if why:  # the caller discards this design (and verifies the one it keeps)
        res.status += f"; not verified: {why}"
        return res, fwd, False
    if verify:
        if ckw:  # a forward contact solve from rest (load stepping): the longest silent part after the search
            _LOG.info("design: verifying contractions [%s] with contact",
                      ", ".join(f"{c:.4g}" for c in res.contractions))
        v = verify_design(mesh, units.material, mus, res, y * units.length, weights=w, gap_rtol=gap_rtol,
                          tol=min(inner_tol, VERIFY_TOL), start="design" if verify == "design" else "rest",
                          held=prob.held, **ckw)
        res.verification = v
        if res.success and not v.passed:
            res.success = False
            res.status += f"; rejected by verification: {v.message}"
            return res, fwd, True
    return res, fwd, False


#: the verification's tolerance when the forward solves' ``inner_tol`` is looser: ``solve_internal``'s
#: default, so that a verified design solves forward with the defaults too
VERIFY_TOL = 1e-8


def _in_units(res: DesignResult, units) -> DesignResult:
    """A design of the unit problem in the caller's units (in place; returned): lengths times
    ``units.length``, tensions times ``units.force``."""
    if units.identity:
        return res
    L = units.length
    res.x = res.x * L
    res.translation = res.translation * L
    res.difference, res.initial_difference = res.difference * L, res.initial_difference * L
    res.max_error = res.max_error * L
    res.history = [(t, d * L) for t, d in res.history]
    res.anchor_radius = res.anchor_radius * L
    res.rest_lengths, res.stroke = res.rest_lengths * L, res.stroke * L
    res.tension = res.tension * units.force
    return res


def check_design_options(options, method: str = "flattened", outer: str = "nelder-mead") -> dict:
    """Check a design's solver ``options`` before any work: IPOPT's options (without the ``ipopt.`` prefix)
    for ``method="flattened"``, else those of ``scipy.optimize.minimize`` (L-BFGS-B for ``"nested"``,
    Nelder-Mead or Powell for ``"derivative-free"`` after ``outer``).

    Returns a copy (``{}`` for None). Raises ``TypeError`` for a non-mapping, ``ValueError`` naming an
    unknown option or an invalid value (instead of a CasADi error when the solver is built).

    Example
    -------
    >>> check_design_options({"max_cpu_time": 10.0})
    {'max_cpu_time': 10.0}
    >>> check_design_options({"bogus": 1})
    Traceback (most recent call last):
    ...
    ValueError: unknown ipopt option 'bogus'
    """
    if options is None:
        return {}
    if not hasattr(options, "items"):
        raise TypeError(f"options must be a dict of solver options, got {type(options).__name__}")
    options = dict(options)
    if method == "flattened":
        try:
            check_options("ipopt", {f"ipopt.{k}": v for k, v in options.items()})
        except (ValueError, TypeError) as exc:  # name the option as the caller spelled it (no prefix)
            raise type(exc)(str(exc).replace("'ipopt.", "'")) from None
    else:
        scipy_method = "L-BFGS-B" if method == "nested" else \
            {"nelder-mead": "Nelder-Mead", "powell": "Powell"}[outer]
        check_options(f"scipy:{scipy_method}", options)
    return options
