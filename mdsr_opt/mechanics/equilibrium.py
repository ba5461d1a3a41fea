"""External and internal driving: ``solve_external`` (anchors and drags) and ``solve_internal``
(muscles contracted in a free body), built on :mod:`mdsr_opt.mechanics.loadsteps`."""

from __future__ import annotations

import time
from typing import Mapping, Sequence
import numpy as np

from ..core.errors import LayoutError
from ..core.guards import interruptible
from ..body.mesh import Mesh
from ..body.muscles import Muscle, check_contractions, check_distinct_ropes, check_muscles, label_of
from ..core.checks import node_indices, positive_float
from .align import align
from .backends import CONSTRAINED_BACKENDS, supports_constraints
from .constrained import ConstrainedModel
from .anchors import check_anchor_radius, rigid_groups
from .constraints import muscle_constraints, spring_segments, spring_stiffness
from .barriersolve import solve_with_barrier
from .contactsteps import contact_spec, solve_with_contact
from .drags import drag_path
from .obstacles import HalfPlane, check_obstacles, check_prescribed
from .selfprescribed import check_prescribed_self
from . import loadsteps
from .loadsteps import (check_common, check_mesh_material, equilibrium_result, initial_guess_of, load_continuation,
                        upright)
from .model import get_model, spring_parameters
from .residual import kkt_residual
from .result import EquilibriumResult
from .stability import check_stability
from .units import Units

__all__ = ['solve_external', 'external_stability', 'solve_internal', 'in_gauge_frame', 'gauge_coordinates',
           'check_held', 'in_held_frame']


# ---------------------------------------------------------------------------------- external driving
@interruptible()  # Ctrl-C anywhere in the solve raises KeyboardInterrupt, never a result
def solve_external(mesh: Mesh, material, anchors: Sequence[int] | np.ndarray | None,
                   drags: Mapping[int, Sequence[float]] | tuple | None, *, backend: str = "ipopt",
                   tol: float = 1e-8, max_iter: int = 200, options: dict | None = None,
                   min_step: float = 1.0 / 256, verbose: bool = False,
                   initial_guess: str | np.ndarray = "predictor", obstacles=None, contact: bool = False,
                   contact_gap: float | None = None, friction: float = 0.0,
                   contact_method: str = "ipopt") -> EquilibriumResult:
    """External driving: anchors stay at rest, drag nodes move to given positions, the rest settle.

    Parameters
    ----------
    mesh, material : the body.
    anchors : node indices held at their rest positions.
    drags : ``{node: (x, y)}`` (straight moves), ``(indices, positions (k, 2))``, a
        :class:`~mdsr_opt.mechanics.drags.RigidDrag` (rotate nodes through an angle about a centre, optionally with a
        shift; load stepping follows the arc), or a list of dicts and RigidDrags. In every form, and in
        ``anchors``, node indices are integers (a float, even ``16.0``, is refused), in range and each given
        once, also when dragged twice to the same place (:func:`~mdsr_opt.core.checks.node_indices`); no node
        is both anchored and dragged.
    backend : one of :func:`available_backends`.
    tol : the tolerance contract (:mod:`~mdsr_opt.mechanics.residual`): a success has its scaled KKT residual
        (the max-norm of the free energy gradient relative to ``E t size``; ``residual``) at most ``tol``,
        in any units (the solve runs on the body scaled to a reference size and unit stiffness,
        :mod:`~mdsr_opt.mechanics.units`, and its results are mapped back).
    max_iter : iteration cap of each solve (per load step tried, as in :func:`solve_internal`), not of the
        call: ``iterations`` in the result sums them all.
    options : extra options for the backend (e.g. ``{"ipopt.print_level": 5}``).
    min_step : smallest load fraction tried before giving up, in (0, 1].
    verbose : print each accepted load step.
    initial_guess : ``"predictor"`` (default: every load step starts from a Newton predictor, at rest the
        linear-elastic solution), ``"rest"`` (each step starts from the current state, the rest shape at
        first, with only the fixed nodes moved) or an (n, 2) state to start the first step from. The load
        steps move the fixed nodes from where that state has them to their prescribed positions: along the
        drags' paths when it has them at rest, else straight (a state solved for nearby drags: a
        continuation from it, not again from rest). ``"rest"`` exists to study poor first guesses; combine
        it with ``min_step=1`` to forbid load stepping.
    obstacles : list of :class:`~mdsr_opt.HalfPlane`, :class:`~mdsr_opt.Disk`, :class:`~mdsr_opt.Obstacle` (or one)
        Rigid obstacles the body's boundary may touch but not enter (with Coulomb ``friction`` when given);
        none may hold a node at rest, and no drag may enter one. See :mod:`~mdsr_opt.mechanics.contactsolve`.
    contact : bool
        Model self-contact of the boundary (outline and holes): no crossing, a gap kept between a boundary
        node and the boundary segments it touches. Off by default (each load step then also looks for
        candidate pairs). Anchors and drags that would push prescribed parts of the body through each other
        are refused (:func:`~mdsr_opt.mechanics.selfprescribed.check_prescribed_self`). The contact report's
        forces are in ``contact["force_unit"]``, units of ``E*t*length`` as rope tensions.
    contact_gap : the gap kept by every contact, length units (default 1e-4 x the body's size).
    friction : Coulomb's coefficient between the body and the obstacles (default 0: frictionless):
        quasi-static, a lagged smoothed potential per load step (:mod:`~mdsr_opt.mechanics.friction`, which
        states its error); ``contact["friction"]`` then gives each touching node's tangential force and
        whether it slips.
    contact_method : ``"ipopt"`` (default) or ``"barrier"``
        How ``contact=True`` is solved: ``"ipopt"``, a gap constraint per candidate node-segment pair
        (:mod:`~mdsr_opt.mechanics.contactsolve`); ``"barrier"``, a smooth barrier on the node-segment
        distances within ``dhat`` (a tenth of the mean boundary edge, at most half the smallest rest distance
        of a node from a segment not ending at it) minimised by the project's Newton method with continuous
        collision detection (:mod:`~mdsr_opt.mechanics.barriersolve`; self-contact and
        :class:`~mdsr_opt.HalfPlane` obstacles, frictionless, no ``contact_gap``; backend ``"newton"`` is
        reported). A free boundary node within ``dhat`` of a half-plane at rest (a body resting on the ground)
        is refused with a ValueError: lift the body by at least ``dhat``, anchor those nodes (fixed nodes are
        left out of the planes' barrier) or use ``"ipopt"``. Its contact report gives each pair within
        ``dhat`` with its distance and the barrier's force, and the barrier's energy (``barrier_energy``),
        which ``energy`` leaves out.

        With contact the equilibrium reached can depend on the path and on the method: a body pressed against
        itself or an obstacle can have several stable states under the same load, and the load steps, the
        method and the start decide which one a solve finds. Trial 12's C-ring (203 nodes, tip turned 95
        degrees onto its lower arm): ``"ipopt"`` ends at energy 8.337, ``"barrier"`` at 7.432, and
        ``"ipopt"`` started from the barrier's state at 7.424, all three stable and free of crossings, 12 %
        apart. A contact result is a stable equilibrium, not the lowest: to look for a lower one, solve again
        by the other method or from another state (``initial_guess``) and compare energies. A solve with
        ``"ipopt"`` whose path touches nothing returns the state of the solve without contact
        (:mod:`~mdsr_opt.mechanics.contactfree`).

    Returns
    -------
    EquilibriumResult
        With contact modelled, ``contact`` holds the active pairs and their normal forces (the gap
        constraints' multipliers), the contact force on each node and on each obstacle; the residual takes
        the contact forces in, and stability is checked on the tangent space of the pushing contacts.
        Only a stable equilibrium is a success: the Hessian on the free coordinates must be positive definite
        (``stable``, ``stability``; inertia of a sparse factorisation,
        :func:`~mdsr_opt.mechanics.stability.check_stability`).
        At a saddle (e.g. the straight state of a compressed strip) the solve steps along the direction of
        negative curvature (2 % of the body size) and re-solves, up to 4 times; ``success=False`` with the
        reason when no stable state is found.

    Raises
    ------
    KeyboardInterrupt
        On Ctrl-C (SIGINT) during the solve, within about a solver iteration.
    """
    check_mesh_material(mesh, material)
    tol = check_common(tol, max_iter, backend, min_step)
    predict, x_start = initial_guess_of(initial_guess, mesh)
    n = mesh.n_nodes
    anc = node_indices(np.zeros(0, dtype=np.int64) if anchors is None else anchors, "anchors", n=n)
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
    units = Units(mesh, material)  # solved on the unit body (size 1, E t = 1), mapped back
    barrier = check_contact_method(contact_method, contact, obstacles, contact_gap, friction)
    spec = contact_spec(units, obstacles, contact, contact_gap, "ipopt" if barrier else backend, friction)
    if spec.obstacles:  # a drag into an obstacle: refused here, not a load stepping that stalls at its edge
        check_prescribed(check_obstacles(obstacles), didx, path.positions, spec.gap * units.length)
    if spec.self_contact and len(didx):  # prescribed parts pushed through each other: refused, not a stalled solve
        rest_anc = mesh.points[anc]
        check_prescribed_self(mesh, nodes, lambda s: np.vstack([rest_anc, path.positions(s)]),
                              spec.gap * units.length, anchored=len(anc))
    mesh, material = units.unit_mesh, units.unit_material
    model = get_model(mesh, material)
    t_model = time.perf_counter() - t0  # ~0 when the mesh's model was built before
    p = model.params(material)
    fixed = np.zeros(2 * n, dtype=bool)
    fixed[2 * nodes] = True
    fixed[2 * nodes + 1] = True
    order = np.argsort(np.concatenate([2 * nodes, 2 * nodes + 1]))
    anchored = mesh.points[anc]

    def values_of(s):  # fixed coordinates at load s, in the order of the mask (anchors, then drag paths)
        at = np.vstack([anchored, units.to_unit(path.positions(s))])
        return np.concatenate([at[:, 0], at[:, 1]])[order]

    values_of = _from_guess(values_of, None if isinstance(initial_guess, str) else units.state_in(x_start)[fixed])

    if barrier:
        planes = [[o.point, o.normal] for o in spec.obstacles]  # HalfPlanes on the unit body
        return units.equilibrium_out(solve_with_barrier(mesh, model, material, p, fixed, values_of,
                                                        units.state_in(x_start), tol, max_iter, min_step, verbose,
                                                        "external", units, t_model, planes=planes or None,
                                                        self_contact=spec.self_contact))
    if spec.active:
        res, _lam = solve_with_contact(mesh, model, material, lambda s: p, fixed, values_of, units.state_in(x_start),
                                       spec, tol, max_iter, options, min_step, verbose, predict, "external", units,
                                       t_model=t_model)
        return units.equilibrium_out(res)
    x, status, ok, iters, steps, t_solve, t_build = load_continuation(
        mesh, model, lambda s: p, fixed, values_of, units.state_in(x_start), backend, tol, max_iter, options,
        min_step, verbose, predict)
    return units.equilibrium_out(equilibrium_result(
        mesh, model, material, p, p, x, fixed, status, ok, iters, steps, t_model + t_build, t_solve, backend,
        "external", tol))


def check_contact_method(method, contact, obstacles, contact_gap, friction) -> bool:
    """Whether ``method`` (``contact_method`` of :func:`solve_external`) asks for the barrier; refuses an
    unknown method and what the barrier does not model."""
    if method not in ("ipopt", "barrier"):
        raise ValueError(f"contact_method must be 'ipopt' or 'barrier', got {method!r}")
    if method == "ipopt":
        return False
    obs = [] if obstacles is None else list(obstacles) if isinstance(obstacles, (list, tuple)) else [obstacles]
    if contact is not True and not obs:
        raise ValueError("contact_method='barrier' solves contact: give contact=True and/or obstacles")
    if any(not isinstance(o, HalfPlane) for o in obs) or contact_gap is not None or friction:
        raise ValueError("contact_method='barrier' models self-contact and HalfPlane obstacles, frictionless (no "
                         "Disk or Obstacle, friction or contact_gap: its gap is set by the barrier); use "
                         "contact_method='ipopt'")
    return True


def _from_guess(values_of, start):
    """The fixed coordinates' path ``values_of`` over the load, starting instead from their values ``start`` in
    a given first state (None: none given): unchanged when the state has them where the path starts (at
    rest), else straight from there to the path's end, so that a state solved for nearby drags is continued
    from, not solved again from rest through states far from it."""
    if start is None:
        return values_of
    v0, v1 = values_of(0.0), values_of(1.0)
    if np.allclose(start, v0, rtol=0.0, atol=1e-12 * max(1.0, float(np.abs(v0).max(initial=1.0)))):
        return values_of
    start = np.array(start, dtype=float)
    return lambda s: start + s * (v1 - start)


def external_stability(mesh: Mesh, material, anchors, drags, x, *, lowest: bool = False):
    """Is ``x`` a stable equilibrium of external driving with these anchors and drags?

    Parameters
    ----------
    mesh, material : the body.
    anchors, drags : as in :func:`solve_external` (only which nodes are fixed matters here).
    x : (n, 2) state, e.g. a design target.
    lowest : also estimate the lowest eigenvalue of the free Hessian (see
        :func:`~mdsr_opt.mechanics.stability.check_stability`).

    Returns
    -------
    check : StabilityCheck
        Of the energy's Hessian on the free coordinates at ``x``.
    residual : float
        Max-norm of the energy gradient on the free coordinates relative to ``E t size`` (small at an
        equilibrium).
    """
    check_mesh_material(mesh, material)
    n = mesh.n_nodes
    anc = node_indices(np.zeros(0, dtype=np.int64) if anchors is None else anchors, "anchors", n=n)
    nodes = np.union1d(anc, drag_path(drags, mesh).nodes)
    units = Units(mesh, material)  # checked on the unit body (size 1, E t = 1)
    xflat = units.state_in(mesh._check_state(x).reshape(-1))
    mesh, material = units.unit_mesh, units.unit_material
    model = get_model(mesh, material)
    p = model.params(material)
    fixed = np.zeros(2 * n, dtype=bool)
    fixed[2 * nodes] = fixed[2 * nodes + 1] = True
    residual = kkt_residual(model, xflat, p, fixed, 0.0,
                            force=material.E * material.thickness * mesh.size).value
    return units.stability_out(check_stability(model.hessian(xflat, p), ~fixed, lowest=lowest)), residual


# ---------------------------------------------------------------------------------- internal driving
def gauge_coordinates(mesh) -> tuple[int, int, int]:
    """Three gauge coordinates (node i x & y, node j one coordinate), chosen from geometry alone (cached on
    the mesh: every solve and every design asks for them)."""
    cached = mesh.__dict__.get("_gauge_coordinates")
    if cached is None:
        cached = mesh.__dict__["_gauge_coordinates"] = _gauge_coordinates(mesh)
    return cached


def _gauge_coordinates(mesh) -> tuple[int, int, int]:
    P = mesh.points
    c = P.mean(0)
    d = np.linalg.norm(P - c, axis=1)
    i = int(np.lexsort((P[:, 1], P[:, 0], d))[0])
    dj = np.linalg.norm(P - P[i], axis=1)
    j = int(np.lexsort((P[:, 1], P[:, 0], -dj))[0])
    v = P[j] - P[i]
    comp = 1 if abs(v[0]) >= abs(v[1]) else 0
    return 2 * i, 2 * i + 1, 2 * j + comp


def held_coordinates(mesh, held: np.ndarray | None, muscles=(), radius: float | None = None) -> np.ndarray:
    """The fixed-coordinate mask of internal driving: the three gauge coordinates of a free body
    (``held`` None), else both coordinates of every held node and of every node of an anchor patch of
    ``muscles`` (:func:`~mdsr_opt.mechanics.anchors.rigid_groups` at ``radius``) holding two or more held
    nodes: such a patch moves rigidly with two clamped points, so it stays at rest (and has no constraint rows,
    :class:`~mdsr_opt.mechanics.constraints.MuscleConstraints`)."""
    fixed = np.zeros(2 * mesh.n_nodes, dtype=bool)
    if held is None:
        fixed[list(gauge_coordinates(mesh))] = True
        return fixed
    groups = rigid_groups(mesh, muscles, radius) if len(muscles) else []
    nodes = [np.asarray(held)] + [g for g in groups if np.isin(g, held).sum() >= 2]
    nodes = np.unique(np.concatenate(nodes))
    fixed[2 * nodes] = fixed[2 * nodes + 1] = True
    return fixed


def _constrained_model(emodel, mc, ropes) -> ConstrainedModel:
    cache = emodel.__dict__.setdefault("_constrained_cache", {})
    key = (id(mc), bool(ropes))
    if key not in cache or cache[key].constraints is not mc:
        if len(cache) >= 16:
            cache.pop(next(iter(cache)))
        cache[key] = ConstrainedModel(emodel, mc, ropes)
    return cache[key]


def in_gauge_frame(mesh: Mesh, x: np.ndarray) -> np.ndarray | None:
    """``x`` (n, 2) moved rigidly into the gauge frame of :func:`solve_internal` (its gauge coordinates at
    their rest values), the rotation nearest the identity of the two that do it; None when none does (node
    ``j`` nearer node ``i`` than its fixed coordinate needs) or ``x`` inverts an element.

    A state of the body in any pose (e.g. an earlier result, aligned to rest) starts a solve from here
    without the shear that setting the three gauge coordinates alone would make."""
    x = np.asarray(x, dtype=float)
    if x.shape != (mesh.n_nodes, 2):
        raise ValueError(f"x must have shape ({mesh.n_nodes}, 2), got {x.shape}")
    if not upright(mesh, x):
        return None
    gi, _gi1, gj = gauge_coordinates(mesh)
    i, j, comp = gi // 2, gj // 2, gj % 2
    P = mesh.points
    w, v = x[j] - x[i], P[j] - P[i]
    rho = float(np.hypot(*w))
    if rho == 0.0 or abs(v[comp]) > rho:
        return None
    alpha = float(np.arctan2(w[1], w[0]))
    if comp == 1:  # (R w)_1 = rho sin(theta + alpha) = v_1
        base = float(np.arcsin(v[1] / rho))
        cands = [base - alpha, np.pi - base - alpha]
    else:  # (R w)_0 = rho cos(theta + alpha) = v_0
        base = float(np.arccos(v[0] / rho))
        cands = [base - alpha, -base - alpha]
    th = min(cands, key=lambda t: abs(np.angle(np.exp(1j * t))))
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    return (x - x[i]) @ R.T + P[i]


def check_held(mesh, held, muscles=None) -> np.ndarray | None:
    """The ``held`` nodes of internal driving checked at the door: None (a free body), or a sorted int64 array
    of at least two distinct node indices in range (:func:`~mdsr_opt.core.checks.node_indices`: integers, a
    float or boolean refused). With ``muscles`` (checked :class:`Muscle` objects) a rope whose every node is
    held is refused: nothing of it could move.

    Raises ``TypeError`` (not integers) or ``ValueError`` (empty, one node, out of range, repeated)."""
    if held is None:
        return None
    idx = node_indices(held, "held", n=mesh.n_nodes)
    if len(idx) == 0:
        raise ValueError("held is empty: give the nodes the body is clamped at (at least two), or held=None for "
                         "a free body")
    if len(idx) < 2:
        raise ValueError(f"held needs at least two nodes (got node {int(idx[0])} only): one node held leaves the "
                         "body free to turn about it; give two or more, e.g. the nodes of a clamped base")
    hs = set(idx.tolist())
    for c, mu in enumerate(muscles or ()):
        if set(mu.nodes) <= hs:
            raise ValueError(f"held: every node of muscle {label_of(muscles, c)} is held, so it could not contract; "
                             "hold fewer nodes")
    return np.sort(idx)


def in_held_frame(mesh: Mesh, x: np.ndarray, held: np.ndarray) -> np.ndarray:
    """``x`` (n, 2) moved rigidly so that its ``held`` nodes lie as near their rest positions as a rigid motion
    takes them (least squares; exact when ``x`` holds them at rest): a state in any pose starting a solve with
    those nodes held, without the shear that setting them alone would make."""
    x = np.asarray(x, dtype=float)
    if x.shape != (mesh.n_nodes, 2):
        raise ValueError(f"x must have shape ({mesh.n_nodes}, 2), got {x.shape}")
    return align(x[held], mesh.points[held]).apply(x)


@interruptible()  # Ctrl-C anywhere in the solve raises KeyboardInterrupt, never a result
def solve_internal(mesh: Mesh, material, muscles: Sequence[Muscle], contractions, *, muscle_model: str = "cable",
                   stiffness: float = 10.0, anchor_radius: float | None = None, backend: str = "ipopt",
                   tol: float = 1e-8, max_iter: int = 200, options: dict | None = None,
                   min_step: float = 1.0 / 256, align_to_rest: bool = True, verbose: bool = False,
                   initial_guess: str | np.ndarray = "predictor", check_stability: bool = True,
                   obstacles=None, contact: bool = False, contact_gap: float | None = None,
                   friction: float = 0.0, held=None) -> EquilibriumResult:
    """Internal driving: muscles contract by fractions ``contractions`` of their rest lengths in a free body,
    or in a body clamped at its ``held`` nodes.

    Parameters
    ----------
    muscles : list of :class:`Muscle` (or node lists) along mesh edges.
    contractions : one value in ``[0, 1)`` per muscle.
    muscle_model : ``"cable"`` (default) or ``"springs"``.

        - ``"cable"``: an inextensible rope sliding along the muscle's node chain, pulled in by a servo:
          ``min E_e(x)`` subject to ``L_c(x) <= (1 - a_c) L0_c`` for every muscle, solved exactly by the NLP
          (no penalty). The tension is the constraint's multiplier, never compressive; a rope that would have
          to push goes slack (``slack=True``, achieved < commanded).
        - ``"springs"``: the paper's dummy springs, one per segment, with the stiffness stated per unit rest
          length so the model does not depend on the mesh: a segment of rest length ``l0`` is a spring
          ``k/2 (l - (1 - a) l0)^2`` with ``k = K / l0`` and ``K = stiffness * E * thickness * D`` (``D`` the body's diameter)
          (a rod of axial stiffness ``K``; see
          :func:`~mdsr_opt.mechanics.constraints.segment_spring_parameters`).
    stiffness : ``kappa`` of the springs model (ignored by the cable).
    anchor_radius : radius (length units) of the rigid patch that anchors each muscle end: the body nodes
        within it at rest move rigidly with the end node. Default
        :func:`~mdsr_opt.mechanics.anchors.default_anchor_radius` (0.04 x the body's diameter); 0 ends each muscle
        on its node alone. Used with both models.
    backend : one of :func:`available_backends`; with constraints (the cable, or any anchor patch) only those
        of :data:`~mdsr_opt.mechanics.backends.CONSTRAINED_BACKENDS` (not ``"newton"`` or ``"scipy"``).
    tol : the tolerance contract (:mod:`~mdsr_opt.mechanics.residual`): a success has its scaled KKT residual
        at most ``tol`` (``residual``: the Lagrangian's free gradient relative to ``E t size`` with the ropes
        pulling only within ``tol L0`` of their targets, and the ropes' and anchor patches' violation), in
        any units (solved on the body's unit copy, :mod:`~mdsr_opt.mechanics.units`); a state re-checked with
        :func:`~mdsr_opt.synthesis.verify.check_minimum` at ``tol`` meets it too.
    max_iter : iteration cap of each solve, not of the call: every load step tried (a long one is first
        given at most :data:`~mdsr_opt.mechanics.loadsteps.STEP_ITER_CAP` and halved), and the stability
        check's re-solve, may take up to ``max_iter``; ``iterations`` in the result sums them all, so it can
        exceed ``max_iter``. An integer >= 1.
    options : extra options for the backend (e.g. ``{"ipopt.print_level": 5}``).
    min_step : smallest load fraction tried before giving up, in (0, 1].
    verbose : print each accepted load step.
    align_to_rest : rigidly align the result to the rest shape (the body's pose is otherwise arbitrary).
    initial_guess : ``"predictor"``, ``"rest"`` or an (n, 2) state, as in :func:`solve_external`; a state
        in any pose (e.g. an earlier result's ``x``) is moved rigidly into the solver's gauge frame
        (:func:`in_gauge_frame`).
    check_stability : bool
        Check that the equilibrium reached is stable, leaving a saddle along its negative curvature (the
        default). ``False`` skips the check (one sparse factorisation): ``success`` then
        means a converged equilibrium with every element upright, which may be a saddle (``stable`` is
        None). For warm starts, such as the flattened design's, whose result is verified later.
    obstacles, contact, contact_gap, friction : contact, as in :func:`solve_external`. With obstacles the body is held
        at its three gauge coordinates (at rest) in the obstacles' frame and not aligned to rest; the net force
        the gauge holds is then ``contact["gauge_force"]`` (zero when the contacts balance the body). As
        :func:`solve_external` notes, with contact the state reached can depend on the path (the load steps,
        ``initial_guess``): a body pressed against itself or an obstacle can have several stable states at
        the same contractions; a solve whose path touches nothing returns the state without contact.
    held : node indices, optional
        Nodes clamped at their rest positions, as a robot is mounted on its base (at least two distinct nodes,
        integers in range, each once: :func:`check_held`); default None, the paper's free body, held only at
        its three gauge coordinates (:func:`gauge_coordinates`) and aligned to rest. With ``held`` the held
        nodes fix the body's pose: the result is not aligned to rest (``align_to_rest`` is ignored), an
        initial state in any pose is first moved rigidly onto the held nodes' rest positions
        (:func:`in_held_frame`), and obstacles, also at rest coordinates, stand where they stand relative to
        the mount; with obstacles ``contact["held_force"]`` is the net force the held nodes exert on the body
        (the mount's reaction) instead of ``gauge_force``. A muscle's anchor patch holding two or more held
        nodes is clamped whole (it moves rigidly with them, so it stays at rest).

    Returns
    -------
    EquilibriumResult
        With, per muscle, ``commanded``, ``achieved`` (``1 - L/L0`` along the node chain in the returned
        state), ``stroke`` (``achieved * L0``, length units), ``tension`` and ``slack``. Load stepping moves
        the rope targets ``(1 - s a) L0`` (or the springs' rest lengths) with the load fraction ``s``. Only a
        stable state is a success (unless ``check_stability=False``): the Hessian of the Lagrangian must
        be positive definite on the tangent space of the active constraints (taut ropes, anchor patches;
        ``stable``, ``stability``).

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
    model = muscle_model
    check_mesh_material(mesh, material)
    tol = check_common(tol, max_iter, backend)
    if model not in ("springs", "cable"):
        raise ValueError(f"model must be 'springs' or 'cable', got {model!r}")
    stiffness = positive_float(stiffness, "stiffness")
    radius = check_anchor_radius(mesh, anchor_radius)
    mus = check_muscles(mesh, muscles)
    if not mus:
        raise ValueError("internal driving needs at least one muscle")
    if model == "cable":
        check_distinct_ropes(mus)
    a = check_contractions(contractions, len(mus))
    if not isinstance(check_stability, (bool, np.bool_)):
        raise TypeError(f"check_stability must be True or False, got {check_stability!r}")
    hold = check_held(mesh, held, mus)
    predict, x_start = initial_guess_of(initial_guess, mesh)
    if not isinstance(initial_guess, str):  # a state in any pose: moved rigidly into the solver's frame
        moved = in_gauge_frame(mesh, x_start.reshape(-1, 2)) if hold is None else \
            in_held_frame(mesh, x_start.reshape(-1, 2), hold)
        if moved is not None:
            x_start = moved.reshape(-1)
    units = Units(mesh, material)  # solved on the unit body (size and E t about 1), mapped back
    spec = contact_spec(units, obstacles, contact, contact_gap, backend, friction)
    mesh, material = units.unit_mesh, units.unit_material
    radius_given, radius, x_start = radius, units.to_unit(radius), units.state_in(x_start)
    # the chain inside the anchor patches keeps its length: the rest must take up the whole stroke
    k_seg, a_fac = spring_segments(mesh, material, mus, stiffness, radius)
    if np.any(a * a_fac >= 1.0):
        c = int(np.argmax(a * a_fac))
        raise LayoutError(f"muscle {label_of(mus, c)}: its anchor patches cover so much of it that a contraction "
                          f"of {a[c]:g} would shorten the rest by {a[c] * a_fac[c]:.3g} >= 1; give a smaller anchor_radius")
    constrained = model == "cable" or len(rigid_groups(mesh, mus, radius)) > 0
    if constrained and not supports_constraints(backend):
        why = "the exact cable" if model == "cable" else f"the rigid anchor patches (anchor_radius={radius_given:g})"
        raise ValueError(f"backend {backend!r} cannot take constraints, which {why} needs; use one of "
                         f"{', '.join(CONSTRAINED_BACKENDS)}" + ("" if model == "cable" else
                                                                 ", or anchor_radius=0"))
    t0 = time.perf_counter()
    mc = muscle_constraints(mesh, mus, radius, hold)  # one cache per mesh, shared with the design
    emodel = get_model(mesh, material)
    cm = _constrained_model(emodel, mc, model == "cable") if model == "cable" or mc.n_rigid else None
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
    fixed = held_coordinates(mesh, hold, mus, radius)
    X = mesh.points.reshape(-1).copy()
    vals = X[fixed]
    solver_model = cm if cm is not None else emodel
    if spec.active:
        res, lam = solve_with_contact(mesh, emodel, material, p_of, fixed, lambda s: vals, x_start, spec, tol,
                                      max_iter, options, min_step, verbose, predict, "internal", units, cm=cm,
                                      settle=bool(check_stability), loose=loadsteps.INTERNAL_INTERMEDIATE_TOL,
                                      p_elastic=p_el0 if cm is None else None, t_model=t_model)
        if spec.obstacles:
            align_to_rest = False  # the body stays in the obstacles' frame, held at its gauge or held nodes
            g = emodel.gradient(res.x.reshape(-1), p_energy(1.0)) - (np.asarray(res.contact["node_forces"]).reshape(-1)
                                                                     / units.force)
            if cm is not None and lam is not None:
                g = g + cm.jacobian(res.x.reshape(-1)).T @ lam
            # the force the gauge exerts on the body: what balances the rest at its fixed coordinates
            gx, gy = g[0::2][fixed[0::2]].sum(), g[1::2][fixed[1::2]].sum()
            res.contact["gauge_force" if hold is None else "held_force"] = [float(gx) * units.force,
                                                                           float(gy) * units.force]
        taut = np.ones(len(mus), dtype=bool) if lam is None else lam[:len(mus)] > 0
        return _internal_out(res, units, mesh, mc, model, mus, a, a_fac, K, radius, L0, cm, lam, taut, tol,
                             align_to_rest and hold is None)
    x, status, ok, iters, steps, t_solve, t_build = load_continuation(
        mesh, solver_model, p_of, fixed, lambda s: vals, x_start, backend, tol, max_iter, options, min_step,
        verbose, predict, settle=bool(check_stability), intermediate_tol=loadsteps.INTERNAL_INTERMEDIATE_TOL)
    p1 = p_of(1.0)
    p_el = p_el0
    taut = np.ones(len(mus), dtype=bool)
    residual = None
    lam = None
    if cm is not None:  # the multipliers of the tolerance contract's residual (ropes within tol of their targets)
        kkt = kkt_residual(cm, x, p1, fixed, tol, material.E * material.thickness * mesh.size)
        lam, residual = kkt.lam, kkt.value
        if model == "cable":
            taut = kkt.taut
        p1 = cm.params(cm.split(p1)[0], cm.split(p1)[1], lam)
        p_el = cm.params(p_el0, cm.split(p1)[1])
    res = equilibrium_result(mesh, solver_model, material, p1, p_el, x, fixed, status, ok, iters, steps,
                  t_model + t_build, t_solve, backend, "internal", tol, check_stability=bool(check_stability),
                  residual=residual)
    return _internal_out(res, units, mesh, mc, model, mus, a, a_fac, K, radius, L0, cm, lam, taut, tol,
                         align_to_rest and hold is None)


def _internal_out(res, units, mesh, mc, model, mus, a, a_fac, K, radius, L0, cm, lam, taut, tol, align_to_rest):
    """The muscles' part of an internal driving result, aligned to rest if asked, in the user's units."""
    x = res.x.reshape(-1)
    res.muscle_model = model
    res.anchor_radius = radius
    res.rest_lengths = L0.copy()
    res.commanded = a.copy()
    L = mc.lengths(x)
    res.achieved = 1.0 - L / L0
    res.stroke = L0 - L
    if model == "cable":
        # no multipliers from a failed contact solve: no tension to report
        res.tension = np.where(taut, lam[:len(mus)], 0.0) if cm is not None and lam is not None \
            else np.full(len(mus), np.nan if cm is not None else 0.0)
        # slack: no tension and the path shorter than the rope (a rope at its length with no load is taut,
        # not slack; one a little short that still pulls, within the tolerance contract, is taut)
        res.slack = ~taut & (res.achieved > a + tol)
    else:
        # the springs' mean force over the free segments, K (L_free / L0_free - (1 - a')), from the whole
        # chain's length since the anchored segments keep their rest lengths
        res.tension = K * a_fac * (a - res.achieved)
        res.slack = res.tension <= 0.0
    if align_to_rest:
        al = align(res.x, mesh.points)
        res.x = al.apply(res.x)
        res.rotation, res.translation = al.R, al.t
        if res.contact is not None:  # the contact forces turn with the body
            res.contact["node_forces"] = (np.asarray(res.contact["node_forces"]) @ al.R.T).tolist()
    return units.equilibrium_out(res)
